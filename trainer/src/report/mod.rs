//! `trainer report`: plots (SVG and PNG) and a written summary of a model on runs.
//!
//! Per run: raw and compensated rate − reference (10-s means) with the loop
//! temperature; the measured bias (10-s means) against the loop temperature,
//! coloured by ramp direction, with the model overlaid, and the residual
//! against temperature; the Allan deviation before/after on log-log axes with
//! shaded ±1-σ confidence bands. For the model, with a colour bar: a lag bank's
//! or multi-scale model's bias along the runs' path over its own inputs; any
//! other model's over the loop temperature T and a steady ramp rate ΔT (every
//! ΔT window reads the same rate on a steady ramp), greyed where no training
//! sample lay (no sample of the reported runs, when the training runs are not
//! known). Plus report.json and report.md (the model, and per run its figures
//! and how many samples were clamped).
//!
//! This module writes the page (report.md, report.json, the run pass that
//! gathers every plot's data); `canvas` holds what the plots share (the
//! `Figure` trait, rendering, block means) and `rate`, `bias_temp`,
//! `allan_plot` and `surface` draw a plot kind each.

use std::path::{Path, PathBuf};

use anyhow::Context;
use rbf_core::Model;

use crate::evaluation::axes::accept_evaluation;
use crate::evaluation::diagnose::RunDiagnosis;
use crate::evaluation::evaluate::{Evaluator, RunEvaluation};
use crate::evaluation::table::figure;
use crate::output::{self, DirTarget, Existing, StagedDir};
use crate::reading::run::RunReader;
use crate::reading::run::samples::StreamedRun;
use crate::{describe::summary, reading::input, text};
use rbf_core::axis::Axis;

mod allan_plot;
mod bias_temp;
mod canvas;
mod palette;
mod rate;
mod settled;
mod surface;

use self::{allan_plot::*, bias_temp::*, canvas::*, rate::*, settled::*, surface::*};

/// What one run contributes to the report, gathered in one streaming pass.
struct RunPlots {
    stem: String,
    /// Rows × nominal sample period, s.
    duration_s: f64,
    evaluation: RunEvaluation,
    rate: RatePlot,
    bias_temp: BiasTempPlot,
    /// The run's gaps in words ([`RunDiagnosis::gap_notice`]), `None` without any.
    gap_notice: Option<String>,
}

/// One pass over the run of `reader`: evaluation, 10-s means for the rate
/// plot, trajectory points (sample indices from `first_index` on).
fn read_run(
    model: &Model,
    reader: RunReader,
    stem: &str,
    title: &str,
    trajectory: &mut Trajectory,
    first_index: &mut usize,
    accept: crate::evaluation::axes::Acceptance,
) -> anyhow::Result<RunPlots> {
    let path = reader.path().to_owned();
    let thermometers = model.features().set.thermometers();
    let mut surface = SurfaceCoordinates::of(model);
    let named = RunDiagnosis::new(&path, 1.0).named_by(reader.header().line(), reader.columns());
    let run = StreamedRun::from_reader(reader, thermometers)?;
    let (period_s, has_ref) = (run.nominal_period_s, run.has_ref);
    let config = rbf_core::CompensatorConfig::for_nominal_period_s(period_s);
    let mut compensator = rbf_core::Compensator::new();
    let mut evaluator = Evaluator::new(&path, period_s, has_ref);
    let mut diagnosis = RunDiagnosis::new(&path, period_s).named_like(&named);
    let mut clamped = BlockMeans::new(PLOT_MEAN_S);
    let (mut raw, mut comp, mut temp, mut bias) = (
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
        BlockMeans::new(PLOT_MEAN_S),
    );
    let (mut rows, mut compensated, mut rate_sum, mut comp_sum) = (0usize, 0usize, 0.0f64, 0.0f64);
    run.for_each_line(|line, row, sample| {
        let out = compensator.process(Some(model), &config, sample);
        let r = row.ref_dph.unwrap_or(0.0);
        let loop_c = row.readings_c()[rbf_core::features::LOOP_THERMOMETER];
        evaluator.push(
            row.time_s,
            loop_c,
            row.rate_dph - r,
            out.rate_comp_dph as f64 - r,
            out.flags,
        );
        diagnosis.push(line, row);
        compensated += usize::from(!out.flags.contains(rbf_core::Flags::NO_VALID_MODEL));
        rate_sum += row.rate_dph;
        comp_sum += f64::from(out.rate_comp_dph);
        raw.push(row.time_s, row.rate_dph - r);
        comp.push(row.time_s, out.rate_comp_dph as f64 - r);
        clamped.push(
            row.time_s,
            f64::from(u8::from(out.flags.contains(rbf_core::Flags::INPUT_CLAMPED))),
        );
        bias.push(row.time_s, out.bias_dph as f64);
        temp.push(
            row.time_s,
            row.readings_c()[rbf_core::features::LOOP_THERMOMETER].unwrap_or(f64::NAN),
        );
        if let Some((x, y)) = surface.point(&config, sample) {
            trajectory.push(*first_index + rows, (x, y, out.bias_dph));
        }
        rows += 1;
    })?;
    *first_index += rows;
    let gap_notice = diagnosis.gap_notice();
    // The checks and the gap count `trainer eval` gives the same run.
    let evaluation = accept_evaluation(
        &path,
        None,
        thermometers,
        (evaluator.finish(), diagnosis, compensated),
        accept,
    )?;
    // Without ref_dph each trace is taken about its own mean (as the
    // evaluation's figures are), known only now: a block mean of (v − m) is
    // the block mean of v, less m.
    let mean = |sum: f64| if has_ref { 0.0 } else { sum / rows.max(1) as f64 };
    let less_mean = |blocks: BlockMeans, mean: f64| -> Vec<(f64, f64)> {
        blocks.finish().into_iter().map(|(t, v)| (t, v - mean)).collect()
    };
    let (raw, comp, temp) = (
        less_mean(raw, mean(rate_sum)),
        less_mean(comp, mean(comp_sum)),
        temp.finish(),
    );
    let points = bias_points(&temp, &raw, &bias.finish(), &comp);
    // The same blocks as `comp` (the same times pushed): those holding a clamped sample.
    let clamped: Vec<(f64, f64)> = comp
        .iter()
        .zip(clamped.finish())
        .filter(|(_, (_, share))| *share > 0.0)
        .map(|(&point, _)| point)
        .collect();
    Ok(RunPlots {
        stem: stem.to_owned(),
        gap_notice,
        duration_s: rows as f64 * period_s,
        bias_temp: BiasTempPlot {
            title: format!(
                "{title}: bias against loop temperature; 100-s STD {:.3} → {:.3} °/h",
                evaluation.cluster_std_before_dph, evaluation.cluster_std_after_dph
            ),
            points,
        },
        rate: RatePlot {
            title: format!(
                "{title}: rate before and after compensation; 100-s STD {:.3} → {:.3} °/h",
                evaluation.cluster_std_before_dph, evaluation.cluster_std_after_dph
            ),
            y_desc: if has_ref {
                "rate − ref_dph [°/h] (10-s means)"
            } else {
                "rate − its run mean (no ref_dph) [°/h] (10-s means)"
            },
            raw,
            comp,
            clamped,
            temp,
        },
        evaluation,
    })
}

/// The name a run's plots take: its file stem (`stdin` for `-`).
fn run_stem(path: &Path) -> String {
    if input::is_stdin(path) {
        return "stdin".to_owned();
    }
    path.file_stem()
        .map_or("run".into(), |s| s.to_string_lossy().into_owned())
}

/// Whether `rel` (a path relative to a report directory) names a file a
/// report writes: a plot (`.svg`, `.png`), `report.json`, `report.md`,
/// `fit.txt`, at the top or in a multi-axis report's `axis-x`, `axis-y`,
/// `axis-z` (those directories themselves included). A directory holding
/// anything else is never replaced.
pub fn report_may_hold(rel: &Path) -> bool {
    let parts: Vec<&std::ffi::OsStr> = rel.iter().collect();
    let axis_dir = |p: &std::ffi::OsStr| ["axis-x", "axis-y", "axis-z"].iter().any(|a| p == *a);
    if let [only] = parts[..]
        && axis_dir(only)
    {
        return true;
    }
    let (dirs, name) = match parts.split_last() {
        Some((name, dirs)) => (dirs, name.to_string_lossy()),
        None => return false,
    };
    let in_place = match dirs {
        [] => true,
        [axis] => axis_dir(axis),
        _ => false,
    };
    in_place
        && (name.ends_with(".svg")
            || name.ends_with(".png")
            || ["report.json", "report.md", "fit.txt"].contains(&name.as_ref()))
}

/// Checks, before any work, that a report on `runs` can be written into
/// `dir` ([`output::check_dir_target`]: the directory is replaced as a
/// whole, so none of `inputs` or `outputs` may lie in it, and an existing
/// one that is not empty only with [`Existing::Replace`] and when it holds
/// nothing but a report's files) and that the runs' plot names differ.
/// Returns the runs' plot names and the checked directory.
pub fn check_report_targets(
    runs: &[PathBuf],
    dir: &Path,
    inputs: &[&Path],
    outputs: &[&Path],
    existing: Existing,
) -> anyhow::Result<(Vec<String>, DirTarget)> {
    let stems: Vec<String> = runs.iter().map(|p| run_stem(p)).collect();
    for (i, stem) in stems.iter().enumerate() {
        if stems[..i].contains(stem) {
            anyhow::bail!(
                "two runs are named {}: their plots would overwrite each other; rename one",
                text::escape_controls(stem)
            );
        }
    }
    let target = output::check_dir_target(dir, inputs, outputs, existing, &report_may_hold)?;
    Ok((stems, target))
}

/// The model section of report.md: its file, kind, form, centres and every
/// input with its training range.
fn model_markdown(model: &Model, model_path: &Path) -> String {
    let mut md = format!("## Model\n\n- file: `{}`\n", text::path(model_path));
    let description = crate::describe::describe(model);
    md.push_str(&format!("- kind: {}\n", description.kind));
    md.push_str(&format!("- form: {}\n", description.form));
    if let Some(t0) = description.ref_temp_c {
        md.push_str(&format!(
            "- reference temperature T₀: {} °C\n",
            summary::sig(f64::from(t0), 4)
        ));
    }
    md.push_str(&format!(
        "- centres: {}\n",
        summary::count(summary::centers(model) as u64, "centre", "centres")
    ));
    md.push_str("- inputs (training range):\n");
    for (name, lo, hi) in summary::training_ranges(model) {
        md.push_str(&format!(
            "  - {}: {} … {}\n",
            text::escape_controls(&name),
            summary::sig(f64::from(lo), 4),
            summary::sig(f64::from(hi), 4)
        ));
    }
    md.push('\n');
    md
}

/// `n` of `samples` as a table cell: the count and its percentage.
fn clamped_cell(n: usize, samples: usize) -> String {
    if samples == 0 {
        return n.to_string();
    }
    format!("{n} ({:.1} %)", 100.0 * n as f64 / samples as f64)
}

/// The runs a report is made of.
#[derive(Clone, Copy, Debug)]
pub struct ReportRuns<'a> {
    /// Every run, in the order reported.
    pub paths: &'a [PathBuf],
    /// How many of the first `paths` the model was trained on (`trainer
    /// fit`): their samples alone mark where a box model's bias surface is
    /// backed by data. `None` when that is not known (`trainer report`):
    /// every run's samples then.
    pub trained_on: Option<usize>,
}

/// Writes the report of `model` (read from `model_path`) on the runs at
/// `runs` (`-`: standard input) into the staged directory `out`, in its
/// subdirectory `sub` (empty: at the top); returns how many files it wrote,
/// the runs' evaluations and the notices of runs with gaps
/// ([`RunDiagnosis::gap_notice`]), which `report.md` lists too.
/// `axis` picks that axis of multi-axis runs (`None`: single-axis runs).
///
/// Every run is read once, streaming (memory: 10-s means and a bounded
/// trajectory, whatever the run's length), before any file is written.
/// Nothing is visible until `out`'s [`output::Transaction`] commits. A run
/// where no row could be compensated, or that is implausible
/// ([`crate::reading::plausible`]), is refused unless `accept` says so.
pub fn write_report(
    model: &Model,
    model_path: &Path,
    runs: ReportRuns,
    out: &StagedDir,
    sub: &Path,
    accept: crate::evaluation::axes::Acceptance,
    axis: Option<Axis>,
) -> anyhow::Result<(usize, Vec<RunEvaluation>, Vec<String>)> {
    let (trained_on, runs) = (runs.trained_on, runs.paths);
    input::check_stdin_once(runs.iter().map(|p| p.as_path()).chain([model_path]))?;
    let stems: Vec<String> = runs.iter().map(|p| run_stem(p)).collect();
    // A multi-axis report's titles name the axis.
    let titled = |stem: &str| match axis {
        Some(a) => format!("{stem}, axis {}", a.name()),
        None => stem.to_owned(),
    };
    let mut trajectory = Trajectory::new();
    let mut first_index = 0;
    // The first sample index past the training runs.
    let mut trained_end_index = None;
    let plots = runs
        .iter()
        .zip(&stems)
        .enumerate()
        .map(|(k, (path, stem))| {
            if Some(k) == trained_on {
                trained_end_index = Some(first_index);
            }
            let mut reader = RunReader::open(path)?;
            match axis {
                Some(axis) => reader.select_axis(axis)?,
                None => reader.header().require_single_axis()?,
            }
            read_run(
                model,
                reader,
                stem,
                &titled(stem),
                &mut trajectory,
                &mut first_index,
                accept,
            )
        })
        .collect::<anyhow::Result<Vec<_>>>()?;

    let written = std::cell::Cell::new(0);
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        out.write(&sub.join(name), bytes)?;
        written.set(written.get() + 1);
        Ok(())
    };
    let both = |stem: &str, drawn: anyhow::Result<(String, Vec<u8>)>| -> anyhow::Result<()> {
        let (svg, png) = drawn.with_context(|| format!("{}: plot {stem}", text::path(&out.target().join(sub))))?;
        write(&format!("{stem}.svg"), svg.as_bytes())?;
        write(&format!("{stem}.png"), &png)
    };
    let mut md = match axis {
        Some(a) => format!("# Compensation report, axis {}\n\n", a.name()),
        None => String::from("# Compensation report\n\n"),
    };
    md.push_str(&model_markdown(model, model_path));
    md.push_str("## Runs\n\n| run | 100-s STD before [°/h] | after [°/h] | improvement | MSD improvement | ARW after [°/√h] | BI before → after [°/h] | clamped samples |\n|---|---|---|---|---|---|---|---|\n");
    for p in &plots {
        let stem = &p.stem;
        both(&format!("{stem}_rate"), render(&p.rate))?;
        both(&format!("{stem}_bias_vs_temp"), render(&p.bias_temp))?;
        let allan = AllanPlot {
            title: format!(
                "{}: overlapping Allan deviation; bias instability {} → {} °/h",
                titled(stem),
                p.evaluation.allan_before.bias_instability_cell(),
                p.evaluation.allan_after.bias_instability_cell()
            ),
            evaluation: &p.evaluation,
            duration_s: p.duration_s,
        };
        both(&format!("{stem}_allan"), render(&allan))?;
        if let Some(settled) = &p.evaluation.settled {
            let plot = SettledPlot {
                title: format!(
                    "{}: settled bias against loop temperature, ±2σ of the mean; {}",
                    titled(stem),
                    spread_words(settled)
                ),
                settled,
            };
            both(&format!("{stem}_settled_bias"), render(&plot))?;
        }
        let e = &p.evaluation;
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} → {} | {} |\n",
            text::escape_controls(stem),
            figure(e.cluster_std_before_dph, |v| format!("{v:.4}")),
            figure(e.cluster_std_after_dph, |v| format!("{v:.4}")),
            figure(e.cluster_std_improvement_pct, |v| format!("{v:.1} %")),
            figure(e.msd_improvement_pct, |v| format!("{v:.1} %")),
            figure(e.allan_after.arw_deg_per_sqrt_h, |v| format!("{v:.2e}")),
            e.allan_before.bias_instability_cell(),
            e.allan_after.bias_instability_cell(),
            clamped_cell(e.flagged.input_clamped, e.samples)
        ));
    }
    md.push_str(
        "\nClamped samples: inputs outside the model's training range, held at its edge \
         (flag 1).\n",
    );
    md.push_str(&format!("{}.\n", crate::evaluation::allan::FLOOR_RULE));
    let gap_notices: Vec<String> = plots.iter().filter_map(|p| p.gap_notice.clone()).collect();
    if !gap_notices.is_empty() {
        md.push_str("\n## Gaps in the runs\n\n");
        for notice in &gap_notices {
            md.push_str(&format!("- {}\n", text::escape_controls(notice)));
        }
    }
    md.push_str(&settled_markdown(&plots));
    let trained_end_index = trained_end_index.or(trained_on.map(|_| first_index));
    let surface = SurfacePlot::new(model, trajectory.points, trained_end_index);
    both("bias_surface", render(&surface))?;
    md.push_str("\n## Plots\n\n![bias surface](bias_surface.svg)\n\n");
    for p in &plots {
        let stem = &p.stem;
        md.push_str(&format!(
            "### {}\n\n![rate]({stem}_rate.svg)\n\n![bias against temperature]({stem}_bias_vs_temp.svg)\n\n![Allan deviation]({stem}_allan.svg)\n\n![settled bias]({stem}_settled_bias.svg)\n\n",
            text::escape_controls(stem)
        ));
    }
    let evaluations: Vec<&RunEvaluation> = plots.iter().map(|p| &p.evaluation).collect();
    let json =
        serde_json::to_string_pretty(&serde_json::json!({"model": text::path(model_path), "runs": evaluations}))?;
    write("report.json", json.as_bytes())?;
    write("report.md", md.as_bytes())?;
    Ok((
        written.get(),
        plots.into_iter().map(|p| p.evaluation).collect(),
        gap_notices,
    ))
}

/// The settled-bias section of report.md: per run its spread (or why none)
/// and a row per plateau.
fn settled_markdown(plots: &[RunPlots]) -> String {
    let mut md = format!(
        "\n## Settled bias (soak plateaus)\n\nA {} (docs/workflow.md, \"The soak test\"). Column {}.\n\n",
        crate::dataset::plateaus::rule_text(),
        crate::dataset::plateaus::outside_rule_text()
    );
    for p in plots {
        let Some(settled) = &p.evaluation.settled else { continue };
        md.push_str(&format!(
            "- {}: {}\n",
            text::escape_controls(&p.stem),
            spread_words(settled)
        ));
    }
    let any = plots
        .iter()
        .any(|p| p.evaluation.settled.as_ref().is_some_and(|s| !s.plateaus.is_empty()));
    if any {
        md.push_str(
            "\n| run | loop T [°C] | steady [min] | window [s] | bias before [°/h] | bias after [°/h] | noise [°/h] | \
             outside the training range [%] |\n\
             |---|---|---|---|---|---|---|---|\n",
        );
        for p in plots {
            let Some(settled) = &p.evaluation.settled else { continue };
            for q in &settled.plateaus {
                md.push_str(&format!(
                    "| {} | {:.2} | {:.0} | {:.0} … {:.0} | {:+.4} | {:+.4} | {} | {:.0} |\n",
                    text::escape_controls(&p.stem),
                    q.temp_c,
                    q.steady_s / 60.0,
                    q.window_start_s,
                    q.window_end_s,
                    q.bias_before_dph,
                    q.bias_after_dph,
                    figure(q.noise_dph, |v| format!("{v:.4}")),
                    q.outside_range_pct
                ));
            }
        }
    }
    md
}

/// The summary page of a multi-axis report (its top report.md): every run
/// and axis side by side, with links to each axis's own report.
pub fn axes_summary_markdown(model_path: &Path, axes: &[(Axis, Vec<RunEvaluation>)]) -> String {
    let names: Vec<&str> = axes.iter().map(|(a, _)| a.name()).collect();
    let mut md = format!(
        "# Compensation report, axes {}\n\nModel: `{}`. Each axis in full: {}.\n\n",
        names.join(", "),
        text::path(model_path),
        names
            .iter()
            .map(|n| format!("[axis {n}](axis-{n}/report.md)"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    md.push_str(
        "| run | axis | 100-s STD before [°/h] | after [°/h] | improvement | BI after [°/h] | clamped | settled spread before → after [°/h] |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let runs = axes.iter().map(|(_, e)| e.len()).max().unwrap_or(0);
    for run in 0..runs {
        for (axis, evaluations) in axes {
            let Some(e) = evaluations.get(run) else { continue };
            let settled = match e
                .settled
                .as_ref()
                .map(|s| (s.settled_spread_before_dph, s.settled_spread_dph))
            {
                Some((Some(before), Some(after))) => format!("{before:.3} → {after:.4}"),
                _ => "– (under 2 plateaus)".to_owned(),
            };
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                text::escape_controls(&run_stem(Path::new(&e.run))),
                axis.name(),
                figure(e.cluster_std_before_dph, |v| format!("{v:.4}")),
                figure(e.cluster_std_after_dph, |v| format!("{v:.4}")),
                figure(e.cluster_std_improvement_pct, |v| format!("{v:.1} %")),
                e.allan_after.bias_instability_cell(),
                clamped_cell(e.flagged.input_clamped, e.samples),
                settled
            ));
        }
    }
    md.push_str(&format!("\n{}.\n", crate::evaluation::allan::FLOOR_RULE));
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plotting::axes::TICK_LABEL_PX;
    use plotters::prelude::{IntoDrawingArea, IntoTextStyle, SVGBackend};
    use rbf_core::FeatureSet;

    #[test]
    fn a_report_directory_may_hold_only_what_a_report_writes() {
        for ok in ["report.md", "fit.txt", "run_rate.svg", "axis-y", "axis-y/run_allan.png"] {
            assert!(report_may_hold(Path::new(ok)), "{ok}");
        }
        for not in ["notes.txt", "run.csv", "keep", "axis-y/sub/x.svg", "other/report.md"] {
            assert!(!report_may_hold(Path::new(not)), "{not}");
        }
    }

    #[test]
    fn the_default_models_surface_spans_its_fastest_rate_input_not_a_power_of_temperature() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::samples::Run::load(&data).unwrap();
        let opts = crate::fit::FitOptions::default();
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &opts).unwrap().model;
        let FeatureSet::LagBank(bank) = model.features().set else {
            panic!("the default is the lag bank")
        };
        let fastest = model.input_range(bank.static_inputs()).unwrap();
        assert_eq!(surface_rate_range(&model), Some(fastest));
        // The 1 °C/min run's rates stay within ±1 °C/min; (T̂ − T₀)² reaches 100 °C².
        assert!(fastest.0 > -1.0 && fastest.1 < 1.0, "{fastest:?}");
    }

    #[test]
    fn bias_points_are_coloured_by_the_direction_the_temperature_moves() {
        // 10-s means: heating at 1 °C/min, a hold, cooling at 1 °C/min.
        let temps = [20.0, 20.1667, 20.3333, 20.3333, 20.3333, 20.1667, 20.0];
        let temp: Vec<(f64, f64)> = temps.iter().enumerate().map(|(i, &t)| (10.0 * i as f64, t)).collect();
        let value = |v: f64| temp.iter().map(|&(t, _)| (t, v)).collect::<Vec<_>>();
        let points = bias_points(&temp, &value(1.0), &value(0.75), &value(0.25));
        let ramps: Vec<Ramp> = points.iter().map(|p| p.ramp).collect();
        use Ramp::{Cooling, Heating, Steady};
        assert_eq!(ramps, [Heating, Heating, Heating, Steady, Cooling, Cooling, Cooling]);
        assert_eq!(
            (points[0].measured_dph, points[0].model_dph, points[0].residual_dph),
            (1.0, 0.75, 0.25)
        );
    }

    #[test]
    fn allan_bands_narrow_with_more_clusters() {
        // T/τ = 3: 1/√4; T/τ = 51: 1/√100.
        assert!((crate::evaluation::allan::relative_error(10.0, 30.0) - 0.5).abs() < 1e-12);
        assert!((crate::evaluation::allan::relative_error(1.0, 51.0) - 0.1).abs() < 1e-12);
        assert!(crate::evaluation::allan::relative_error(10.0, 10.0).is_infinite());
        let band = allan_band(&[(1.0, 2.0)], 51.0);
        assert!((band[0].1 - 1.8).abs() < 1e-12 && (band[0].2 - 2.2).abs() < 1e-12);
    }

    #[test]
    fn clamped_samples_are_a_count_and_a_percentage() {
        assert_eq!(clamped_cell(11, 100), "11 (11.0 %)");
        assert_eq!(clamped_cell(0, 0), "0");
    }

    /// The text labels and the circles' centres (x, y) of an SVG that plotters drew.
    fn svg_texts_and_circles(svg: &str) -> (Vec<String>, Vec<(f64, f64)>) {
        let texts = svg
            .split("<text")
            .skip(1)
            .filter_map(|t| Some(t.split_once('>')?.1.split_once("</text>")?.0.trim().to_owned()))
            .collect();
        let attr = |e: &str, name: &str| -> f64 {
            let v = e
                .split(&format!(" {name}=\""))
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap();
            v.parse().unwrap()
        };
        let circles = svg
            .split("<circle")
            .skip(1)
            .map(|c| (attr(c, "cx"), attr(c, "cy")))
            .collect();
        (texts, circles)
    }

    /// An evaluation whose Allan curves run from `hi` down to `lo`, °/h, over 1 … 1000 s.
    fn evaluation_with_allan(lo: f64, hi: f64) -> RunEvaluation {
        let tau_s: Vec<f64> = (0..11).map(|k| 2f64.powi(k)).collect();
        let curve = |top: f64| crate::evaluation::allan::AllanDeviation {
            adev_dph: tau_s.iter().map(|t| top * (lo / top).powf(t.log2() / 10.0)).collect(),
            tau_s: tau_s.clone(),
            arw_deg_per_sqrt_h: f64::NAN,
            bias_instability_dph: f64::NAN,
            floor_tau_s: f64::NAN,
            floor_reached: false,
            floor_uncertainty_pct: f64::NAN,
            confident_tau_max_s: 1000.0,
        };
        RunEvaluation {
            run: "r.csv".into(),
            axis: None,
            basis: "samples".into(),
            samples: 10_000,
            reference: "ref_dph",
            msd_before_dph2: 1.0,
            msd_after_dph2: 1.0,
            msd_improvement_pct: 0.0,
            cluster_std_before_dph: 1.0,
            cluster_std_after_dph: 1.0,
            cluster_std_improvement_pct: 0.0,
            flagged: Default::default(),
            allan_before: curve(hi),
            allan_after: curve(hi * 0.9),
            settled: None,
            gaps: None,
        }
    }

    #[test]
    fn a_short_allan_axis_is_labelled_below_its_first_decade_once_per_value_and_off_the_frame() {
        // 0.003 … 0.05 °/h: the axis starts above 0.001.
        let e = evaluation_with_allan(0.003, 0.05);
        let plot = AllanPlot {
            title: "r".into(),
            evaluation: &e,
            duration_s: 20_000.0,
        };
        let (svg, _) = render(&plot).unwrap();
        assert_drawable(&svg);
        let (texts, circles) = svg_texts_and_circles(&svg);
        for label in ["0.005", "0.01", "0.02", "0.05"] {
            assert!(texts.iter().any(|t| t == label), "no tick label {label}: {texts:?}");
        }
        let numbers: Vec<&String> = texts.iter().filter(|t| t.parse::<f64>().is_ok()).collect();
        let mut unique = numbers.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(numbers.len(), unique.len(), "a tick label written twice: {numbers:?}");
        // The markers at τ = 1 s and 1024 s stay off the frame (the plot's
        // area starts after the 80-px label area and the 12-px margin).
        let (x_min, x_max) = circles
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), c| (a.min(c.0), b.max(c.0)));
        assert!(x_min > 12.0 + 80.0 + 10.0, "first marker on the frame: x {x_min}");
        assert!(
            x_max < f64::from(SIZE.0) - 12.0 - 10.0,
            "last marker on the frame: x {x_max}"
        );
    }

    /// The font size an SVG that plotters drew gives the text `content`.
    fn svg_font_size(svg: &str, content: &str) -> f64 {
        svg.split("<text")
            .skip(1)
            .find(|t| {
                t.split_once('>')
                    .is_some_and(|(_, rest)| rest.trim_start().starts_with(content))
            })
            .and_then(|t| t.split(" font-size=\"").nth(1)?.split('"').next()?.parse().ok())
            .unwrap_or_else(|| panic!("no text {content:?}"))
    }

    #[test]
    fn a_title_too_long_for_the_plot_shrinks_to_fit_rather_than_being_clipped() {
        let e = evaluation_with_allan(0.003, 0.05);
        let size_of = |title: String| {
            let plot = AllanPlot {
                title: title.clone(),
                evaluation: &e,
                duration_s: 20_000.0,
            };
            svg_font_size(&render(&plot).unwrap().0, &title)
        };
        let tail = ": overlapping Allan deviation; bias instability ≤9.75e-3 → ≤2.24e-3 °/h";
        let short = size_of(format!("run{tail}"));
        let long = size_of(format!("{}{tail}", "chamber_run_of_unit_0042_axis_z_".repeat(2)));
        assert!(long < 0.9 * short, "{long} against {short}");
    }

    #[test]
    fn clamped_samples_are_marked_on_the_compensated_rate_in_their_own_colour() {
        let series = |f: &dyn Fn(usize) -> f64| (0..200).map(|k| (10.0 * k as f64, f(k))).collect::<Vec<_>>();
        let comp = series(&|k| 1e-3 * (k as f64 / 9.0).sin());
        let plot = RatePlot {
            title: "r".into(),
            y_desc: "rate − ref_dph [°/h] (10-s means)",
            raw: series(&|k| 1e-3 * k as f64),
            clamped: comp[150..].to_vec(),
            comp,
            temp: series(&|k| 20.0 + k as f64 / 40.0),
        };
        let colour = |c: plotters::style::RGBColor| format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2);
        let (svg, _) = render(&plot).unwrap();
        assert!(
            svg.contains(&colour(palette::CLAMPED)),
            "the clamped samples are marked"
        );
        assert!(
            svg.contains("inputs clamped to the training range (flag 1)"),
            "and named"
        );
        assert!(
            !svg.contains(&colour(palette::OUTSIDE_TRAINING)),
            "grey means only outside the range"
        );
        let unclamped = RatePlot {
            clamped: Vec::new(),
            ..plot
        };
        let (svg, _) = render(&unclamped).unwrap();
        assert!(!svg.contains(&colour(palette::CLAMPED)));
    }

    #[test]
    fn long_y_tick_labels_widen_their_label_area_rather_than_run_into_the_axis_description() {
        // A rate about -1.2e-4 °/h that varies by 1e-6: labels such as -0.0001202.
        let wave = |k: usize| -1.2e-4 + 1e-6 * (k as f64 / 9.0).sin();
        let series = |f: &dyn Fn(usize) -> f64| (0..400).map(|k| (10.0 * k as f64, f(k))).collect::<Vec<_>>();
        let plot = RatePlot {
            title: "r".into(),
            y_desc: "rate − ref_dph [°/h] (10-s means)",
            raw: series(&wave),
            comp: series(&|k| wave(k) + 2e-7),
            clamped: Vec::new(),
            temp: series(&|k| 20.0 + k as f64 / 40.0),
        };
        let (svg, _) = render(&plot).unwrap();
        let mut area_svg = String::new();
        let area = SVGBackend::with_string(&mut area_svg, SIZE).into_drawing_area();
        let style = ("sans-serif", TICK_LABEL_PX).into_text_style(&area);
        // The description's rotated line ends at its x plus its font's height.
        let desc_right_px = 12.0 + TICK_LABEL_PX;
        let left_labels: Vec<(f64, String)> = svg
            .split("<text")
            .skip(1)
            .filter_map(|t| {
                let (attrs, rest) = t.split_once('>')?;
                let text = rest.split_once("</text>")?.0.trim();
                text.parse::<f64>().ok()?;
                let x: f64 = attrs.split(" x=\"").nth(1)?.split('"').next()?.parse().ok()?;
                (x < 200.0 && attrs.contains("text-anchor=\"end\"")).then(|| (x, text.to_owned()))
            })
            .collect();
        assert!(left_labels.len() >= 3, "{left_labels:?}");
        assert!(left_labels.iter().any(|(_, t)| t.len() >= 10), "{left_labels:?}");
        for (right_px, text) in &left_labels {
            let (width, _) = area.estimate_text_size(text, &style).unwrap();
            assert!(
                right_px - f64::from(width) > desc_right_px,
                "{text} reaches the axis description: {right_px} − {width} px"
            );
        }
    }

    #[test]
    fn light_grid_lines_stay_apart_rather_than_stack_into_a_grey_band() {
        let points: Vec<BiasPoint> = (0..300)
            .map(|k| {
                let temp_c = 12.0 + k as f64 * 0.09;
                BiasPoint {
                    temp_c,
                    measured_dph: 0.02 * temp_c,
                    model_dph: 0.02 * temp_c,
                    residual_dph: 0.06 * (k as f64 / 5.0).sin(),
                    ramp: Ramp::Heating,
                }
            })
            .collect();
        let (svg, _) = render(&BiasTempPlot {
            title: "r".into(),
            points,
        })
        .unwrap();
        // plotters draws the light lines at a tenth of black's opacity.
        let attr = |l: &str, name: &str| -> i64 {
            l.split(&format!(" {name}=\""))
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let light: Vec<&str> = svg
            .split("<line")
            .skip(1)
            .filter(|l| l.contains("opacity=\"0.1\""))
            .collect();
        assert!(light.len() > 10, "no light grid lines drawn");
        for (from, to) in [("y1", "y2"), ("x1", "x2")] {
            let mut at: Vec<i64> = light
                .iter()
                .filter(|l| attr(l, from) == attr(l, to))
                .map(|l| attr(l, from))
                .collect();
            at.sort_unstable();
            at.dedup();
            let closest = at.windows(2).map(|w| w[1] - w[0]).min().unwrap_or(i64::MAX);
            assert!(closest >= 7, "light lines along {from} {closest} px apart: {at:?}");
        }
    }

    #[test]
    fn the_bias_surface_masks_what_no_run_reached_and_spends_its_colours_on_the_rest() {
        // Samples only in the lower-left quarter of the box.
        let path: Vec<(f32, f32, f32)> = (0..200)
            .map(|k| (-40.0 + k as f32 * 0.2, -1.0 + k as f32 * 0.004, 0.0))
            .collect();
        let reached = reached_cells(&path, (-40.0, 60.0), (-1.0, 1.0), 60);
        let share = reached.iter().filter(|r| **r).count() as f64 / reached.len() as f64;
        assert!(share > 0.01 && share < 0.2, "{share}");
        // The corner no sample reached is masked; where they went is not.
        assert!(!reached[60 * 60 - 1] && reached[0]);
    }

    /// The SVG of `model`'s bias plot over `trajectory` (the reported runs').
    fn surface_svg(model: &Model, trajectory: Vec<(f32, f32, f32)>) -> String {
        let surface = SurfacePlot {
            model,
            trajectory,
            training_only: false,
        };
        render(&surface).unwrap().0
    }

    /// A cubic in T trained over -40 … 60 °C.
    fn cubic_in_t() -> Model {
        use rbf_core::model::{ModelBody, ModelInfo};
        use rbf_core::poly::Poly3;
        Model::new(
            rbf_core::FeatureConfig::single(FeatureSet::Temp, 0.0),
            &[(-40.0, 60.0)],
            ModelBody::Poly3(Poly3::new(25.0, [0.5, -0.01, 1e-4, -2e-6]).unwrap()),
            ModelInfo::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_box_models_surface_hatches_what_no_run_reached_with_ticks_written_as_numbers() {
        let model = cubic_in_t();
        // The runs stayed below 0 °C and within ±0.2 °C/min.
        let trajectory: Vec<(f32, f32, f32)> = (0..100)
            .map(|k| (-40.0 + 0.4 * k as f32, 0.2 * (k as f32 / 7.0).sin(), 0.0))
            .collect();
        let svg = surface_svg(&model, trajectory);
        let hatch = format!(
            "stroke=\"#{:02X}{:02X}{:02X}\"",
            OUTSIDE_TRAINING.0, OUTSIDE_TRAINING.1, OUTSIDE_TRAINING.2
        );
        assert!(svg.matches(&hatch).count() > 60, "the warm half is hatched");
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t.contains("hatched")), "{texts:?}");
        assert!(texts.iter().any(|t| t.contains("not a model input")), "{texts:?}");
        for t in texts.iter().filter(|t| t.parse::<f64>().is_ok()) {
            assert!(!t.ends_with(".0") && t != "-0", "tick label {t}");
        }
        // The rate axis spans the runs' rates, not a made-up ±1 °C/min.
        let rates = y_ticks(&svg);
        assert!(rates.len() >= 3 && rates.iter().all(|r| r.abs() <= 0.25), "{rates:?}");
    }

    #[test]
    fn a_box_surface_from_a_fit_is_masked_by_the_training_runs_alone() {
        let model = cubic_in_t();
        // A training run below 0 °C (samples 0 … 99), a holdout above it.
        let points: Vec<(usize, (f32, f32, f32))> = (0..200).map(|k| (k, (-40.0 + 0.5 * k as f32, 0.0, 0.0))).collect();
        let surface = SurfacePlot::new(&model, points.clone(), Some(100));
        assert!(surface.training_only);
        assert!(surface.trajectory.len() == 100 && surface.trajectory.iter().all(|p| p.0 < 10.0));
        let (svg, _) = render(&surface).unwrap();
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t.contains("no training sample")), "{texts:?}");
        // Without knowing the training runs (trainer report): every run's samples.
        let surface = SurfacePlot::new(&model, points, None);
        assert!(!surface.training_only && surface.trajectory.len() == 200);
    }

    /// The numbers an SVG that plotters drew writes, with where: (x, y, value).
    fn svg_numbers(svg: &str) -> Vec<(f64, f64, f64)> {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let (attrs, rest) = t.split_once('>')?;
                let value = rest.split_once("</text>")?.0.trim().parse().ok()?;
                let attr = |name: &str| -> Option<f64> {
                    attrs
                        .split(&format!(" {name}=\""))
                        .nth(1)?
                        .split('"')
                        .next()?
                        .parse()
                        .ok()
                };
                Some((attr("x")?, attr("y")?, value))
            })
            .collect()
    }

    /// The tick labels of a surface plot's x axis (below the plot, left of
    /// the colour bar).
    fn x_ticks(svg: &str) -> Vec<f64> {
        svg_numbers(svg)
            .into_iter()
            .filter(|n| n.1 > f64::from(SIZE.1) - 60.0 && n.0 < f64::from(SIZE.0 - COLOUR_BAR_PX))
            .map(|n| n.2)
            .collect()
    }

    /// The tick labels of a plot's left y axis.
    fn y_ticks(svg: &str) -> Vec<f64> {
        svg_numbers(svg)
            .into_iter()
            .filter(|n| n.0 < 100.0 && n.1 < f64::from(SIZE.1) - 60.0)
            .map(|n| n.2)
            .collect()
    }

    /// No text of `svg` carries a combining mark, which the PNG's font does not draw.
    fn assert_drawable(svg: &str) {
        let (texts, _) = svg_texts_and_circles(svg);
        for t in texts {
            assert!(
                !t.chars().any(crate::plotting::axes::is_combining),
                "a combining mark the PNG font drops: {t:?}"
            );
        }
    }

    #[test]
    fn a_response_banks_surface_spans_the_loop_temperature_and_the_runs_rates() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::samples::Run::load(&data).unwrap();
        let opts = crate::fit::FitOptions {
            method: crate::fit::Method::ResponseBank,
            ..crate::fit::FitOptions::default()
        };
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &opts).unwrap().model;
        let FeatureSet::ResponseBank(bank) = model.features().set else {
            panic!("the response bank was asked for")
        };
        let (t_lo, t_hi) = (f64::from(bank.range_min_c), f64::from(bank.range_max_c));
        // Along the run: T across the covered range, ΔT within ±0.5 °C/min.
        let trajectory: Vec<(f32, f32, f32)> = (0..200)
            .map(|k| {
                let t = t_lo + (t_hi - t_lo) * f64::from(k) / 199.0;
                (t as f32, 0.5 * (k as f32 / 20.0).sin(), 0.0)
            })
            .collect();
        let svg = surface_svg(&model, trajectory);
        let temps = x_ticks(&svg);
        assert!(
            temps.len() >= 3 && temps.iter().all(|&t| t >= t_lo - 1.0 && t <= t_hi + 1.0),
            "the x axis spans the loop temperature {t_lo} … {t_hi}: {temps:?}"
        );
        let rates = y_ticks(&svg);
        assert!(rates.len() >= 3 && rates.iter().all(|r| r.abs() <= 0.6), "{rates:?}");
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(texts.iter().any(|t| t == "loop temperature T [°C]"), "{texts:?}");
        // The colours: the bias at the run's temperatures, below 1 °/h in size
        // (off the run's temperatures, the bank's tangents reach over 1 °/h).
        let bar: Vec<f64> = svg_numbers(&svg)
            .into_iter()
            .filter(|n| n.0 > f64::from(SIZE.0 - COLOUR_BAR_PX))
            .map(|n| n.2)
            .collect();
        assert!(!bar.is_empty() && bar.iter().all(|b| b.abs() <= 1.0), "{bar:?}");
        assert_drawable(&svg);
    }

    #[test]
    fn the_lag_banks_bias_plot_marks_its_training_range_and_writes_t_hat_in_words() {
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/ifog_train_1cpm.csv");
        let run = crate::reading::run::samples::Run::load(&data).unwrap();
        let model = crate::fit::fit(std::slice::from_ref(&run), &[], &crate::fit::FitOptions::default())
            .unwrap()
            .model;
        let (lo, hi) = model.input_range(0).unwrap();
        // One sample beyond the training range: drawn grey, outside the dashed box.
        let svg = surface_svg(&model, vec![(lo, 0.0, 0.1), (hi, 0.0, 0.2), (hi + 20.0, 0.0, 9.0)]);
        assert_drawable(&svg);
        assert!(svg.contains("mean coil temperature T-hat [°C]"), "T̂ written out");
        assert!(
            svg.contains("stroke-dasharray") || svg.matches("<polyline").count() > 10,
            "training range drawn"
        );
        let grey = format!(
            "fill=\"#{:02X}{:02X}{:02X}\"",
            OUTSIDE_TRAINING.0, OUTSIDE_TRAINING.1, OUTSIDE_TRAINING.2
        );
        assert_eq!(svg.matches("<circle").count(), 3);
        assert!(svg.contains(&grey), "the sample outside the training range is grey");
        // The colour bar spans 0.1 … 0.2, not the extrapolated 9.
        let (texts, _) = svg_texts_and_circles(&svg);
        assert!(
            !texts
                .iter()
                .any(|t| t.parse::<f64>().is_ok_and(|v| v > 1.0 && v < 10.0)),
            "{texts:?}"
        );
    }

    #[test]
    fn a_point_without_a_temperature_is_left_out() {
        let temp = [(0.0, 20.0), (10.0, f64::NAN), (20.0, 20.0)];
        let v = [(0.0, 1.0), (10.0, 1.0), (20.0, 1.0)];
        assert_eq!(bias_points(&temp, &v, &v, &v).len(), 2);
    }
}
