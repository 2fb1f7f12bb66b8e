//! `trainer fit` on multi-axis runs: every axis fitted by the single-axis
//! fit (its full model search, the axes in parallel), one multi-axis blob,
//! the summary per axis and the accuracy table per run and axis.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use rbf_core::MAX_AXIS_CENTERS;
use rbf_core::axis::Axis;
use rbf_core::shared_basis::SharedAxisModels;
use std::fmt::Write as _;
use trainer::blobfile::{encode_axis_models, encode_shared_models};
use trainer::dataset::{RunFiles, RunSet};
use trainer::evaluate::{
    RunEvaluation, RunModels, evaluate_blocks, evaluate_blocks_with, evaluate_file, evaluate_reader, print_table,
};
use trainer::fit::{self, FitOptions, FitOutcome};
use trainer::output::{Output, Transaction};
use trainer::run::RunReader;
use trainer::text;

use super::super::common::{JsonSink, print_and_commit};
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
    let joint = try_joint(a, opts, axes, &outcomes)?;
    let fit_s = started.elapsed().as_secs_f64();
    let models: Vec<(Axis, &rbf_core::Model)> = axes.iter().copied().zip(outcomes.iter().map(|o| &o.0.model)).collect();
    let blob = match &joint.chosen {
        Some(shared) => encode_shared_models(shared)?,
        None => encode_axis_models(&models)?,
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
    for (axis, (outcome, _)) in axes.iter().zip(&outcomes) {
        if let Some(search) = &outcome.bank {
            writeln!(out, "\naxis {}:", axis.name())?;
            for line in search.coverage.lines(&a.in_use()?) {
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
        "joint": joint.json,
        "fit_seconds": fit_s,
        "blob_bytes": blob.len(),
        "runs": runs_json(&evals),
    });
    let mut transaction = Transaction::new();
    write_blob(model_out, &blob, &mut transaction)?;
    let json_on_stdout = json_out.is_stdout();
    json_out.write(&json, &mut transaction)?;
    print_and_commit(&out, json_on_stdout, transaction)?;
    Ok(())
}

/// Points (of 100-s cluster STD improvement) a joint model's axis may lose
/// against the axis's own fit and still be chosen.
const JOINT_TOLERANCE_POINTS: f64 = 0.5;

/// The joint model tried beside the per-axis fits ([`try_joint`]).
struct JointTrial {
    /// The shared-basis model, when chosen.
    chosen: Option<Box<SharedAxisModels>>,
    /// Per axis (as `fit_axes`), the joint model's runs scored as the per-axis fits' are.
    scored: Vec<Vec<(&'static str, usize, RunEvaluation)>>,
    /// What the fit summary says about it.
    summary: String,
    /// The same for the JSON report.
    json: serde_json::Value,
}

/// Tries one shared-basis model for every axis: the basis is the structure
/// the full search chose on the first axis (features, normalisation,
/// centres, width, ridge), each axis's output layer refitted on its own
/// block means ([`fit::joint::refit_layers`]). It is chosen when, on the
/// fit's own scoring (the validation runs' block means when there are
/// validation runs, else the training runs'), every axis's 100-s cluster STD
/// improvement is within [`JOINT_TOLERANCE_POINTS`] of its own fit's, or
/// when `--joint` asks for it. (MSD, dominated by white noise, hid a basis
/// that misfits an axis's thermal structure: on a simulated IMU it scored an
/// axis's joint and own fits alike where their STD100 differed by more than
/// the tolerance.)
/// Runs whose axes have their own thermometers keep the per-axis models (a
/// shared basis reads one thermometer), as do fits that are not Gaussian RBF
/// networks.
fn try_joint(a: &Args, opts: &FitOptions, axes: &[Axis], outcomes: &[AxisFit]) -> anyhow::Result<JointTrial> {
    let not_tried = |why: String| JointTrial {
        chosen: None,
        scored: Vec::new(),
        summary: format!("joint model (one basis for every axis): not tried: {why}\nchose: a model per axis\n"),
        json: serde_json::json!({ "tried": false, "chosen": false, "why": why }),
    };
    let (Some(&first_axis), Some((first, _))) = (axes.first(), outcomes.first()) else {
        return Ok(not_tried("no axis".to_owned()));
    };
    if axes.len() < 2 {
        return Ok(not_tried("one axis".to_owned()));
    }
    if a.no_joint {
        return Ok(not_tried("--no-joint".to_owned()));
    }
    for path in a.runs.iter().chain(&a.validate).chain(&a.holdout) {
        let reader = RunReader::open(path)?;
        let first_temps = reader.axis_columns(first_axis)?.temps;
        for &axis in axes {
            if reader.axis_columns(axis)?.temps != first_temps {
                return Ok(not_tried(format!(
                    "{} gives each axis its own thermometer; one basis reads one thermometer (temp_c)",
                    text::path(path)
                )));
            }
        }
    }
    let Some(ridge) = first.choice.as_ref().map(|c| c.ridge) else {
        return Ok(not_tried(format!(
            "the fit of axis {} is not a Gaussian RBF network",
            first_axis.name()
        )));
    };
    let trains: Vec<RunFiles> = axes.iter().map(|&axis| RunFiles::for_axis(&a.runs, Some(axis))).collect();
    let pairs: Vec<(Axis, &RunFiles)> = axes.iter().copied().zip(&trains).collect();
    let shared = match fit::joint::refit_layers(&first.model, ridge, &pairs, opts.block_s) {
        Ok(shared) => Box::new(shared),
        Err(e) => return Ok(not_tried(format!("{e:#}"))),
    };
    let role_of_choice = if a.validate.is_empty() { "train" } else { "validate" };
    let mut scored = Vec::new();
    let mut lines = format!(
        "joint model (one basis for every axis: the structure fitted on axis {}, {} centre{}; each axis's output \
         layer refitted), STD100 improvement on the {role_of_choice} runs' block means, joint vs the axis's own fit:\n",
        first_axis.name(),
        shared.centers_used(),
        if shared.centers_used() == 1 { "" } else { "s" }
    );
    let mut axis_json = Vec::new();
    let mut all_within = true;
    for (&axis, (_, own_scored)) in axes.iter().zip(outcomes) {
        let mut axis_scored = Vec::new();
        for (role, paths) in [("train", &a.runs), ("validate", &a.validate)] {
            if paths.is_empty() {
                continue;
            }
            let runs = RunFiles::for_axis(paths, Some(axis));
            let blocks = runs.block_means(shared.features(), opts.block_s)?;
            for (i, path) in runs.paths().iter().enumerate() {
                let mut reader = RunReader::open(path)?;
                reader.select_axis(axis)?;
                let has_ref = reader.columns().ref_dph.is_some();
                let eval = |f: &rbf_core::FeatureVector| {
                    let e = shared.eval_axes(f);
                    (e.bias_dph.get(axis.index()).copied().unwrap_or(0.0), e.clamped)
                };
                let mut e = evaluate_blocks_with(eval, &blocks, i, path, opts.block_s, has_ref);
                e.axis = Some(axis.name());
                axis_scored.push((role, i, e));
            }
        }
        let mean = |s: &[(&str, usize, RunEvaluation)]| {
            let v: Vec<f64> = s
                .iter()
                .filter(|(r, _, _)| *r == role_of_choice)
                .map(|(_, _, e)| e.cluster_std_improvement_pct)
                .collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        let (joint_pct, own_pct) = (mean(&axis_scored), mean(own_scored));
        let within = joint_pct >= own_pct - JOINT_TOLERANCE_POINTS;
        all_within &= within;
        let _ = writeln!(
            lines,
            "  axis {}: {joint_pct:.2} % joint, {own_pct:.2} % own fit: {}",
            axis.name(),
            if within {
                format!("within {JOINT_TOLERANCE_POINTS} points")
            } else {
                format!("{:.2} points worse", own_pct - joint_pct)
            }
        );
        axis_json.push(serde_json::json!({
            "axis": axis.name(), "joint_std100_improvement_pct": joint_pct, "own_std100_improvement_pct": own_pct,
            "within_tolerance": within,
        }));
        scored.push(axis_scored);
    }
    let chosen = all_within || a.joint;
    lines.push_str(if all_within {
        "chose: the joint model (every axis within 0.5 points of its own fit; the firmware evaluates one basis for \
         all axes)\n"
    } else if a.joint {
        "chose: the joint model (--joint; an axis lost more than 0.5 points with it)\n"
    } else {
        "chose: a model per axis (an axis lost more than 0.5 points with the joint model; --joint takes it anyway)\n"
    });
    Ok(JointTrial {
        chosen: chosen.then_some(shared),
        scored,
        summary: lines,
        json: serde_json::json!({
            "tried": true, "chosen": chosen, "forced": a.joint && !all_within, "basis_axis": first_axis.name(),
            "scored_on": role_of_choice, "tolerance_points": JOINT_TOLERANCE_POINTS, "axes": axis_json,
        }),
    })
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
