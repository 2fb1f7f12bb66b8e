//! `trainer fit` on multi-axis runs: every axis fitted by the single-axis
//! fit (its full model search, the axes in parallel), one multi-axis blob,
//! the summary per axis and the accuracy table per run and axis.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use rbf_core::MAX_AXIS_CENTERS;
use rbf_core::record::Axis;
use trainer::blobfile::encode_axis_models;
use trainer::dataset::{RunFiles, RunSet};
use trainer::evaluate::{RunEvaluation, evaluate_axis_file, evaluate_blocks, print_table};
use trainer::fit::{self, FitOptions, FitOutcome};
use trainer::output::Output;
use trainer::run::RunReader;
use trainer::text;

use super::super::common::{JsonSink, print_text};
use super::{Args, FitHow, outcome_json, runs_json, write_blob, write_summary};

/// Fits every axis of `axes` on the runs of `a` with `opts`, writes the
/// blob into `model_out` and the JSON report into `json_out`, and prints
/// what `trainer fit` prints.
pub(super) fn run(
    a: &Args,
    opts: &FitOptions,
    how: &FitHow,
    axes: &[Axis],
    model_out: Option<Output>,
    json_out: JsonSink,
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
    if let Some(k) = opts.centers {
        anyhow::ensure!(
            k <= MAX_AXIS_CENTERS,
            "--centers {k}: a multi-axis model holds at most {MAX_AXIS_CENTERS} centres per axis (the three-axis \
             firmware's capacity)"
        );
    }
    let opts = &FitOptions {
        max_centers: opts.max_centers.min(MAX_AXIS_CENTERS),
        ..opts.clone()
    };
    let started = std::time::Instant::now();
    let outcomes = fit_axes(a, opts, axes)?;
    let fit_s = started.elapsed().as_secs_f64();
    let models: Vec<(Axis, &rbf_core::Model)> = axes.iter().copied().zip(outcomes.iter().map(|o| &o.0.model)).collect();
    let blob = encode_axis_models(&models)?;

    let mut out: Vec<u8> = Vec::new();
    for (axis, (outcome, _)) in axes.iter().zip(&outcomes) {
        writeln!(out, "axis {}:", axis.name())?;
        write_summary(&mut out, opts.method, outcome, how)?;
    }
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    // Training and validation runs scored on each axis's block means (as the
    // single-axis fit does), holdout runs sample by sample; a row per run and axis.
    let mut evals: Vec<(&str, RunEvaluation)> = Vec::new();
    for (role, paths) in [("train", &a.runs), ("validate", &a.validate)] {
        for p in 0..paths.len() {
            for (_, scored) in &outcomes {
                if let Some(e) = scored.iter().find(|(r, i, _)| *r == role && *i == p) {
                    evals.push((role, e.2.clone()));
                }
            }
        }
    }
    for path in &a.holdout {
        for (&axis, (outcome, _)) in axes.iter().zip(&outcomes) {
            evals.push(("holdout", evaluate_axis_file(&outcome.model, path, Some(axis))?));
        }
    }
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    for (axis, (outcome, _)) in axes.iter().zip(&outcomes) {
        if let Some(search) = &outcome.bank {
            writeln!(out, "\naxis {}:", axis.name())?;
            for line in search.coverage.lines() {
                writeln!(out, "{line}")?;
            }
        }
    }
    writeln!(
        out,
        "\nwrote {} ({} bytes, axes {})",
        text::path(&a.output),
        blob.len(),
        trainer::axes::names(axes)
    )?;
    let json = serde_json::json!({
        "method": opts.method,
        "axes": axes.iter().zip(&outcomes).map(|(axis, (o, _))| {
            let mut axis_json = outcome_json(o);
            axis_json["axis"] = serde_json::json!(axis.name());
            axis_json
        }).collect::<Vec<_>>(),
        "fit_seconds": fit_s,
        "blob_bytes": blob.len(),
        "runs": runs_json(&evals),
    });
    write_blob(model_out, &blob)?;
    let json_on_stdout = json_out.is_stdout();
    json_out.write(&json)?;
    print_text(&out, json_on_stdout)?;
    Ok(())
}

/// What [`fit_axes`] gives per axis: the fit, and its training and
/// validation runs scored on the fit's block means (role, run index, evaluation).
type AxisFit = (FitOutcome, Vec<(&'static str, usize, RunEvaluation)>);

/// The single-axis fit of each axis, on threads of their own (a fit's
/// result does not depend on what runs beside it), in the order of `axes`.
fn fit_axes(a: &Args, opts: &FitOptions, axes: &[Axis]) -> anyhow::Result<Vec<AxisFit>> {
    // One progress bar per axis would interleave: none.
    let opts = FitOptions {
        progress: false,
        ..opts.clone()
    };
    let opts = &opts;
    std::thread::scope(|scope| {
        let handles: Vec<_> = axes
            .iter()
            .map(|&axis| {
                scope.spawn(move || -> anyhow::Result<AxisFit> {
                    let train = RunFiles::for_axis(&a.runs, Some(axis));
                    let validate = RunFiles::for_axis(&a.validate, Some(axis));
                    let outcome =
                        fit::fit(&train, &validate, opts).with_context(|| format!("axis {}", axis.name()))?;
                    let mut scored = Vec::new();
                    for (role, runs) in [("train", &train), ("validate", &validate)] {
                        if runs.count() == 0 {
                            continue;
                        }
                        let blocks = runs.block_means(outcome.model.features(), opts.block_s)?;
                        for (i, path) in runs.paths().iter().enumerate() {
                            let mut reader = RunReader::open(path)?;
                            reader.select_axis(axis)?;
                            let has_ref = reader.columns().ref_dph.is_some();
                            let mut e = evaluate_blocks(&outcome.model, &blocks, i, path, opts.block_s, has_ref);
                            e.axis = Some(axis.name());
                            scored.push((role, i, e));
                        }
                    }
                    Ok((outcome, scored))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().map_err(|_| anyhow::anyhow!("a fit thread panicked"))?)
            .collect()
    })
}
