//! Compensation of whole runs and their before/after accuracy.

use std::path::Path;

use rbf_core::axis::Axis;
use rbf_core::record::Columns;
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::thermometer::ThermometerSet;
use rbf_core::{
    CompensatedSample, Compensator, CompensatorConfig, FeatureVector, Flags, GyroSample, MAX_INPUTS, Model,
};
use serde::Serialize;

use crate::dataset::Blocks;
use crate::dataset::plateaus::{MinuteBlocker, SettledBias};
use crate::evaluation::allan::{self, AllanDeviation};
use crate::evaluation::diagnose::{Gaps, RunDiagnosis};
use crate::metrics::{BinMeans, CLUSTER_S, MSD_WINDOW_S, improvement_pct, msd_of_means, sample_std};
use crate::reading::chunked::Batch;
use crate::reading::run::RunReader;
use crate::reading::run::samples::Run;
use crate::text;

/// How many samples carried each flag.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FlagCounts {
    /// Flag 1: input clamped to the training range.
    pub input_clamped: usize,
    /// Flag 2: temperature sensor fault, last good value held.
    pub temp_sensor_fault: usize,
    /// Flag 4: no valid model, output uncompensated.
    pub no_valid_model: usize,
    /// Flag 8: features warming up.
    pub warming_up: usize,
    /// Flag 16: rate sample invalid.
    pub rate_invalid: usize,
}

impl FlagCounts {
    /// The counts in words, the flags that were set only:
    /// `clamped (1) 120, warming up (8) 45`, or `none`.
    pub fn summary(&self) -> String {
        let counts = [
            ("clamped (1)", self.input_clamped),
            ("temperature sensor fault (2)", self.temp_sensor_fault),
            ("no valid model (4)", self.no_valid_model),
            ("warming up (8)", self.warming_up),
            ("rate invalid (16)", self.rate_invalid),
        ];
        let set: Vec<String> = counts
            .iter()
            .filter(|(_, n)| *n > 0)
            .map(|(name, n)| format!("{name} {n}"))
            .collect();
        if set.is_empty() {
            "none".to_owned()
        } else {
            set.join(", ")
        }
    }

    pub(super) fn add(&mut self, flags: Flags, samples: usize) {
        let count = |bit: Flags| if flags.contains(bit) { samples } else { 0 };
        self.input_clamped += count(Flags::INPUT_CLAMPED);
        self.temp_sensor_fault += count(Flags::TEMP_SENSOR_FAULT);
        self.no_valid_model += count(Flags::NO_VALID_MODEL);
        self.warming_up += count(Flags::WARMING_UP);
        self.rate_invalid += count(Flags::RATE_INVALID);
    }
}

/// Before/after accuracy of one run.
#[derive(Clone, Debug, Serialize)]
pub struct RunEvaluation {
    /// The run file.
    pub run: String,
    /// The gyro axis of a multi-axis run (`x`, `y`, `z`); absent for a single-axis run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axis: Option<&'static str>,
    /// Number of samples (= output rows).
    /// What was scored: every sample (`samples`), or the block means a
    /// fit computed (`block means`, or `8-s block means` when a long run's
    /// blocks were merged: see [`evaluate_blocks`]).
    pub basis: String,
    /// Number of samples (= output rows; for block means, the samples behind them).
    pub samples: usize,
    /// What the rate was compared with: `ref_dph` or `run mean`.
    pub reference: &'static str,
    /// MSD of the raw rate (IFOG Eq. 24, 1-s means), °²/h².
    pub msd_before_dph2: f64,
    /// MSD of the compensated rate, °²/h².
    pub msd_after_dph2: f64,
    /// MSD improvement, %.
    pub msd_improvement_pct: f64,
    /// Bias STD of 100-s cluster means, raw, °/h.
    pub cluster_std_before_dph: f64,
    /// Bias STD of 100-s cluster means, compensated, °/h.
    pub cluster_std_after_dph: f64,
    /// Cluster-STD improvement, %.
    pub cluster_std_improvement_pct: f64,
    /// Samples per flag.
    pub flagged: FlagCounts,
    /// Overlapping Allan deviation of rate − reference, raw.
    pub allan_before: AllanDeviation,
    /// Overlapping Allan deviation of rate − reference, compensated.
    pub allan_after: AllanDeviation,
    /// The settled plateaus and the spread of their bias, before and after
    /// ([`crate::dataset::plateaus`]); `None` where the run was scored on a
    /// fit's block means, which do not keep the loop temperature.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub settled: Option<SettledBias>,
    /// The gaps in the run's time column, as `trainer eval` reports them
    /// ([`crate::evaluation::diagnose::Gaps`]); `None` (absent from the
    /// JSON) where another command scored the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gaps: Option<Gaps>,
}

/// [`RunEvaluation::reference`] of a run without `ref_dph`.
pub const RUN_MEAN: &str = "run mean";

impl RunEvaluation {
    /// The share of samples clamped to the model's training range (flag 1), %; NaN without samples.
    pub fn clamped_pct(&self) -> f64 {
        if self.samples == 0 {
            f64::NAN
        } else {
            100.0 * self.flagged.input_clamped as f64 / self.samples as f64
        }
    }
}

/// Compensates every sample of `run` (one output per input, always).
pub fn compensate_run(model: Option<&Model>, run: &Run) -> Vec<CompensatedSample> {
    let config = run.compensator_config();
    let mut compensator = Compensator::new();
    run.samples().map(|s| compensator.process(model, &config, &s)).collect()
}

/// Before/after accuracy of `model` on `run`.
pub fn evaluate_run(model: &Model, run: &Run) -> RunEvaluation {
    evaluate_output(run, &compensate_run(Some(model), run))
}

/// Before/after accuracy of `run` given its compensated output `out` (one per sample).
fn evaluate_output(run: &Run, out: &[CompensatedSample]) -> RunEvaluation {
    let reference = run.reference_dph();
    let mut evaluator = Evaluator::new(&run.path, run.nominal_period_s, run.ref_dph.is_some());
    for (i, o) in out.iter().enumerate().take(run.len()) {
        let r = reference.at(i);
        evaluator.push(
            run.time_s[i],
            run.temp_c[i],
            run.rate_dph[i] - r,
            o.rate_comp_dph as f64 - r,
            o.flags,
        );
    }
    evaluator.finish()
}

/// Before/after accuracy of `model` on the run in `path` (on `axis` of a multi-axis run;
/// `None`: a single-axis run), read in one streaming pass (memory: bin means and a bounded
/// Allan series, whatever the run's length); the evaluation names the axis. Without
/// `ref_dph` deviations are taken about their mean, which the MSD, cluster STD and Allan
/// deviation are blind to.
pub fn evaluate_file(model: &Model, path: &Path, axis: Option<Axis>) -> anyhow::Result<RunEvaluation> {
    let mut reader = RunReader::open(path)?;
    if let Some(axis) = axis {
        reader.select_axis(axis)?;
    }
    let (mut evaluation, _, _) = only_axis(evaluate_reader(&RunModels::one(Some(model), &reader), reader)?)?;
    evaluation.axis = axis.map(Axis::name);
    Ok(evaluation)
}

/// The one result of an evaluation or compensation of one axis.
pub fn only_axis<T>(results: Vec<T>) -> anyhow::Result<T> {
    results
        .into_iter()
        .next()
        .ok_or_else(|| anyhow::anyhow!("no axis was evaluated or compensated"))
}

/// [`RunEvaluation::basis`] of a sample-by-sample evaluation.
pub const SAMPLES: &str = "samples";
/// [`RunEvaluation::basis`] of [`evaluate_blocks`] on blocks as the fit
/// asked for them; merged blocks ([`Blocks::merge_pairs`]) say their length
/// before it ([`block_basis`]).
pub const BLOCK_MEANS: &str = "block means";

/// [`RunEvaluation::basis`] of blocks `length_s` long merged `doublings`
/// times: [`BLOCK_MEANS`], or e.g. `8-s block means` for merged blocks.
pub fn block_basis(doublings: u32, length_s: f64) -> String {
    if doublings == 0 {
        BLOCK_MEANS.to_owned()
    } else {
        format!("{length_s}-s {BLOCK_MEANS}")
    }
}

/// Before/after accuracy of `model` on run number `run` of `blocks` (the
/// block means a fit computed, `block_s` asked for, of `model`'s inputs),
/// without reading the run again: how `trainer fit` scores its training
/// runs. The model is evaluated at each block's mean inputs, which for 1-s
/// blocks differs from the mean of its per-sample outputs far below the
/// bias noise (`trainer eval` scores every sample). A long run's merged
/// blocks ([`Blocks::merge_pairs`]) are scored as they are, e.g. as 8-s
/// means (the MSD then of 8-s means, not 1-s ones), and the basis says so
/// ([`block_basis`]); samples the fit left out (warming
/// up, a thermometer fault) are not in the blocks, and a block counts as
/// clamped with all its samples when its mean inputs are. `has_ref`: the
/// targets are deviations from `ref_dph` (else from the run's mean).
pub fn evaluate_blocks(
    model: &impl BlockBias,
    blocks: &Blocks,
    run: usize,
    path: &Path,
    block_s: f64,
    has_ref: bool,
) -> RunEvaluation {
    let length_s = blocks.length_s(block_s);
    let mut evaluator = Evaluator::new(path, block_spacing_s(blocks, run, length_s), has_ref);
    evaluator.basis = block_basis(blocks.doublings, length_s);
    evaluator.settled = None;
    let dims = blocks.dims.min(MAX_INPUTS);
    for i in (0..blocks.len()).filter(|&i| blocks.run[i] == run) {
        let mut x = [0.0f32; MAX_INPUTS];
        for (x, v) in x.iter_mut().zip(&blocks.x[i][..dims]) {
            *x = *v as f32;
        }
        let (bias_dph, clamped) = model.bias_at(&FeatureVector::from_values(&x[..dims]));
        let flags = if clamped { Flags::INPUT_CLAMPED } else { Flags::NONE };
        let (time_s, samples) = (blocks.time_s.get(i), blocks.samples.get(i));
        let y = blocks.y[i];
        evaluator.push_mean(
            time_s.copied().unwrap_or(i as f64 * length_s),
            y,
            y - f64::from(bias_dph),
            flags,
            samples.map_or(1, |n| *n as usize),
        );
    }
    evaluator.finish()
}

/// What [`evaluate_blocks`] scores: a model evaluated at a block's mean inputs.
pub trait BlockBias {
    /// The bias at `inputs`, °/h, and whether they were clamped to the trained range.
    fn bias_at(&self, inputs: &FeatureVector) -> (f32, bool);
}

impl BlockBias for Model {
    fn bias_at(&self, inputs: &FeatureVector) -> (f32, bool) {
        let e = self.eval(inputs);
        (e.bias_dph, e.clamped)
    }
}

/// One axis of a shared-basis model, as [`evaluate_blocks`] scores it.
pub struct SharedAxis<'m> {
    /// The shared-basis model.
    pub models: &'m SharedAxisModels,
    /// The axis whose output layer is scored.
    pub axis: Axis,
}

impl BlockBias for SharedAxis<'_> {
    fn bias_at(&self, inputs: &FeatureVector) -> (f32, bool) {
        let e = self.models.eval_axes(inputs);
        (e.bias_dph.get(self.axis.index()).copied().unwrap_or(0.0), e.clamped)
    }
}

/// How far apart run `run`'s blocks of `length_s` seconds start, s: the
/// median step of their start times, never less than `length_s`. Blocks
/// shorter than the sample period hold one sample each and come one sample
/// period apart (a 0.2-Hz run in 1-s blocks: one block every 5 s); the
/// 100-s clusters then expect as many blocks as there are, not one a second.
fn block_spacing_s(blocks: &Blocks, run: usize, length_s: f64) -> f64 {
    let starts: Vec<f64> = (0..blocks.len().min(blocks.time_s.len()))
        .filter(|&i| blocks.run[i] == run)
        .map(|i| blocks.time_s[i])
        .collect();
    let mut steps: Vec<f64> = starts.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    if steps.is_empty() {
        return length_s;
    }
    let middle = steps.len() / 2;
    let (_, median, _) = steps.select_nth_unstable_by(middle, f64::total_cmp);
    median.max(length_s)
}

/// The models a run's axes are compensated with, whatever their count: what
/// [`evaluate_reader`] and [`compensate_reader`](super::compensate::compensate_reader) take. A single-axis run is one
/// [`RunModels::PerAxis`] entry on the reader's own columns ([`RunModels::one`]).
#[derive(Clone, Debug)]
pub enum RunModels<'m> {
    /// Each axis its own model (`None`: uncompensated, flag 4) and its columns (the first the
    /// reader's own, the others from [`RunReader::axis_columns`]), in output order.
    PerAxis(Vec<(Option<&'m Model>, Columns)>),
    /// One shared-basis model; each axis with its columns (x, y, z order), all read from one
    /// thermometer set ([`require_shared_thermometer`]), stepped together by
    /// [`Compensator::process_shared`], the step the firmware runs.
    Shared {
        /// The shared-basis model.
        models: &'m SharedAxisModels,
        /// The run's axes and their columns.
        axes: Vec<(Axis, Columns)>,
    },
}

impl<'m> RunModels<'m> {
    /// One model (`None`: uncompensated) on the reader's own columns: a single-axis run, or
    /// the axis [`RunReader::select_axis`] chose.
    pub fn one(model: Option<&'m Model>, reader: &RunReader) -> Self {
        RunModels::PerAxis(vec![(model, *reader.columns())])
    }

    /// Each axis's columns, in output order.
    pub(super) fn columns(&self) -> Vec<Columns> {
        match self {
            RunModels::PerAxis(axes) => axes.iter().map(|(_, c)| *c).collect(),
            RunModels::Shared { axes, .. } => axes.iter().map(|(_, c)| *c).collect(),
        }
    }

    /// Refuses a run without the thermometers the models read (without a model: the loop
    /// thermometer), and a shared-basis model on axes with their own thermometers.
    pub fn require_thermometers(&self, reader: &RunReader) -> anyhow::Result<()> {
        match self {
            RunModels::PerAxis(axes) => {
                for (model, columns) in axes {
                    let thermometers = model.map_or(ThermometerSet::LOOP, |m| m.features().set.thermometers());
                    reader.header().require_thermometers(columns, thermometers)?;
                }
                Ok(())
            }
            RunModels::Shared { models, .. } => {
                require_shared_thermometer(reader, &self.columns(), models.features().set.thermometers())
            }
        }
    }

    /// A fresh stepper: filter state for every axis, none of it warmed up.
    pub(super) fn stepper(&self) -> Stepper<'m> {
        match self {
            RunModels::PerAxis(axes) => Stepper::PerAxis(axes.iter().map(|(m, _)| (*m, Compensator::new())).collect()),
            RunModels::Shared { models, axes } => Stepper::Shared {
                models,
                axes: axes.iter().map(|(a, _)| *a).collect(),
                compensator: Compensator::new(),
            },
        }
    }
}

/// Before/after accuracy of each axis of the run `reader` reads, compensated with `models`
/// in one pass; per axis, in `models`' order, also what the rows showed ([`RunDiagnosis`])
/// and the number of compensated rows (no flag 4).
pub fn evaluate_reader(
    models: &RunModels<'_>,
    reader: RunReader,
) -> anyhow::Result<Vec<(RunEvaluation, RunDiagnosis, usize)>> {
    models.require_thermometers(&reader)?;
    evaluate_stepped(models.stepper(), &models.columns(), reader)
}

/// Refuses a shared-basis model on a run whose axes do not read one
/// thermometer set (per-axis coil thermometers), and a run without
/// `thermometers`.
pub fn require_shared_thermometer(
    reader: &RunReader,
    columns: &[Columns],
    thermometers: ThermometerSet,
) -> anyhow::Result<()> {
    if let Some(first) = columns.first() {
        reader.header().require_thermometers(first, thermometers)?;
        if columns.iter().any(|c| c.temps != first.temps) {
            anyhow::bail!(
                "{}: its axes have their own thermometers (temp_x_c …); a shared-basis model reads one thermometer \
                 for every axis (temp_c): fit a model on runs like it",
                text::path(reader.path())
            );
        }
    }
    Ok(())
}

/// How the axes of a run are stepped: one compensator and model per axis,
/// or one compensator for a shared-basis model of every axis.
#[allow(
    clippy::large_enum_variant,
    reason = "one stepper per run, built once: the shared variant's compensator (its filter state) is not worth a box"
)]
pub(super) enum Stepper<'m> {
    /// Per axis, in the order of the columns: its model (`None`:
    /// uncompensated) and its compensator.
    PerAxis(Vec<(Option<&'m Model>, Compensator)>),
    /// One shared-basis model; the axis of each column set, in order.
    Shared {
        models: &'m SharedAxisModels,
        axes: Vec<Axis>,
        compensator: Compensator,
    },
}

impl Stepper<'_> {
    /// One row's step: per axis (in the columns' order) its output into `out`.
    pub(super) fn step(
        &mut self,
        config: &CompensatorConfig,
        rows: &[(rbf_core::record::Row, GyroSample)],
        out: &mut Vec<CompensatedSample>,
    ) {
        out.clear();
        match self {
            Stepper::PerAxis(axes) => {
                for ((model, compensator), (_, sample)) in axes.iter_mut().zip(rows) {
                    out.push(compensator.process(*model, config, sample));
                }
            }
            Stepper::Shared {
                models,
                axes,
                compensator,
            } => {
                let Some((_, first)) = rows.first() else {
                    return;
                };
                let mut rates_dph = [0.0f32; rbf_core::axis::MAX_AXES];
                for (axis, (_, sample)) in axes.iter().zip(rows) {
                    if let Some(r) = rates_dph.get_mut(axis.index()) {
                        *r = sample.rate_dph;
                    }
                }
                let all = compensator.process_shared(Some(*models), config, first.dt_s, &first.temps_c, &rates_dph);
                out.extend(axes.iter().filter_map(|axis| all.get(axis.index()).copied()));
            }
        }
    }
}

/// The evaluation loop of [`evaluate_reader`].
fn evaluate_stepped(
    mut stepper: Stepper<'_>,
    columns: &[Columns],
    reader: RunReader,
) -> anyhow::Result<Vec<(RunEvaluation, RunDiagnosis, usize)>> {
    let path = reader.path().to_owned();
    let period_s = reader.nominal_period_s();
    let config = CompensatorConfig::for_nominal_period_s(period_s);
    let mut state: Vec<(Evaluator, RunDiagnosis, usize)> = columns
        .iter()
        .map(|columns| {
            (
                Evaluator::new(&path, period_s, columns.ref_dph.is_some()),
                RunDiagnosis::new(&path, period_s).named_by(reader.header().line(), columns),
                0,
            )
        })
        .collect();
    let parser = reader.header().row_parser();
    let mut rows = Vec::with_capacity(columns.len());
    let mut outputs = Vec::with_capacity(columns.len());
    let mut refused: Option<crate::reading::run::rows::RunError> = None;
    reader.for_each_batch(|batch| {
        for i in 0..batch.len() {
            if refused.is_some() {
                return;
            }
            if let Err(e) = rows_of_axes(&parser, columns, &batch, i, &mut rows) {
                refused = Some(e);
                return;
            }
            stepper.step(&config, &rows, &mut outputs);
            for (((evaluator, diagnosis, compensated), (row, _)), out) in state.iter_mut().zip(&rows).zip(&outputs) {
                let r = row.ref_dph.unwrap_or(0.0);
                evaluator.push(
                    row.time_s,
                    row.readings_c()[rbf_core::features::LOOP_THERMOMETER],
                    row.rate_dph - r,
                    out.rate_comp_dph as f64 - r,
                    out.flags,
                );
                diagnosis.push(batch.line(i), row);
                *compensated += usize::from(!out.flags.contains(Flags::NO_VALID_MODEL));
            }
        }
    })?;
    if let Some(e) = refused {
        return Err(e.into());
    }
    Ok(state
        .into_iter()
        .map(|(evaluator, diagnosis, compensated)| (evaluator.finish(), diagnosis, compensated))
        .collect())
}

/// Row `i` of `batch` as each of `columns` reads it (the first: the batch's
/// own columns, the row as parsed), with its gyro sample, into `out`; the
/// others' samples take the first's time step. A refused field's error
/// names the file, line and column.
pub(super) fn rows_of_axes(
    parser: &crate::reading::run::rows::RowParser,
    columns: &[Columns],
    batch: &Batch,
    i: usize,
    out: &mut Vec<(rbf_core::record::Row, GyroSample)>,
) -> Result<(), crate::reading::run::rows::RunError> {
    out.clear();
    let first = (batch.row(i), batch.sample(i));
    out.push(first);
    for c in columns.iter().skip(1) {
        let text = std::str::from_utf8(batch.line_text(i)).unwrap_or("");
        let row = parser.parse(c, batch.line(i), text)?;
        let sample = GyroSample::from_recorded(None, row.time_s, row.rate_dph, &row.readings_c());
        out.push((
            row,
            GyroSample {
                dt_s: first.1.dt_s,
                ..sample
            },
        ));
    }
    Ok(())
}

/// Refuses a run of `rows` rows where none could be compensated
/// (`compensated` = 0), naming the causes [`RunDiagnosis::causes`] finds
/// for `thermometers`, unless `allow_uncompensated`. A run
/// without rows has nothing to compensate and passes.
pub fn require_compensated(
    path: &Path,
    rows: usize,
    compensated: usize,
    diagnosis: &RunDiagnosis,
    thermometers: ThermometerSet,
    allow_uncompensated: bool,
) -> anyhow::Result<()> {
    if compensated > 0 || rows == 0 || allow_uncompensated {
        return Ok(());
    }
    let causes = diagnosis.causes(thermometers);
    let why = if causes.is_empty() {
        String::new()
    } else {
        format!(". Why: {}", causes.join("; "))
    };
    Err(NothingCompensated(format!(
        "{}: no row could be compensated: all {rows} carry flag 4 (uncompensated){why}",
        text::path(path)
    ))
    .into())
}

/// A run where no row could be compensated, refused unless the caller
/// accepts such runs; the message names the run and the causes.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct NothingCompensated(pub String);

/// Refuses a run that cannot be evaluated: fewer than 2 rows, or a bias
/// target that never varies (its before/after gains would be 0/0).
pub fn require_evaluable(path: &Path, rows: usize, diagnosis: &RunDiagnosis) -> anyhow::Result<()> {
    if rows < 2 {
        anyhow::bail!("{}: run has {rows} data rows; at least 2 are needed", text::path(path));
    }
    if diagnosis.target_is_constant() {
        anyhow::bail!("{}: {}", text::path(path), diagnosis.constant_target());
    }
    Ok(())
}

/// Accumulates a run's before/after accuracy sample by sample: 1-s and 100-s
/// bin means, flag counts, bounded Allan series ([`allan::Decimated`]) and
/// the 60-s blocks its settled plateaus are found in ([`MinuteBlocker`]).
pub struct Evaluator {
    run: String,
    basis: String,
    nominal_period_s: f64,
    has_ref: bool,
    samples: usize,
    flagged: FlagCounts,
    msd: [BinMeans; 2],
    clusters: [BinMeans; 2],
    allan: [allan::Decimated; 2],
    /// `None`: block means are scored, whose temperatures are not known here.
    settled: Option<MinuteBlocker>,
    /// Sum of the residual before compensation over every sample, °/h (the
    /// run mean is the reference of a run without `ref_dph`).
    before_sum_dph: f64,
}

impl Evaluator {
    /// An evaluator for the run at `path`, sampled every `nominal_period_s`;
    /// `has_ref`: deviations are from `ref_dph` (else about their mean).
    pub fn new(path: &Path, nominal_period_s: f64, has_ref: bool) -> Self {
        let bins = |bin_s| {
            [
                BinMeans::new(bin_s, nominal_period_s),
                BinMeans::new(bin_s, nominal_period_s),
            ]
        };
        Evaluator {
            run: text::path(path),
            basis: SAMPLES.to_owned(),
            nominal_period_s,
            has_ref,
            samples: 0,
            flagged: FlagCounts::default(),
            msd: bins(MSD_WINDOW_S),
            clusters: bins(CLUSTER_S),
            allan: [allan::Decimated::new(), allan::Decimated::new()],
            settled: Some(MinuteBlocker::new(nominal_period_s)),
            before_sum_dph: 0.0,
        }
    }

    /// Takes one sample at `time_s`: its loop temperature (°C, `None`: not
    /// read), raw and compensated deviation from the reference, °/h.
    pub fn push(&mut self, time_s: f64, temp_c: Option<f64>, before_dph: f64, after_dph: f64, flags: Flags) {
        if let Some(blocker) = &mut self.settled {
            blocker.push(
                time_s,
                temp_c,
                before_dph,
                after_dph,
                flags.contains(Flags::INPUT_CLAMPED),
            );
        }
        self.push_mean(time_s, before_dph, after_dph, flags, 1);
    }

    /// Takes the mean of `samples` samples starting at `time_s` (a block).
    fn push_mean(&mut self, time_s: f64, before_dph: f64, after_dph: f64, flags: Flags, samples: usize) {
        self.samples += samples;
        self.before_sum_dph += before_dph * samples as f64;
        self.flagged.add(flags, samples);
        for (k, v) in [before_dph, after_dph].into_iter().enumerate() {
            self.msd[k].push(time_s, v);
            self.clusters[k].push(time_s, v);
            self.allan[k].push(v);
        }
    }

    /// The evaluation.
    pub fn finish(self) -> RunEvaluation {
        let about_mean = !self.has_ref;
        let [msd_before, msd_after] = self.msd.map(|b| msd_of_means(&b.finish(), about_mean));
        let [std_before, std_after] = self.clusters.map(|b| sample_std(&b.finish()));
        let period = self.nominal_period_s;
        // Without ref_dph the reference is the run's mean rate.
        let offset_dph = if about_mean && self.samples > 0 {
            self.before_sum_dph / self.samples as f64
        } else {
            0.0
        };
        let settled = self.settled.map(|blocker| {
            let first_time_s = blocker.first_time_s().unwrap_or(0.0);
            SettledBias::of(&blocker.finish(), first_time_s, period, offset_dph)
        });
        let [allan_before, allan_after] = self.allan.map(|a| {
            let (series, factor) = a.finish();
            allan::analyse(&series, period * factor as f64)
        });
        RunEvaluation {
            run: self.run,
            axis: None,
            basis: self.basis,
            samples: self.samples,
            reference: if about_mean { RUN_MEAN } else { "ref_dph" },
            msd_before_dph2: msd_before,
            msd_after_dph2: msd_after,
            msd_improvement_pct: improvement_pct(msd_before, msd_after),
            cluster_std_before_dph: std_before,
            cluster_std_after_dph: std_after,
            cluster_std_improvement_pct: improvement_pct(std_before, std_after),
            flagged: self.flagged,
            allan_before,
            allan_after,
            settled,
            gaps: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::compensate::push_compensated_row;
    use rbf_core::record;

    #[test]
    fn a_fit_s_block_mean_scores_agree_with_scoring_every_sample() {
        use crate::dataset::{RunFiles, RunSet};
        // A 3-h, 1.5 °C/min run at 10 Hz; the default model fitted on it.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.csv");
        let mut sim = crate::simulate::ChamberRun::ifog(1.5, 3);
        sim.duration_s = Some(3.0 * 3600.0);
        sim.sample_rate_hz = 10.0;
        sim.write_csv(&mut std::fs::File::create(&path).unwrap()).unwrap();
        let train = RunFiles::new(std::slice::from_ref(&path));
        let opts = crate::fit::FitOptions {
            progress: false,
            ..crate::fit::FitOptions::default()
        };
        let model = crate::fit::fit(&train, &RunFiles::new(&[]), &opts).unwrap().model;
        let blocks = train.block_means(model.features(), opts.block_s).unwrap();
        let by_blocks = evaluate_blocks(&model, &blocks, 0, &path, opts.block_s, true);
        // Every sample scored, but the warm-up the fit leaves out.
        let run = Run::load(&path).unwrap();
        let out = compensate_run(Some(&model), &run);
        let mut evaluator = Evaluator::new(&path, run.nominal_period_s, true);
        for (i, o) in out
            .iter()
            .enumerate()
            .filter(|(_, o)| !o.flags.contains(Flags::WARMING_UP))
        {
            let r = run.ref_dph.as_ref().unwrap()[i];
            evaluator.push(
                run.time_s[i],
                run.temp_c[i],
                run.rate_dph[i] - r,
                f64::from(o.rate_comp_dph) - r,
                o.flags,
            );
        }
        let by_samples = evaluator.finish();
        assert_eq!(
            (by_blocks.basis.as_str(), by_samples.basis.as_str()),
            (BLOCK_MEANS, SAMPLES)
        );
        let close = |a: f64, b: f64, tolerance: f64, what: &str| {
            assert!((a / b - 1.0).abs() <= tolerance, "{what}: blocks {a}, samples {b}");
        };
        close(
            by_blocks.msd_before_dph2,
            by_samples.msd_before_dph2,
            0.01,
            "MSD before",
        );
        close(by_blocks.msd_after_dph2, by_samples.msd_after_dph2, 0.02, "MSD after");
        close(
            by_blocks.cluster_std_before_dph,
            by_samples.cluster_std_before_dph,
            0.01,
            "STD100 before",
        );
        close(
            by_blocks.cluster_std_after_dph,
            by_samples.cluster_std_after_dph,
            0.02,
            "STD100 after",
        );
        assert!(
            by_blocks.samples.abs_diff(by_samples.samples) <= 20,
            "{} samples against {}",
            by_blocks.samples,
            by_samples.samples
        );
    }

    #[test]
    fn flag_counts_read_as_words() {
        let mut c = FlagCounts::default();
        assert_eq!(c.summary(), "none");
        c.add(Flags::INPUT_CLAMPED, 12);
        c.add(Flags::WARMING_UP, 3);
        assert_eq!(c.summary(), "clamped (1) 12, warming up (8) 3");
    }

    #[test]
    fn compensated_rows_are_written_byte_for_byte_as_the_firmware_replay_writes_them() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let mut fast = Vec::new();
        let mut shared = String::new();
        for i in 0..200_000u32 {
            let bias_dph = match i % 4 {
                0 => f32::from_bits(rng.random()),
                1 => rng.random_range(-1.0f32..1.0),
                2 => (rng.random_range(-4096i32..4096) as f32) / 512.0,
                _ => rng.random_range(-1e6f32..1e6),
            };
            let sample = CompensatedSample {
                bias_dph,
                rate_comp_dph: 9.75 - bias_dph,
                temp_c: 20.0,
                flags: Flags(rng.random()),
            };
            let line = format!("{i}.01,9.75,20.0078125");
            let samples = [
                sample,
                CompensatedSample {
                    flags: Flags(i as u8),
                    ..sample
                },
            ];
            let n = 1 + (i % 2) as usize;
            push_compensated_row(&mut fast, line.as_bytes(), &samples[..n]);
            record::write_compensated_row(&mut shared, &line, &samples[..n]).unwrap();
        }
        assert_eq!(String::from_utf8(fast).unwrap(), shared);
    }
}
