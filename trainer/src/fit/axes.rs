//! The fit of multi-axis runs: every axis fitted by the single-axis fit (its
//! full model search, the axes in parallel) and the joint three-axis policy,
//! which tries one shared basis for every axis and chooses it or a model per
//! axis. It uses the single-axis [`fit`](super::fit()) and
//! [`crate::evaluation::evaluate`] (it scores the fits on their block means);
//! `trainer fit` prints and writes what it gives.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use rbf_core::axis::Axis;
use rbf_core::shared_basis::SharedAxisModels;

use crate::dataset::{RunFiles, RunSet};
use crate::evaluation::evaluate::{RunEvaluation, SharedAxis, evaluate_blocks};
use crate::fit::{self, FitOptions, FitOutcome};
use crate::reading::run::RunReader;
use crate::text;

/// The runs of a multi-axis fit, by role.
#[derive(Clone, Copy, Debug)]
pub struct AxisRuns<'a> {
    /// Runs the models are fitted on.
    pub train: &'a [PathBuf],
    /// Runs that choose the hyper-parameters (and score the joint model when there are any).
    pub validate: &'a [PathBuf],
    /// Runs only reported, never used to choose.
    pub holdout: &'a [PathBuf],
}

/// Whether the multi-axis fit writes one shared basis for every axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JointMode {
    /// The joint model when every axis stays within [`JOINT_TOLERANCE_POINTS`] of its own fit.
    #[default]
    Auto,
    /// The joint model whatever it costs (`trainer fit --joint`).
    Always,
    /// A model per axis, the joint model not tried (`trainer fit --no-joint`).
    Never,
}

/// Points (of 100-s cluster STD improvement) a joint model's axis may lose
/// against the axis's own fit and still be chosen.
pub const JOINT_TOLERANCE_POINTS: f64 = 0.5;

/// The joint model tried beside the per-axis fits ([`try_joint`]).
pub struct JointTrial {
    /// The shared-basis model, when chosen.
    pub chosen: Option<Box<SharedAxisModels>>,
    /// Per axis (as [`fit_axes`]), the joint model's runs scored as the per-axis fits' are.
    pub scored: Vec<Vec<(&'static str, usize, RunEvaluation)>>,
    /// What the fit summary says about it.
    pub summary: String,
    /// The same for the JSON report.
    pub json: serde_json::Value,
}

/// Tries one shared-basis model for every axis: the basis is the structure
/// the full search chose on the first axis (features, normalisation,
/// centres, width, ridge), each axis's output layer refitted on its own
/// block means ([`fit::joint::refit_layers`]). It is chosen when, on the
/// fit's own scoring (the validation runs' block means when there are
/// validation runs, else the training runs'), every axis's 100-s cluster STD
/// improvement is within [`JOINT_TOLERANCE_POINTS`] of its own fit's, or
/// when `mode` is [`JointMode::Always`] (`--joint`); [`JointMode::Never`]
/// (`--no-joint`) does not try it. (MSD, dominated by white noise, hid a basis
/// that misfits an axis's thermal structure: on a simulated IMU it scored an
/// axis's joint and own fits alike where their STD100 differed by more than
/// the tolerance.)
/// Runs whose axes have their own thermometers keep the per-axis models (a
/// shared basis reads one thermometer), as do fits that are not Gaussian RBF
/// networks.
pub fn try_joint(
    runs: &AxisRuns,
    opts: &FitOptions,
    axes: &[Axis],
    outcomes: &[AxisFit],
    mode: JointMode,
) -> anyhow::Result<JointTrial> {
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
    if mode == JointMode::Never {
        return Ok(not_tried("--no-joint".to_owned()));
    }
    for path in runs.train.iter().chain(runs.validate).chain(runs.holdout) {
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
    let Some(ridge) = first.rbf_choice().map(|c| c.ridge) else {
        return Ok(not_tried(format!(
            "the fit of axis {} is not a Gaussian RBF network",
            first_axis.name()
        )));
    };
    let trains: Vec<RunFiles> = axes
        .iter()
        .map(|&axis| RunFiles::for_axis(runs.train, Some(axis)))
        .collect();
    let pairs: Vec<(Axis, &RunFiles)> = axes.iter().copied().zip(&trains).collect();
    let shared = match fit::joint::refit_layers(&first.model, ridge, &pairs, opts.block_s) {
        Ok(shared) => Box::new(shared),
        Err(e) => return Ok(not_tried(format!("{e:#}"))),
    };
    let role_of_choice = if runs.validate.is_empty() { "train" } else { "validate" };
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
        for (role, paths) in [("train", runs.train), ("validate", runs.validate)] {
            if paths.is_empty() {
                continue;
            }
            let files = RunFiles::for_axis(paths, Some(axis));
            let blocks = files.block_means(shared.features(), opts.block_s)?;
            for (i, path) in files.paths().iter().enumerate() {
                let mut reader = RunReader::open(path)?;
                reader.select_axis(axis)?;
                let has_ref = reader.columns().ref_dph.is_some();
                let scored = SharedAxis { models: &shared, axis };
                let mut e = evaluate_blocks(&scored, &blocks, i, path, opts.block_s, has_ref);
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
    let forced = mode == JointMode::Always;
    let chosen = all_within || forced;
    lines.push_str(if all_within {
        "chose: the joint model (every axis within 0.5 points of its own fit; the firmware evaluates one basis for \
         all axes)\n"
    } else if forced {
        "chose: the joint model (--joint; an axis lost more than 0.5 points with it)\n"
    } else {
        "chose: a model per axis (an axis lost more than 0.5 points with the joint model; --joint takes it anyway)\n"
    });
    Ok(JointTrial {
        chosen: chosen.then_some(shared),
        scored,
        summary: lines,
        json: serde_json::json!({
            "tried": true, "chosen": chosen, "forced": forced && !all_within, "basis_axis": first_axis.name(),
            "scored_on": role_of_choice, "tolerance_points": JOINT_TOLERANCE_POINTS, "axes": axis_json,
        }),
    })
}

/// What [`fit_axes`] gives per axis: the fit, and its training and
/// validation runs scored on the fit's block means (role, run index, evaluation).
pub type AxisFit = (FitOutcome, Vec<(&'static str, usize, RunEvaluation)>);

/// The single-axis fit of each axis, on threads of their own (a fit's
/// result does not depend on what runs beside it), in the order of `axes`.
pub fn fit_axes(runs: &AxisRuns, opts: &FitOptions, axes: &[Axis]) -> anyhow::Result<Vec<AxisFit>> {
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
                    let train = RunFiles::for_axis(runs.train, Some(axis));
                    let validate = RunFiles::for_axis(runs.validate, Some(axis));
                    let outcome = fit::fit(&train, &validate, opts).with_context(|| format!("axis {}", axis.name()))?;
                    let mut scored = Vec::new();
                    for (role, files) in [("train", &train), ("validate", &validate)] {
                        if files.count() == 0 {
                            continue;
                        }
                        let blocks = files.block_means(outcome.model.features(), opts.block_s)?;
                        for (i, path) in files.paths().iter().enumerate() {
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
