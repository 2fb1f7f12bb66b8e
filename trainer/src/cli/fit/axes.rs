//! `trainer fit` on multi-axis runs: every axis fitted by the single-axis
//! fit (its full model search, the axes in parallel), one multi-axis blob,
//! the summary per axis and the accuracy table per run and axis.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use rbf_core::record::Axis;
use trainer::blobfile::encode_axis_models;
use trainer::dataset::RunFiles;
use trainer::evaluate::{RunEvaluation, evaluate_axis_file, print_table};
use trainer::fit::{self, FitOptions, FitOutcome};
use trainer::output::Output;
use trainer::run::RunReader;
use trainer::text;

use super::super::common::{JsonSink, print_text};
use super::{Args, FitHow, features_json, write_summary};

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
    let started = std::time::Instant::now();
    let outcomes = fit_axes(a, opts, axes)?;
    let fit_s = started.elapsed().as_secs_f64();
    let models: Vec<(Axis, &rbf_core::Model)> = axes.iter().copied().zip(outcomes.iter().map(|o| &o.model)).collect();
    let blob = encode_axis_models(&models)?;

    let mut out: Vec<u8> = Vec::new();
    for (axis, outcome) in axes.iter().zip(&outcomes) {
        writeln!(out, "axis {}:", axis.name())?;
        write_summary(&mut out, opts.method, outcome, how)?;
    }
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    let roles = [("train", &a.runs), ("validate", &a.validate), ("holdout", &a.holdout)];
    let mut evals: Vec<(&str, RunEvaluation)> = Vec::new();
    for (role, paths) in roles {
        for path in paths.iter() {
            for (&axis, outcome) in axes.iter().zip(&outcomes) {
                evals.push((role, evaluate_axis_file(&outcome.model, path, Some(axis))?));
            }
        }
    }
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    for (axis, outcome) in axes.iter().zip(&outcomes) {
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
        "axes": axes.iter().zip(&outcomes).map(|(axis, o)| serde_json::json!({
            "axis": axis.name(),
            "choice": o.choice,
            "feature_sets": o.sets,
            "lag_bank_search": o.bank,
            "features": features_json(o.model.features()),
            "svr": o.svr,
        })).collect::<Vec<_>>(),
        "fit_seconds": fit_s,
        "blob_bytes": blob.len(),
        "runs": evals.iter().map(|(role, e)| serde_json::json!({"role": role, "evaluation": e})).collect::<Vec<_>>(),
    });
    if let Some(mut output) = model_out {
        output
            .write_all(&blob)
            .with_context(|| format!("{}: write failed", text::path(output.path())))?;
        output.commit()?;
    }
    let json_on_stdout = json_out.is_stdout();
    json_out.write(&json)?;
    print_text(&out, json_on_stdout)?;
    Ok(())
}

/// The single-axis fit of each axis, on threads of their own (a fit's
/// result does not depend on what runs beside it), in the order of `axes`.
fn fit_axes(a: &Args, opts: &FitOptions, axes: &[Axis]) -> anyhow::Result<Vec<FitOutcome>> {
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
                scope.spawn(move || {
                    let train = RunFiles::for_axis(&a.runs, Some(axis));
                    let validate = RunFiles::for_axis(&a.validate, Some(axis));
                    fit::fit(&train, &validate, opts).with_context(|| format!("axis {}", axis.name()))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().map_err(|_| anyhow::anyhow!("a fit thread panicked"))?)
            .collect()
    })
}
