//! `trainer fit` on multi-axis runs: the arguments into
//! [`trainer::fit::axes`] (the per-axis fits and the joint-model policy), then
//! one multi-axis blob, the summary per axis and the accuracy table per run
//! and axis, printed and written.

use std::io::Write;
use std::path::PathBuf;

use rbf_core::MAX_AXIS_CENTERS;
use rbf_core::axis::Axis;
use trainer::acceptance::{Rejected, Verdict};
use trainer::blobfile::{encode_axis_models, encode_shared_models};
use trainer::evaluation::diagnose;
use trainer::evaluation::evaluate::{RunEvaluation, RunModels, evaluate_file, evaluate_reader};
use trainer::evaluation::table::print_table;
use trainer::fit::FitOptions;
use trainer::fit::axes::{AxisRuns, JointMode, fit_axes, try_joint};
use trainer::output::{Output, Transaction};
use trainer::reading::plausible;
use trainer::reading::run::RunReader;
use trainer::text;

use super::super::common::{JsonSink, print_json_and_commit, print_notes};
use super::args::Args;
use super::blob_out::write_blob;
use super::json::{outcome_json, runs_json};
use super::judging::{Calibration, judge_axis, verdict_text};
use super::record_out::write_records;
use super::summary::{FitHow, training_settled_floor, write_summary, write_vouching};

/// Fits every axis of `axes` on the runs of `a` with `opts`, writes the
/// blob into `model_out` and the JSON report into `json_out`, and prints
/// what `trainer fit` prints; judges each axis against the spec and records each axis's
/// calibration in the store of `calibration`.
pub(super) fn run(
    a: &Args,
    opts: &FitOptions,
    how: &FitHow,
    axes: &[Axis],
    model_out: Option<Output>,
    json_out: JsonSink,
    calibration: Calibration<'_>,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.report.is_none(),
        "--report is for single-axis runs; after a multi-axis fit, trainer report --model MODEL.bin RUN.csv... -o DIR \
         writes a report per axis"
    );
    let all_runs: Vec<&PathBuf> = a.runs.iter().chain(&a.validate).chain(&a.holdout).collect();
    for path in &all_runs {
        for &axis in axes {
            let mut reader = RunReader::open(path)?;
            reader.select_axis(axis)?;
            reader.require_temp()?;
        }
    }
    // Every axis within what a three-axis firmware holds per axis.
    let method = opts.method.clone().with_center_cap(MAX_AXIS_CENTERS).map_err(|k| {
        anyhow::anyhow!(
            "--centers {k}: a multi-axis model holds at most {MAX_AXIS_CENTERS} centres per axis (the three-axis \
             firmware's capacity)"
        )
    })?;
    let opts = &FitOptions { method, ..opts.clone() };
    let started = std::time::Instant::now();
    let runs = AxisRuns {
        train: &a.runs,
        validate: &a.validate,
        holdout: &a.holdout,
    };
    let mode = if a.joint {
        JointMode::Always
    } else if a.no_joint {
        JointMode::Never
    } else {
        JointMode::Auto
    };
    let outcomes = fit_axes(&runs, opts, axes)?;
    let joint = try_joint(&runs, opts, axes, &outcomes, mode)?;
    let fit_s = started.elapsed().as_secs_f64();
    // The checks the single-axis fit makes after its fit: each axis's
    // plausibility, and the gaps of the time column all axes share, named once.
    let training_and_validation: Vec<PathBuf> = a.runs.iter().chain(&a.validate).cloned().collect();
    for (k, &axis) in axes.iter().enumerate() {
        let findings = diagnose::run_findings(&training_and_validation, Some(axis))?;
        plausible::require_plausible(&findings.implausible, a.allow_implausible)?;
        if k == 0 {
            print_notes(&findings.gap_notices);
        }
    }
    let models: Vec<(Axis, &rbf_core::Model)> = axes.iter().copied().zip(outcomes.iter().map(|o| &o.0.model)).collect();
    let provenance = Some(calibration.provenance);
    let blob = match &joint.chosen {
        Some(shared) => encode_shared_models(shared, provenance)?,
        None => encode_axis_models(&models, provenance)?,
    };

    let mut out: Vec<u8> = Vec::new();
    for (axis, (outcome, _)) in axes.iter().zip(&outcomes) {
        writeln!(out, "axis {}:", axis.name())?;
        write_summary(&mut out, outcome, how)?;
    }
    out.write_all(joint.summary.as_bytes())?;
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    // Training and validation runs scored on each axis's block means (as the
    // single-axis fit does), holdout runs sample by sample; a row per run and axis.
    let mut evals: Vec<(&str, RunEvaluation)> = Vec::new();
    for (role, paths) in [("train", &a.runs), ("validate", &a.validate)] {
        for p in 0..paths.len() {
            for (k, (_, scored)) in outcomes.iter().enumerate() {
                let scored = match (&joint.chosen, joint.scored.get(k)) {
                    (Some(_), Some(joint_scored)) => joint_scored,
                    _ => scored,
                };
                if let Some(e) = scored.iter().find(|(r, i, _)| *r == role && *i == p) {
                    evals.push((role, e.2.clone()));
                }
            }
        }
    }
    for path in &a.holdout {
        if let Some(shared) = &joint.chosen {
            let reader = RunReader::open(path)?;
            let columns: Vec<(Axis, rbf_core::record::Columns)> = axes
                .iter()
                .map(|&axis| Ok((axis, reader.axis_columns(axis)?)))
                .collect::<anyhow::Result<_>>()?;
            let models = RunModels::Shared {
                models: shared,
                axes: columns.clone(),
            };
            for (evaluation, (axis, _)) in evaluate_reader(&models, reader)?.into_iter().zip(&columns) {
                let mut e = evaluation.0;
                e.axis = Some(axis.name());
                evals.push(("holdout", e));
            }
            continue;
        }
        for (&axis, (outcome, _)) in axes.iter().zip(&outcomes) {
            evals.push(("holdout", evaluate_file(&outcome.model, path, Some(axis))?));
        }
    }
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    let in_use = a.in_use()?;
    for (axis, (outcome, _)) in axes.iter().zip(&outcomes) {
        if let Some(search) = outcome.bank_search() {
            writeln!(out, "\naxis {}:", axis.name())?;
            for line in search
                .coverage
                .lines(&in_use, trainer::fit::coverage::model_range_c(&outcome.model))
            {
                writeln!(out, "{line}")?;
            }
            write_vouching(
                &mut out,
                outcome,
                &in_use,
                training_settled_floor(&evals, Some(axis.name())).as_ref(),
            )?;
        }
    }
    // Each axis judged on its own holdout evaluations, forecast and coverage.
    let verdicts: Vec<Option<Verdict>> = axes
        .iter()
        .zip(&outcomes)
        .map(|(axis, (o, _))| {
            calibration
                .spec
                .map(|spec| judge_axis(spec, &in_use, o, &evals, Some(axis.name())))
        })
        .collect();
    for (axis, verdict) in axes.iter().zip(&verdicts) {
        if let Some(v) = verdict {
            writeln!(out, "\naxis {}: {}", axis.name(), verdict_text(v))?;
        }
    }
    writeln!(
        out,
        "\nwrote {} ({} bytes, axes {})",
        text::path(&a.output),
        blob.len(),
        trainer::evaluation::axes::names(axes)
    )?;
    let acceptance =
        |v: &Verdict| serde_json::json!({"status": if v.passed() { "pass" } else { "fail" }, "reasons": v.reasons});
    let unit_reasons: Vec<String> = axes
        .iter()
        .zip(&verdicts)
        .flat_map(|(axis, v)| {
            v.iter()
                .flat_map(move |v| v.reasons.iter().map(move |r| format!("axis {}: {r}", axis.name())))
        })
        .collect();
    let json = serde_json::json!({
        "method": opts.method.name(),
        "axes": axes.iter().zip(&outcomes).zip(&verdicts).map(|((axis, (o, _)), v)| {
            let mut axis_json = outcome_json(o, &in_use, training_settled_floor(&evals, Some(axis.name())).as_ref());
            axis_json["axis"] = serde_json::json!(axis.name());
            axis_json["acceptance"] = v.as_ref().map_or(serde_json::Value::Null, acceptance);
            axis_json
        }).collect::<Vec<_>>(),
        "joint": joint.json,
        "fit_seconds": fit_s,
        "blob_bytes": blob.len(),
        "runs": runs_json(&evals),
        "acceptance": match calibration.spec {
            Some(_) => acceptance(&Verdict { reasons: unit_reasons.clone() }),
            None => serde_json::Value::Null,
        },
    });
    let mut transaction = Transaction::new();
    write_blob(model_out, &blob, &mut transaction)?;
    let json_on_stdout = json_out.is_stdout();
    let json_doc = json;
    let json = json_out.write(&json_doc, &mut transaction)?;
    print_json_and_commit(&out, json_on_stdout, json, transaction)?;
    write_records(calibration.store, a.serial.as_deref(), &json_doc, &blob)?;
    if unit_reasons.is_empty() {
        Ok(())
    } else {
        Err(Rejected(format!(
            "the unit missed its acceptance spec: {}",
            unit_reasons.join("; ")
        ))
        .into())
    }
}
