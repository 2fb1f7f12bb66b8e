//! Multi-axis runs and models on the commands: which axes a set of runs
//! carries, which model serves each axis of a run, and `compensate` /
//! `eval` of every axis. Every axis count goes through the one path of
//! [`crate::evaluation::evaluate`] ([`RunModels`]: one entry per axis, or one shared basis).

use crate::evaluation::diagnose::RunDiagnosis;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;

use rbf_core::Model;
use rbf_core::axis::Axis;
use rbf_core::record::Columns;
use rbf_core::thermometer::ThermometerSet;

use crate::blobfile::{ModelFile, read_model_file};
use crate::evaluation::compensate::{Compensation, compensate_reader};
use crate::evaluation::evaluate::{RunEvaluation, RunModels, evaluate_reader, require_compensated, require_evaluable};
use crate::output::{self, Existing, Output};
use crate::reading::plausible::require_plausible;
use crate::reading::run::RunReader;
use crate::{reading::input, text};

/// Axis names as a message lists them, e.g. `x, y, z`.
pub fn names(axes: &[Axis]) -> String {
    axes.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
}

/// The axes every run of `paths` carries: empty for single-axis runs, the
/// same axes for all of them, else an error naming the run that differs.
pub fn common_axes(paths: &[&Path]) -> anyhow::Result<Vec<Axis>> {
    let mut first: Option<(&Path, Vec<Axis>)> = None;
    for path in paths {
        let axes = RunReader::open(path)?.axes();
        match &first {
            None => first = Some((path, axes)),
            Some((p, a)) if *a != axes => anyhow::bail!(
                "{} has {}, {} has {}: the runs of one fit carry the same axes",
                text::path(p),
                describe(a),
                text::path(path),
                describe(&axes)
            ),
            Some(_) => {}
        }
    }
    Ok(first.map(|(_, a)| a).unwrap_or_default())
}

/// `axes x, y, z` or `one axis (rate_dph)`.
fn describe(axes: &[Axis]) -> String {
    if axes.is_empty() {
        "one axis (rate_dph)".to_owned()
    } else {
        format!("axes {}", names(axes))
    }
}

/// The model of each axis of the run `reader` reads, with the axis's
/// columns, in x, y, z order (a single-axis run: the one model and the
/// run's columns). A single-axis model on a multi-axis run, or the
/// reverse, or a run axis the model lacks, is refused naming both files.
pub fn models_for_run<'m>(
    file: &'m ModelFile,
    model_path: &Path,
    reader: &RunReader,
) -> anyhow::Result<Vec<(Option<Axis>, &'m Model, Columns)>> {
    let run_axes = reader.axes();
    let mismatch = || {
        anyhow::anyhow!(
            "{} holds a model for {}, {} has {}: fit a model on runs like it",
            text::path(model_path),
            describe(&file.axes()),
            text::path(reader.path()),
            describe(&run_axes)
        )
    };
    if run_axes.is_empty() {
        let model = file.model(None).ok_or_else(mismatch)?;
        return Ok(vec![(None, model, *reader.columns())]);
    }
    run_axes
        .iter()
        .map(|&axis| {
            let model = file.model(Some(axis)).ok_or_else(mismatch)?;
            Ok((Some(axis), model, reader.axis_columns(axis)?))
        })
        .collect()
}

/// The axes of the run `reader` reads with their columns, x first, each
/// of which the shared-basis `file` must have a layer for (refused naming
/// both files, as [`models_for_run`]).
pub fn shared_axes_for_run(
    file: &ModelFile,
    model_path: &Path,
    reader: &RunReader,
) -> anyhow::Result<Vec<(Axis, Columns)>> {
    let run_axes = reader.axes();
    let model_axes = file.axes();
    if run_axes.is_empty() || run_axes.iter().any(|a| !model_axes.contains(a)) {
        anyhow::bail!(
            "{} holds a shared-basis model for {}, {} has {}: fit a model on runs like it",
            text::path(model_path),
            describe(&model_axes),
            text::path(reader.path()),
            describe(&run_axes)
        );
    }
    run_axes
        .iter()
        .map(|&axis| Ok((axis, reader.axis_columns(axis)?)))
        .collect()
}

/// Which runs a command accepts that it would otherwise refuse.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Acceptance {
    /// A run where no row could be compensated (`--allow-uncompensated`).
    pub uncompensated: bool,
    /// A run implausible as a gyro recording ([`crate::reading::plausible`], `--allow-implausible`).
    pub implausible: bool,
}

impl From<bool> for Acceptance {
    /// Accepts uncompensated runs or not; never implausible ones.
    fn from(uncompensated: bool) -> Self {
        Acceptance {
            uncompensated,
            implausible: false,
        }
    }
}

/// What compensating a run did, per axis (`None`: a single-axis run).
pub type AxisCompensations = Vec<(Option<Axis>, Compensation)>;

/// `trainer compensate`: the run at `run` (`-`: standard input) compensated
/// with the model file at `model_path` into `output`, every axis of a
/// multi-axis run with its own model. Every check comes first (the output
/// target against the inputs and `existing`, the model, the run's header);
/// the output appears only when the whole run is written, and not at all
/// when an axis had no row compensated or the run is implausible
/// ([`crate::reading::plausible`]), unless `accept` says so.
/// Returns what each axis's compensation did and the output, written but
/// not yet committed (the caller prints, then commits).
pub fn compensate_command(
    model_path: &Path,
    run: &Path,
    output: &Path,
    existing: Existing,
    accept: impl Into<Acceptance>,
) -> anyhow::Result<(AxisCompensations, Output)> {
    let accept = accept.into();
    input::check_stdin_once([model_path, run])?;
    let target = output::check_target(output, &[model_path, run], existing)?;
    let (file, blob) = read_model_file(model_path)?;
    let provenance = crate::blobfile::provenance_lines(model_path, &blob);
    let reader = RunReader::open(run)?;
    let (models, labels) = run_models(&file, model_path, &reader)?;
    models.require_thermometers(&reader)?;
    let mut out = Output::open(target)?;
    out.write_all(provenance.as_bytes())
        .with_context(|| format!("{}: cannot write", text::path(output)))?;
    // Errors of the run name it and the line; write errors name the output.
    let done = compensate_reader(&models, reader, &mut out).map_err(|e| {
        if e.is::<crate::reading::run::rows::RunError>() {
            e
        } else {
            e.context(text::path(output))
        }
    })?;
    let mut result = Vec::with_capacity(done.len());
    for ((axis, thermometers), c) in labels.into_iter().zip(done) {
        require_usable(run, c.rows, c.compensated, &c.diagnosis, thermometers, accept).map_err(|e| on_axis(e, axis))?;
        result.push((axis, c));
    }
    Ok((result, out))
}

/// An axis of a run as the commands report it: its name (`None`: a single-axis run) and
/// the thermometers its model reads.
type AxisLabel = (Option<Axis>, ThermometerSet);

/// The models of the model file at `model_path` for the axes of the run `reader` reads
/// ([`models_for_run`], or [`shared_axes_for_run`] for a shared-basis file), and per axis,
/// in the same order, its name (`None`: a single-axis run) and the thermometers its model
/// reads.
fn run_models<'m>(
    file: &'m ModelFile,
    model_path: &Path,
    reader: &RunReader,
) -> anyhow::Result<(RunModels<'m>, Vec<AxisLabel>)> {
    if let ModelFile::Shared(models) = file {
        let axes = shared_axes_for_run(file, model_path, reader)?;
        let thermometers = models.features().set.thermometers();
        let labels = axes.iter().map(|(axis, _)| (Some(*axis), thermometers)).collect();
        return Ok((RunModels::Shared { models, axes }, labels));
    }
    let pairs = models_for_run(file, model_path, reader)?;
    let labels = pairs
        .iter()
        .map(|(axis, model, _)| (*axis, model.features().set.thermometers()))
        .collect();
    let models = RunModels::PerAxis(
        pairs
            .into_iter()
            .map(|(_, model, columns)| (Some(model), columns))
            .collect(),
    );
    Ok((models, labels))
}

/// [`require_compensated`], then [`require_plausible`], as `accept` asks.
fn require_usable(
    run: &Path,
    rows: usize,
    compensated: usize,
    diagnosis: &RunDiagnosis,
    thermometers: ThermometerSet,
    accept: Acceptance,
) -> anyhow::Result<()> {
    require_compensated(run, rows, compensated, diagnosis, thermometers, accept.uncompensated)?;
    require_plausible(&diagnosis.implausible(), accept.implausible)
}

/// `e` with the axis named, where there is one.
fn on_axis(e: anyhow::Error, axis: Option<Axis>) -> anyhow::Error {
    match axis {
        Some(a) => e.context(format!("axis {}", a.name())),
        None => e,
    }
}

/// One axis's evaluation of run `path` as `trainer eval` reports it: refused
/// (naming the axis) when it cannot be evaluated or, unless
/// `accept`, when no row was compensated (`thermometers`: those the
/// model reads) or the run is implausible; labelled with its axis and the
/// run's gaps.
pub(crate) fn accept_evaluation(
    path: &Path,
    axis: Option<Axis>,
    thermometers: ThermometerSet,
    (mut evaluation, diagnosis, compensated): (RunEvaluation, RunDiagnosis, usize),
    accept: Acceptance,
) -> anyhow::Result<RunEvaluation> {
    require_evaluable(path, evaluation.samples, &diagnosis).map_err(|e| on_axis(e, axis))?;
    require_usable(path, evaluation.samples, compensated, &diagnosis, thermometers, accept)
        .map_err(|e| on_axis(e, axis))?;
    evaluation.axis = axis.map(Axis::name);
    evaluation.gaps = Some(diagnosis.gaps());
    Ok(evaluation)
}

/// What `trainer eval` found: the evaluations, and the notices of runs
/// with gaps in their time column ([`RunDiagnosis::gap_notice`]), one per
/// run file, in the runs' order.
pub type Evaluated = (Vec<RunEvaluation>, Vec<String>);

/// `trainer eval`: before/after accuracy of the model file on each run (`-`:
/// standard input), per axis for a multi-axis run, each run read once. A run
/// where no row could be compensated or that is implausible is refused
/// unless `accept` says so, as is one that cannot be evaluated
/// ([`require_evaluable`]).
pub fn evaluate_files(
    file: &ModelFile,
    model_path: &Path,
    paths: &[PathBuf],
    accept: impl Into<Acceptance>,
) -> anyhow::Result<Evaluated> {
    let accept = accept.into();
    input::check_stdin_once(paths.iter().map(|p| p.as_path()))?;
    let mut evaluations = Vec::new();
    let mut notices = Vec::new();
    for path in paths {
        let reader = RunReader::open(path)?;
        let (models, labels) = run_models(file, model_path, &reader)?;
        let done = evaluate_reader(&models, reader)?;
        // Every axis reads the one time column: its gaps are the run's.
        notices.extend(done.first().and_then(|(_, diagnosis, _)| diagnosis.gap_notice()));
        for ((axis, thermometers), done) in labels.into_iter().zip(done) {
            evaluations.push(accept_evaluation(path, axis, thermometers, done, accept)?);
        }
    }
    Ok((evaluations, notices))
}

/// The gap notice of a compensated run ([`RunDiagnosis::gap_notice`]):
/// its first axis's (every axis reads the one time column).
pub fn gap_notice(compensations: &AxisCompensations) -> Option<String> {
    compensations.first().and_then(|(_, c)| c.diagnosis.gap_notice())
}
