//! The per-sample compensation loop, for any number of axes: on each
//! data-ready edge, per axis the loop runs, read its front end, read the
//! thermometers its model needs (every `temp_read_every` samples),
//! compensate with rbf-core; then emit one output frame. Whatever the
//! sensors do, every call emits exactly one frame and returns; nothing in
//! here can panic on sensor data, and nothing waits on the output: a frame
//! the output cannot take whole is dropped, counted, and flagged on the
//! next frame that goes out ([`Flags::OUTPUT_DROPPED`]).
//!
//! A single gyro is the one-axis instance (`N = 1`, a single [`Model`]):
//! its frame is the single-axis [`OutputFrame`]. An IMU (`N = 3`) writes
//! one [`AxesFrame`] carrying all axes. With a model per axis
//! ([`AxisModels`], blob format 3) each axis goes through exactly the
//! single-axis step ([`Compensator::process_with`]), so an axis's output is what
//! a single-axis loop would give it; flags are per axis (one axis's failed
//! thermometer flags that axis alone, the others keep compensating). With a
//! shared-basis model ([`SharedAxisModels`], format 3 with the shared-basis
//! flag) one thermometer set serves every axis and one
//! [`Compensator::process_shared`] steps them all, the step `trainer
//! compensate` runs for such a blob; a failure of that thermometer is
//! every axis's (flag 2 on each, flag 4 once the hold runs out), while a
//! failed rate read still flags its axis alone. What concerns the frame (a
//! dropped frame, missed samples, a fault reset) flags every axis.

use embedded_io::Write;
use gyro_wire::frame::{self, AXES_FRAME_TAG, AxesFrame, AxisOutput, MAX_AXES_FRAME_LEN, MAX_FRAME_LEN, OutputFrame};
use rbf_core::axis::{Axis, MAX_AXES};
use rbf_core::blob::axes::AxisModels;
use rbf_core::features::{THERMOMETERS, ThermometerSet};
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::{CompensatedSample, Compensator, CompensatorConfig, Flags, GyroSample, MAX_CENTERS, Model};

use crate::sensors::{AxisFrontEnds, AxisThermometers, RateSample, Readings, SensorFault};

/// Writes `bytes` to `output` without waiting and without panicking: as
/// many `write` calls as make progress, then gives up. An output that takes
/// nothing (`Ok(0)`, which `embedded_io::Write::write_all` turns into a
/// panic), refuses (`WouldBlock`, any error) or takes part of the frame
/// leaves it unsent; false then. A transmit queue that takes frames whole
/// ([`crate::uart::FrameQueue`]) never leaves half a frame on the wire.
pub fn write_frame<W: Write>(output: &mut W, bytes: &[u8]) -> bool {
    let mut rest = bytes;
    // Each call either takes a byte or ends the loop: bounded by the frame length.
    while !rest.is_empty() {
        match output.write(rest) {
            Ok(n) if n > 0 => rest = rest.get(n..).unwrap_or(&[]),
            _ => return false,
        }
    }
    true
}

/// Settings of the loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopConfig {
    /// Gap detection, fault hold and plausibility limits (rbf-core).
    pub compensator: CompensatorConfig,
    /// Read the thermometers on every n-th gyro sample (≥ 1); in between the
    /// last readings stand. The TMP117 converts every 125 ms at 8 averages.
    pub temp_read_every: u32,
}

/// Counters a host can read to judge the loop's health.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoopStats {
    /// Samples processed (= frames emitted or attempted).
    pub samples: u32,
    /// Thermometer reads that failed (one per thermometer and read).
    pub temp_read_faults: u32,
    /// Front-end reads that failed.
    pub rate_read_faults: u32,
    /// Frames the output refused (the output is the only thing that can lose data).
    pub output_errors: u32,
    /// Data-ready edges that passed without a processed sample (see
    /// [`CompensationLoop::step_at`]).
    pub samples_missed: u32,
    /// Times the compensation filters restarted for a new model.
    pub filter_restarts: u32,
}

impl LoopStats {
    /// Counts the sample of data-ready edge `seq`, `next_seq` being the edge
    /// expected; moves `next_seq` past it. Edges between are counted in
    /// [`Self::samples_missed`]; returns true when there were any. A sequence
    /// number behind the expected one (a wrap or a board bug) is no gap; only
    /// a jump forward by less than half the range is.
    #[inline(always)]
    pub fn count_sample(&mut self, next_seq: &mut u32, seq: u32) -> bool {
        let missed = seq.wrapping_sub(*next_seq);
        *next_seq = seq.wrapping_add(1);
        self.samples = self.samples.wrapping_add(1);
        let gap = missed != 0 && missed < u32::MAX / 2;
        if gap {
            self.samples_missed = self.samples_missed.wrapping_add(missed);
        }
        gap
    }

    /// The rate, °/h, and whether the front end called it valid, from a
    /// front-end read; a failed read counts in [`Self::rate_read_faults`]
    /// and gives NaN, invalid.
    #[inline(always)]
    pub fn rate_or_fault(&mut self, read: Result<RateSample, SensorFault>) -> (f32, bool) {
        match read {
            Ok(s) => (s.rate_dph, s.valid),
            Err(_) => {
                self.rate_read_faults = self.rate_read_faults.wrapping_add(1);
                (f32::NAN, false)
            }
        }
    }
}

/// Where the loop's models live and what kind they are: owned (host tools
/// and tests), borrowed (the replay) or decoded in place into storage the
/// board owns ([`InPlaceModel`]); a single gyro's [`Model`] (one axis,
/// `N = 1`), a model per axis of an IMU ([`AxisModels`], `N` =
/// [`MAX_AXES`]) or one shared basis for every axis ([`SharedAxisModels`]).
/// `K` is the models' centre capacity. An image holds the step of the
/// kinds its holder can carry, no other.
pub trait ModelHolder<const K: usize = MAX_CENTERS, const N: usize = 1> {
    /// True when the holder carries a shared-basis model: the loop then
    /// reads one thermometer set and steps every axis at once
    /// ([`Compensator::process_shared`]).
    const SHARED: bool = false;

    /// `axis`'s model to run, if a blob gave a usable one (a single gyro's
    /// model is axis x's).
    fn model(&self, axis: Axis) -> Option<&Model<K>> {
        let _ = axis;
        None
    }

    /// The shared-basis model to run, if a blob gave a usable one.
    fn shared(&self) -> Option<&SharedAxisModels<K>> {
        None
    }

    /// True when a blob gave usable models (for some axis, or shared).
    fn loaded(&self) -> bool;

    /// One step of `axis`: `compensator` compensates `sample` with the
    /// axis's model ([`Compensator::process_with`]).
    #[inline(always)]
    fn process_axis(
        &self,
        axis: Axis,
        compensator: &mut Compensator,
        config: &CompensatorConfig,
        sample: &GyroSample,
    ) -> CompensatedSample {
        compensator.process_with(self.model(axis), config, sample)
    }
}

/// A model decoded in place into storage that outlives the loop (the
/// board's `static`): no model is ever moved by value. `M` is a
/// single-axis [`Model`], an IMU's [`AxisModels`] or a [`SharedAxisModels`].
#[derive(Debug)]
pub struct InPlaceModel<'m, M = Model> {
    storage: &'m mut M,
    valid: bool,
}

impl<'m, M> InPlaceModel<'m, M> {
    /// The model in `storage`, usable when `valid` (a decoder said so).
    pub fn new(storage: &'m mut M, valid: bool) -> Self {
        InPlaceModel { storage, valid }
    }

    /// Lets `decode` rebuild the model in place; it says whether the
    /// storage then holds a usable model.
    pub fn rebuild(&mut self, decode: impl FnOnce(&mut M) -> bool) {
        self.valid = decode(self.storage);
    }

    /// The model, if usable.
    pub fn get(&self) -> Option<&M> {
        self.valid.then_some(&*self.storage)
    }
}

/// How a holder reaches its model, whichever way it holds it.
trait HeldModel<M> {
    /// The model, if usable.
    fn held(&self) -> Option<&M>;
}

impl<M> HeldModel<M> for Option<M> {
    #[inline(always)]
    fn held(&self) -> Option<&M> {
        self.as_ref()
    }
}

impl<M> HeldModel<M> for Option<&M> {
    #[inline(always)]
    fn held(&self) -> Option<&M> {
        *self
    }
}

impl<M> HeldModel<M> for InPlaceModel<'_, M> {
    #[inline(always)]
    fn held(&self) -> Option<&M> {
        self.get()
    }
}

/// Implements [`ModelHolder`] for a holder of each model kind: owned,
/// borrowed and in place.
macro_rules! model_holders {
    ($model:ty; $($holder:ty),+) => {
        $(
            /// A single gyro: its model is axis x's.
            impl ModelHolder<MAX_CENTERS, 1> for $holder {
                #[inline(always)]
                fn model(&self, _axis: Axis) -> Option<&Model> {
                    <Self as HeldModel<$model>>::held(self)
                }

                fn loaded(&self) -> bool {
                    <Self as HeldModel<$model>>::held(self).is_some()
                }

                /// [`Compensator::process`]: the step rbf-core builds once
                /// for a single gyro's [`Model`] (the same arithmetic as
                /// every axis's; the single-axis board image is the smaller for it).
                #[inline(always)]
                fn process_axis(
                    &self,
                    _axis: Axis,
                    compensator: &mut Compensator,
                    config: &CompensatorConfig,
                    sample: &GyroSample,
                ) -> CompensatedSample {
                    compensator.process(<Self as HeldModel<$model>>::held(self), config, sample)
                }
            }
        )+
    };
}

/// Implements [`ModelHolder`] for holders of an IMU's models per axis.
macro_rules! axis_model_holders {
    ($model:ty; $($holder:ty),+) => {
        $(
            /// An IMU with a model per axis.
            impl<const K: usize> ModelHolder<K, MAX_AXES> for $holder {
                fn model(&self, axis: Axis) -> Option<&Model<K>> {
                    <Self as HeldModel<$model>>::held(self).and_then(|m| m.get(axis))
                }

                fn loaded(&self) -> bool {
                    <Self as HeldModel<$model>>::held(self).is_some()
                }
            }
        )+
    };
}

/// Implements [`ModelHolder`] for holders of an IMU's shared-basis model.
macro_rules! shared_model_holders {
    ($model:ty; $($holder:ty),+) => {
        $(
            /// An IMU with one shared basis for every axis.
            impl<const K: usize> ModelHolder<K, MAX_AXES> for $holder {
                const SHARED: bool = true;

                fn shared(&self) -> Option<&SharedAxisModels<K>> {
                    <Self as HeldModel<$model>>::held(self)
                }

                fn loaded(&self) -> bool {
                    <Self as HeldModel<$model>>::held(self).is_some()
                }
            }
        )+
    };
}

model_holders!(Model; Option<Model>, Option<&Model>, InPlaceModel<'_, Model>);
axis_model_holders!(AxisModels<K>; Option<AxisModels<K>>, Option<&AxisModels<K>>, InPlaceModel<'_, AxisModels<K>>);
shared_model_holders!(
    SharedAxisModels<K>;
    Option<SharedAxisModels<K>>,
    Option<&SharedAxisModels<K>>,
    InPlaceModel<'_, SharedAxisModels<K>>
);

/// The output of an axis the loop does not run: 0 bias, 0 rate, NaN temperature, flag 4.
const NO_AXIS: CompensatedSample = CompensatedSample {
    bias_dph: 0.0,
    rate_comp_dph: 0.0,
    temp_c: f32::NAN,
    flags: Flags::NO_VALID_MODEL,
};

/// The axis mask of every axis a loop of `n` axes can run (bit 0 = x).
const fn all_axes(n: usize) -> u8 {
    let n = if n < MAX_AXES { n } else { MAX_AXES };
    ((1u16 << n) - 1) as u8
}

/// The loop over `N` axes (1: a single gyro; [`MAX_AXES`]: an IMU) whose
/// models, of centre capacity `K`, `M` holds ([`ModelHolder`]); it owns
/// the sensors of every axis and the output.
pub struct CompensationLoop<T, R, W, M = Option<Model>, const K: usize = MAX_CENTERS, const N: usize = 1> {
    models: M,
    config: LoopConfig,
    /// The axes the IMU has (bit 0 = x).
    axis_mask: u8,
    thermometers: T,
    front_ends: R,
    output: W,
    compensators: [Compensator; N],
    latest_temps_c: [Readings; N],
    temp_read_due: bool,
    stats: LoopStats,
    temp_read_faults_per_axis: [u32; N],
    /// The sequence number the next sample should have.
    next_seq: u32,
    /// Flags for the next frame that goes out (a dropped frame, a fault reset).
    pending_flags: Flags,
}

impl<T: AxisThermometers, R: AxisFrontEnds, W: Write, M: ModelHolder<K, N>, const K: usize, const N: usize>
    CompensationLoop<T, R, W, M, K, N>
{
    /// A loop over every one of its `N` axes running `models` (none, or
    /// an axis without a model: that axis's output is uncompensated, flag 4).
    pub fn new(models: M, config: LoopConfig, thermometers: T, front_ends: R, output: W) -> Self {
        const { assert!(N >= 1 && N <= MAX_AXES, "a loop runs one to three axes") };
        CompensationLoop {
            models,
            config,
            axis_mask: all_axes(N),
            thermometers,
            front_ends,
            output,
            compensators: [Compensator::new(); N],
            latest_temps_c: [[None; THERMOMETERS]; N],
            temp_read_due: true,
            stats: LoopStats::default(),
            temp_read_faults_per_axis: [0; N],
            next_seq: 0,
            pending_flags: Flags::NONE,
        }
    }

    /// Marks the next frame (every axis) with `flags` (the board:
    /// [`Flags::FAULT_RESET`] after a reset by the fault handler or the watchdog).
    pub fn flag_next_frame(&mut self, flags: Flags) {
        self.pending_flags |= flags;
    }

    /// Sets the axes the IMU has (bit 0 = x; the loop's `N` axes at most)
    /// between two samples; the compensators start afresh.
    pub fn set_axis_mask(&mut self, axis_mask: u8) {
        self.axis_mask = axis_mask & all_axes(N);
        self.compensators = [Compensator::new(); N];
        self.temp_read_due = true;
    }

    /// True when the loop runs `axis`.
    pub fn has_axis(&self, axis: Axis) -> bool {
        self.axis_mask & (1 << axis.index()) != 0
    }

    /// Processes the sample data-ready announced on every axis; `dt_s` is
    /// the time since the previous one, s. Emits one frame and returns what
    /// it holds, per axis (x first; an axis the loop does not run: 0 bias,
    /// 0 rate, NaN temperature, flag 4).
    pub fn step(&mut self, dt_s: f32) -> [CompensatedSample; N] {
        self.step_at(self.next_seq, dt_s)
    }

    /// [`Self::step`] for the sample whose data-ready edge is number `seq`
    /// (counted by the board from timer timestamps, so edges that passed
    /// while the CPU was stalled count too). Edges between the previous
    /// sample and this one are counted in [`LoopStats::samples_missed`] and
    /// flagged ([`Flags::SAMPLES_MISSED`]); the frame carries `seq`.
    ///
    /// Budget per axis: one front-end read, one read per thermometer its
    /// model uses (every `temp_read_every` samples), one
    /// [`ModelHolder::process_axis`] (a shared-basis model: one
    /// [`Compensator::process_shared`] for all axes); then one write of a
    /// single-axis frame (one axis) or an [`AxesFrame`].
    pub fn step_at(&mut self, seq: u32, dt_s: f32) -> [CompensatedSample; N] {
        if self.stats.count_sample(&mut self.next_seq, seq) {
            self.pending_flags |= Flags::SAMPLES_MISSED;
        }
        let read_temps = self.temp_read_due || seq.is_multiple_of(self.config.temp_read_every.max(1));
        self.temp_read_due = false;
        let mut out = [NO_AXIS; N];
        let mut rates_dph = [0.0f32; N];
        if M::SHARED {
            self.step_shared(read_temps, dt_s, &mut out, &mut rates_dph);
        } else {
            for axis in Axis::ALL.into_iter().take(N) {
                if self.has_axis(axis)
                    && let (Some(o), Some(r)) = (out.get_mut(axis.index()), rates_dph.get_mut(axis.index()))
                {
                    (*o, *r) = self.step_axis(axis, read_temps, dt_s);
                }
            }
        }
        if self.emit(seq, &rates_dph, &out) {
            self.pending_flags = Flags::NONE;
        } else {
            self.stats.output_errors = self.stats.output_errors.wrapping_add(1);
            self.pending_flags = Flags::OUTPUT_DROPPED;
        }
        out
    }

    /// One axis's part of a step: its thermometers (when due), its rate, its
    /// compensator; returns its output and its rate, °/h. Not inlined: the
    /// board image holds one copy, not one per axis.
    #[inline(never)]
    fn step_axis(&mut self, axis: Axis, read_temps: bool, dt_s: f32) -> (CompensatedSample, f32) {
        let i = axis.index() % N;
        let model = self.models.model(axis);
        if read_temps {
            let wanted = model.map_or(ThermometerSet::LOOP.bits(), |m| m.features().set.thermometers().bits());
            let failed = self.thermometers.read_axis(axis, wanted, &mut self.latest_temps_c[i]);
            self.stats.temp_read_faults = self.stats.temp_read_faults.wrapping_add(failed);
            self.temp_read_faults_per_axis[i] = self.temp_read_faults_per_axis[i].wrapping_add(failed);
        }
        let (rate_dph, rate_ok) = self.stats.rate_or_fault(self.front_ends.read_axis_rate(axis));
        let sample = GyroSample {
            dt_s,
            rate_dph,
            temps_c: self.latest_temps_c[i],
        };
        let mut o = self
            .models
            .process_axis(axis, &mut self.compensators[i], &self.config.compensator, &sample);
        if !rate_ok {
            o.flags |= Flags::RATE_INVALID;
        }
        o.flags |= self.pending_flags;
        (o, rate_dph)
    }

    /// Every axis's part of a step under a shared-basis model: the one
    /// thermometer set (the first axis's; when due), every axis's rate, one
    /// [`Compensator::process_shared`] (one kernel evaluation for all axes).
    /// A failed thermometer read is every axis's: each gets flag 2 (flag 4
    /// once the hold runs out), and each axis's fault counter counts it.
    fn step_shared(&mut self, read_temps: bool, dt_s: f32, out: &mut [CompensatedSample; N], rates_dph: &mut [f32; N]) {
        let Some(first) = Axis::ALL.into_iter().find(|&a| self.has_axis(a)) else {
            return;
        };
        let t = first.index() % N;
        if read_temps {
            let wanted =
                (self.models.shared()).map_or(ThermometerSet::LOOP.bits(), |m| m.features().set.thermometers().bits());
            let failed = self.thermometers.read_axis(first, wanted, &mut self.latest_temps_c[t]);
            self.stats.temp_read_faults = self.stats.temp_read_faults.wrapping_add(failed);
            for axis in Axis::ALL {
                if self.has_axis(axis) {
                    let i = axis.index() % N;
                    self.temp_read_faults_per_axis[i] = self.temp_read_faults_per_axis[i].wrapping_add(failed);
                }
            }
        }
        let mut rates = [0.0f32; MAX_AXES];
        let mut rate_ok = [true; MAX_AXES];
        for axis in Axis::ALL {
            if self.has_axis(axis) {
                let i = axis.index() % MAX_AXES;
                (rates[i], rate_ok[i]) = self.read_rate(axis);
            }
        }
        let Some(compensator) = self.compensators.first_mut() else {
            return;
        };
        let all = compensator.process_shared(
            self.models.shared(),
            &self.config.compensator,
            dt_s,
            &self.latest_temps_c[t],
            &rates,
        );
        for (i, ((mut o, ok), rate)) in all.into_iter().zip(rate_ok).zip(rates).enumerate() {
            if self.axis_mask & (1 << i) == 0 {
                continue;
            }
            if !ok {
                o.flags |= Flags::RATE_INVALID;
            }
            o.flags |= self.pending_flags;
            if let (Some(slot), Some(r)) = (out.get_mut(i), rates_dph.get_mut(i)) {
                (*slot, *r) = (o, rate);
            }
        }
    }

    /// `axis`'s rate and whether it is valid (a failed read counted). Not
    /// inlined: the shared-basis image holds one copy, not one per axis.
    #[inline(never)]
    fn read_rate(&mut self, axis: Axis) -> (f32, bool) {
        self.stats.rate_or_fault(self.front_ends.read_axis_rate(axis))
    }

    /// Frames and writes the step's output: one axis as the single-axis
    /// [`OutputFrame`], more as one [`AxesFrame`]; false when the output
    /// did not take it whole.
    fn emit(&mut self, seq: u32, rates_dph: &[f32; N], out: &[CompensatedSample; N]) -> bool {
        if const { N == 1 } {
            match (rates_dph.first(), out.first()) {
                (Some(&rate_dph), Some(o)) => self.emit_axis_frame(seq, rate_dph, o),
                _ => false,
            }
        } else {
            self.emit_axes_frame(seq, rates_dph, out)
        }
    }

    /// Frames and writes one single-axis [`OutputFrame`].
    fn emit_axis_frame(&mut self, seq: u32, rate_dph: f32, out: &CompensatedSample) -> bool {
        let frame = OutputFrame {
            seq,
            rate_dph,
            bias_dph: out.bias_dph,
            rate_comp_dph: out.rate_comp_dph,
            temp_c: out.temp_c,
            flags: out.flags.bits(),
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        frame::encode(&frame, &mut buf)
            .ok()
            .and_then(|n| buf.get(..n))
            .is_some_and(|bytes| write_frame(&mut self.output, bytes))
    }

    /// Frames and writes one [`AxesFrame`] (an axis the loop does not run: zeros).
    fn emit_axes_frame(&mut self, seq: u32, rates_dph: &[f32; N], out: &[CompensatedSample; N]) -> bool {
        let mut axes = [AxisOutput::default(); MAX_AXES];
        for (axis, ((a, o), &rate_dph)) in Axis::ALL.into_iter().zip(axes.iter_mut().zip(out).zip(rates_dph)) {
            if self.has_axis(axis) {
                *a = AxisOutput {
                    rate_dph,
                    bias_dph: o.bias_dph,
                    rate_comp_dph: o.rate_comp_dph,
                    temp_c: o.temp_c,
                    flags: o.flags.bits(),
                };
            }
        }
        let frame = AxesFrame {
            tag: AXES_FRAME_TAG,
            seq,
            axis_mask: self.axis_mask,
            axes,
        };
        let mut buf = [0u8; MAX_AXES_FRAME_LEN];
        frame::encode_axes(&frame, &mut buf)
            .ok()
            .and_then(|n| buf.get(..n))
            .is_some_and(|bytes| write_frame(&mut self.output, bytes))
    }

    /// Switches to `models` (after a model update) between two samples; the
    /// feature filters start afresh, as the new models may compute others
    /// (and read other thermometers: they are read on the next sample).
    pub fn replace_model(&mut self, models: M) {
        self.update_model(|m| *m = models);
    }

    /// Changes the models in place between two samples (the board rebuilds
    /// its `static` model through [`InPlaceModel::rebuild`]); the feature
    /// filters start afresh as after [`Self::replace_model`].
    pub fn update_model(&mut self, change: impl FnOnce(&mut M)) {
        self.update_model_if(|m| {
            change(m);
            true
        });
    }

    /// Lets `command` act on the models between two samples; every axis's
    /// feature filters start afresh only when it says a model was installed
    /// (an unknown command, a refused blob or line noise changes nothing).
    pub fn update_model_if(&mut self, command: impl FnOnce(&mut M) -> bool) {
        if command(&mut self.models) {
            self.compensators = [Compensator::new(); N];
            self.temp_read_due = true;
            self.stats.filter_restarts = self.stats.filter_restarts.wrapping_add(1);
        }
    }

    /// The output (to interleave command replies between frames).
    pub fn output_mut(&mut self) -> &mut W {
        &mut self.output
    }

    /// The models in use, as held.
    pub fn models(&self) -> &M {
        &self.models
    }

    /// `axis`'s model in use (a single gyro's: axis x's).
    pub fn model(&self, axis: Axis) -> Option<&Model<K>> {
        self.models.model(axis)
    }

    /// Health counters (thermometer faults summed over the axes).
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// Thermometer reads that failed, per axis (x first).
    pub fn temp_read_faults_per_axis(&self) -> [u32; N] {
        self.temp_read_faults_per_axis
    }

    /// The thermometers and the front ends (their drivers' counters).
    pub fn sensors(&self) -> (&T, &R) {
        (&self.thermometers, &self.front_ends)
    }

    /// Gives the sensors and output back.
    pub fn destroy(self) -> (T, R, W) {
        (self.thermometers, self.front_ends, self.output)
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "the outputs compared are the same arithmetic on the same inputs: exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::sensors::{RateFrontEnd, Thermometer};
    use rbf_core::model::ModelBody;
    use rbf_core::poly::Poly3;
    use rbf_core::{FeatureConfig, FeatureSet, ModelInfo};

    /// A coil warming by 0.05 °C per read.
    struct Warming(f32);

    impl Thermometer for Warming {
        fn read_temp_c(&mut self) -> Result<f32, SensorFault> {
            self.0 += 0.05;
            Ok(self.0)
        }
    }

    /// A front end reading a constant rate, °/h.
    struct Steady(f32);

    impl RateFrontEnd for Steady {
        fn read_rate(&mut self) -> Result<RateSample, SensorFault> {
            Ok(RateSample {
                rate_dph: self.0,
                valid: true,
            })
        }
    }

    /// Bias = 0.5 °/h per °C of loop temperature.
    fn linear_in_t() -> Model {
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let body = ModelBody::Poly3(Poly3::new(0.0, [0.0, 0.5, 0.0, 0.0]).unwrap());
        Model::new(cfg, &[(-50.0, 100.0)], body, ModelInfo::default()).unwrap()
    }

    /// The frames in `bytes`, each with its COBS terminator.
    fn frames(bytes: &mut [u8]) -> impl Iterator<Item = &mut [u8]> {
        bytes.split_mut(|&b| b == 0).filter(|c| !c.is_empty())
    }

    #[test]
    fn an_imu_axis_is_compensated_as_a_single_gyro_and_each_loop_writes_its_own_frame() {
        let model = linear_in_t();
        let mut models = Box::new(AxisModels::<MAX_CENTERS>::EMPTY);
        models.insert(Axis::X, model.clone());
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(10.0),
            temp_read_every: 1,
        };
        let mut gyro = CompensationLoop::new(Some(model), config, Warming(20.0), Steady(15.0), Vec::new());
        let mut imu = CompensationLoop::new(
            Some(&*models),
            config,
            [Warming(20.0), Warming(21.0), Warming(22.0)],
            [Steady(15.0), Steady(16.0), Steady(17.0)],
            Vec::new(),
        );
        for i in 0..40 {
            let dt_s = if i == 0 { 0.0 } else { 0.1 };
            let [one] = gyro.step(dt_s);
            let [x, y, z] = imu.step(dt_s);
            assert_eq!(one, x, "sample {i}: axis x runs the single-gyro step");
            assert!(one.bias_dph > 10.0, "sample {i}: compensated");
            for other in [y, z] {
                assert!(
                    other.flags.contains(Flags::NO_VALID_MODEL),
                    "sample {i}: no model, flag 4"
                );
            }
        }
        let (_, _, mut single_bytes) = gyro.destroy();
        let (_, _, mut axes_bytes) = imu.destroy();
        let single: Vec<OutputFrame> = frames(&mut single_bytes).map(|f| frame::decode(f).unwrap()).collect();
        let axes: Vec<AxesFrame> = frames(&mut axes_bytes)
            .map(|f| frame::decode_axes(f).unwrap())
            .collect();
        assert_eq!((single.len(), axes.len()), (40, 40));
        for (s, a) in single.iter().zip(&axes) {
            assert_eq!((a.seq, a.axis_mask), (s.seq, 0b111));
            let x = a.axes[0];
            assert_eq!(
                (s.rate_dph, s.bias_dph, s.rate_comp_dph, s.flags),
                (x.rate_dph, x.bias_dph, x.rate_comp_dph, x.flags)
            );
        }
    }

    #[test]
    fn an_imu_without_an_axis_zeroes_it_in_the_frame_and_counts_faults_per_axis() {
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(10.0),
            temp_read_every: 1,
        };
        let mut imu = CompensationLoop::new(
            None::<&AxisModels<MAX_CENTERS>>,
            config,
            [Warming(20.0), Warming(21.0), Warming(22.0)],
            [Steady(15.0), Steady(16.0), Steady(17.0)],
            Vec::new(),
        );
        imu.set_axis_mask(0b101);
        let [x, y, z] = imu.step(0.0);
        assert_eq!(
            (x.rate_comp_dph, z.rate_comp_dph),
            (15.0, 17.0),
            "no model: rates pass through"
        );
        assert_eq!(
            (y.bias_dph, y.rate_comp_dph, y.flags),
            (0.0, 0.0, Flags::NO_VALID_MODEL)
        );
        assert!(y.temp_c.is_nan());
        assert_eq!(imu.temp_read_faults_per_axis(), [0; 3]);
        let (_, _, mut bytes) = imu.destroy();
        let f = frame::decode_axes(frames(&mut bytes).next().unwrap()).unwrap();
        assert_eq!((f.axis_mask, f.axes[1]), (0b101, AxisOutput::default()));
    }
}
