//! The per-sample loop of a multi-axis IMU: one data-ready edge, every
//! axis's rate and thermometers read over embedded-hal, one [`AxesFrame`]
//! out carrying all axes.
//!
//! With a model per axis ([`AxisModels`], blob format 3) each axis goes
//! through exactly the single-axis step ([`Compensator::process_with`]),
//! so an axis's output is what the single-axis loop would give it; flags
//! are per axis (one axis's failed thermometer flags that axis alone, the
//! others keep compensating). With a shared-basis model
//! ([`SharedAxisModels`], format 3 with the shared-basis flag) one
//! thermometer set serves every axis and one
//! [`Compensator::process_shared`] steps them all, the step `trainer
//! compensate` runs for such a blob; a failure of that thermometer is
//! every axis's (flag 2 on each, flag 4 once the hold runs out), while a
//! failed rate read still flags its axis alone. What concerns the frame
//! (a dropped frame, missed samples, a fault reset) flags every axis. As
//! in [`crate::compensation`], nothing here can panic on sensor data and
//! nothing waits on the output.

use embedded_io::Write;
use rbf_core::axis::{Axis, MAX_AXES};
use rbf_core::blob::axes::AxisModels;
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::frame::{self, AXES_FRAME_TAG, AxesFrame, AxisOutput, MAX_AXES_FRAME_LEN};
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::{CompensatedSample, Compensator, Flags, GyroSample};

use crate::compensation::{InPlaceModel, LoopConfig, LoopStats, write_frame};
use crate::sensors::{RateFrontEnd, RateSample, Readings, SensorFault, Thermometers};

/// The thermometers of every axis: each axis's loop thermometer (its coil
/// sensor) as `temp_c`, plus whatever shared thermometers its model reads.
pub trait AxisThermometers {
    /// Reads the thermometers of `wanted` (bit i = thermometer i) for
    /// `axis` into `readings` (`None` where a read failed and for those not
    /// wanted); returns how many wanted thermometers gave no reading.
    fn read_axis(&mut self, axis: Axis, wanted: u8, readings: &mut Readings) -> u32;
}

/// One thermometer set per axis, x first.
impl<T: Thermometers> AxisThermometers for [T; MAX_AXES] {
    fn read_axis(&mut self, axis: Axis, wanted: u8, readings: &mut Readings) -> u32 {
        match self.get_mut(axis.index()) {
            Some(t) => t.read_wanted(wanted, readings),
            None => {
                *readings = [None; THERMOMETERS];
                wanted.count_ones()
            }
        }
    }
}

/// The rate front ends of every axis.
pub trait AxisFrontEnds {
    /// Reads `axis`'s sample that data-ready announced.
    fn read_axis_rate(&mut self, axis: Axis) -> Result<RateSample, SensorFault>;
}

/// One front end per axis, x first.
impl<R: RateFrontEnd> AxisFrontEnds for [R; MAX_AXES] {
    fn read_axis_rate(&mut self, axis: Axis) -> Result<RateSample, SensorFault> {
        self.get_mut(axis.index())
            .map_or(Err(SensorFault::Bus), RateFrontEnd::read_rate)
    }
}

/// Where the axes loop's models live: owned (host tools and tests) or
/// decoded in place into the board's `static` ([`InPlaceModel`]); a model
/// per axis ([`AxisModels`]) or one shared basis for every axis
/// ([`SharedAxisModels`]). An image holds the step of the kinds its
/// holder can carry, no other.
pub trait AxesHolder<const K: usize> {
    /// True when the holder carries a shared-basis model: the loop then
    /// reads one thermometer set and steps every axis at once
    /// ([`Compensator::process_shared`]).
    const SHARED: bool = false;

    /// The per-axis models to run, if a blob gave usable ones.
    fn models(&self) -> Option<&AxisModels<K>> {
        None
    }

    /// The shared-basis model to run, if a blob gave a usable one.
    fn shared(&self) -> Option<&SharedAxisModels<K>> {
        None
    }
}

impl<const K: usize> AxesHolder<K> for Option<AxisModels<K>> {
    fn models(&self) -> Option<&AxisModels<K>> {
        self.as_ref()
    }
}

impl<const K: usize> AxesHolder<K> for InPlaceModel<'_, AxisModels<K>> {
    fn models(&self) -> Option<&AxisModels<K>> {
        self.get()
    }
}

impl<const K: usize> AxesHolder<K> for Option<&AxisModels<K>> {
    fn models(&self) -> Option<&AxisModels<K>> {
        *self
    }
}

impl<const K: usize> AxesHolder<K> for Option<SharedAxisModels<K>> {
    const SHARED: bool = true;

    fn shared(&self) -> Option<&SharedAxisModels<K>> {
        self.as_ref()
    }
}

impl<const K: usize> AxesHolder<K> for InPlaceModel<'_, SharedAxisModels<K>> {
    const SHARED: bool = true;

    fn shared(&self) -> Option<&SharedAxisModels<K>> {
        self.get()
    }
}

impl<const K: usize> AxesHolder<K> for Option<&SharedAxisModels<K>> {
    const SHARED: bool = true;

    fn shared(&self) -> Option<&SharedAxisModels<K>> {
        *self
    }
}

/// What one step of the axes loop produced, per axis (x first; an axis the
/// IMU does not have: 0 bias, 0 rate, NaN temperature, flag 4).
pub type AxesOutput = [CompensatedSample; MAX_AXES];

const NO_AXIS: CompensatedSample = CompensatedSample {
    bias_dph: 0.0,
    rate_comp_dph: 0.0,
    temp_c: f32::NAN,
    flags: Flags::NO_VALID_MODEL,
};

/// The multi-axis loop over models of centre capacity `K`.
pub struct AxesLoop<T, R, W, M, const K: usize> {
    models: M,
    config: LoopConfig,
    /// The axes the IMU has (bit 0 = x).
    axis_mask: u8,
    thermometers: T,
    front_ends: R,
    output: W,
    compensators: [Compensator; MAX_AXES],
    latest_temps_c: [Readings; MAX_AXES],
    temp_read_due: bool,
    stats: LoopStats,
    temp_read_faults_per_axis: [u32; MAX_AXES],
    next_seq: u32,
    pending_flags: Flags,
}

impl<T: AxisThermometers, R: AxisFrontEnds, W: Write, M: AxesHolder<K>, const K: usize> AxesLoop<T, R, W, M, K> {
    /// A loop over the axes of `axis_mask` (bit 0 = x; the IMU's wiring)
    /// running `models` (none, or an axis without a model: that axis's
    /// output is uncompensated, flag 4).
    pub fn new(models: M, axis_mask: u8, config: LoopConfig, thermometers: T, front_ends: R, output: W) -> Self {
        AxesLoop {
            models,
            config,
            axis_mask: axis_mask & ((1 << MAX_AXES) - 1),
            thermometers,
            front_ends,
            output,
            compensators: [Compensator::new(); MAX_AXES],
            latest_temps_c: [[None; THERMOMETERS]; MAX_AXES],
            temp_read_due: true,
            stats: LoopStats::default(),
            temp_read_faults_per_axis: [0; MAX_AXES],
            next_seq: 0,
            pending_flags: Flags::NONE,
        }
    }

    /// Marks the next frame (every axis) with `flags`.
    pub fn flag_next_frame(&mut self, flags: Flags) {
        self.pending_flags |= flags;
    }

    /// Sets the axes the IMU has (bit 0 = x) between two samples; the
    /// compensators start afresh.
    pub fn set_axis_mask(&mut self, axis_mask: u8) {
        self.axis_mask = axis_mask & ((1 << MAX_AXES) - 1);
        self.compensators = [Compensator::new(); MAX_AXES];
        self.temp_read_due = true;
    }

    /// True when the IMU has `axis`.
    pub fn has_axis(&self, axis: Axis) -> bool {
        self.axis_mask & (1 << axis.index()) != 0
    }

    /// Processes the sample data-ready announced on every axis; `dt_s` is the
    /// time since the previous one, s. Emits one frame and returns what it holds.
    pub fn step(&mut self, dt_s: f32) -> AxesOutput {
        self.step_at(self.next_seq, dt_s)
    }

    /// [`Self::step`] for data-ready edge number `seq`, as
    /// [`crate::compensation::CompensationLoop::step_at`].
    ///
    /// Budget per axis: one front-end read, one read per thermometer its
    /// model uses (every `temp_read_every` samples), one
    /// [`Compensator::process_with`]; then one ≤ 59-byte write.
    pub fn step_at(&mut self, seq: u32, dt_s: f32) -> AxesOutput {
        if self.stats.count_sample(&mut self.next_seq, seq) {
            self.pending_flags |= Flags::SAMPLES_MISSED;
        }
        let read_temps = self.temp_read_due || seq.is_multiple_of(self.config.temp_read_every.max(1));
        self.temp_read_due = false;
        let mut out = [NO_AXIS; MAX_AXES];
        let mut rates_dph = [0.0f32; MAX_AXES];
        if M::SHARED {
            self.step_shared(read_temps, dt_s, &mut out, &mut rates_dph);
        } else {
            for axis in Axis::ALL {
                if self.has_axis(axis) {
                    let i = axis.index();
                    (out[i], rates_dph[i]) = self.step_axis(axis, read_temps, dt_s);
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
    /// compensator. Not inlined: the board image holds one copy, not one per axis.
    #[inline(never)]
    fn step_axis(&mut self, axis: Axis, read_temps: bool, dt_s: f32) -> (CompensatedSample, f32) {
        let i = axis.index() % MAX_AXES;
        let model = self.models.models().and_then(|m| m.get(axis));
        if read_temps {
            let wanted = model.map_or(1 << LOOP_THERMOMETER, |m| m.features().set.thermometer_mask());
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
        let mut o = self.compensators[i].process_with(model, &self.config.compensator, &sample);
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
    fn step_shared(&mut self, read_temps: bool, dt_s: f32, out: &mut AxesOutput, rates_dph: &mut [f32; MAX_AXES]) {
        let Some(first) = Axis::ALL.into_iter().find(|&a| self.has_axis(a)) else {
            return;
        };
        let t = first.index() % MAX_AXES;
        if read_temps {
            let wanted = (self.models.shared()).map_or(1 << LOOP_THERMOMETER, |m| m.features().set.thermometer_mask());
            let failed = self.thermometers.read_axis(first, wanted, &mut self.latest_temps_c[t]);
            self.stats.temp_read_faults = self.stats.temp_read_faults.wrapping_add(failed);
            for axis in Axis::ALL {
                if self.has_axis(axis) {
                    let i = axis.index() % MAX_AXES;
                    self.temp_read_faults_per_axis[i] = self.temp_read_faults_per_axis[i].wrapping_add(failed);
                }
            }
        }
        let mut rate_ok = [true; MAX_AXES];
        for axis in Axis::ALL {
            if self.has_axis(axis) {
                let i = axis.index() % MAX_AXES;
                (rates_dph[i], rate_ok[i]) = self.read_rate(axis);
            }
        }
        let all = self.compensators[0].process_shared(
            self.models.shared(),
            &self.config.compensator,
            dt_s,
            &self.latest_temps_c[t],
            rates_dph,
        );
        for (i, (mut o, ok)) in all.into_iter().zip(rate_ok).enumerate() {
            if self.axis_mask & (1 << i) == 0 {
                continue;
            }
            if !ok {
                o.flags |= Flags::RATE_INVALID;
            }
            o.flags |= self.pending_flags;
            if let Some(slot) = out.get_mut(i) {
                *slot = o;
            }
        }
    }

    /// `axis`'s rate and whether it is valid (a failed read counted). Not
    /// inlined: the shared-basis image holds one copy, not one per axis.
    #[inline(never)]
    fn read_rate(&mut self, axis: Axis) -> (f32, bool) {
        self.stats.rate_or_fault(self.front_ends.read_axis_rate(axis))
    }

    /// Frames and writes one [`AxesFrame`]; false when the output did not take it whole.
    fn emit(&mut self, seq: u32, rates_dph: &[f32; MAX_AXES], out: &AxesOutput) -> bool {
        let mut axes = [AxisOutput::default(); MAX_AXES];
        for ((a, o), &rate_dph) in axes.iter_mut().zip(out).zip(rates_dph) {
            *a = AxisOutput {
                rate_dph,
                bias_dph: o.bias_dph,
                rate_comp_dph: o.rate_comp_dph,
                temp_c: o.temp_c,
                flags: o.flags.bits(),
            };
        }
        for axis in Axis::ALL {
            if !self.has_axis(axis) {
                axes[axis.index()] = AxisOutput::default();
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

    /// Changes the models in place between two samples (after a model
    /// update); every axis's feature filters start afresh and its
    /// thermometers are read on the next sample.
    pub fn update_model(&mut self, change: impl FnOnce(&mut M)) {
        self.update_model_if(|m| {
            change(m);
            true
        });
    }

    /// Lets `command` act on the models between two samples; the filters
    /// start afresh only when it says a model was installed.
    pub fn update_model_if(&mut self, command: impl FnOnce(&mut M) -> bool) {
        if command(&mut self.models) {
            self.compensators = [Compensator::new(); MAX_AXES];
            self.temp_read_due = true;
            self.stats.filter_restarts = self.stats.filter_restarts.wrapping_add(1);
        }
    }

    /// The output (to interleave command replies between frames).
    pub fn output_mut(&mut self) -> &mut W {
        &mut self.output
    }

    /// The per-axis models in use.
    pub fn models(&self) -> Option<&AxisModels<K>> {
        self.models.models()
    }

    /// The shared-basis model in use.
    pub fn shared_models(&self) -> Option<&SharedAxisModels<K>> {
        self.models.shared()
    }

    /// Health counters (thermometer faults summed over the axes).
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// Thermometer reads that failed, per axis (x first).
    pub fn temp_read_faults_per_axis(&self) -> [u32; MAX_AXES] {
        self.temp_read_faults_per_axis
    }

    /// Gives the sensors and output back.
    pub fn destroy(self) -> (T, R, W) {
        (self.thermometers, self.front_ends, self.output)
    }

    /// The thermometers and the front ends (their drivers' counters).
    pub fn sensors(&self) -> (&T, &R) {
        (&self.thermometers, &self.front_ends)
    }
}
