//! The per-sample compensation loop: read the front end, read the
//! thermometers the model needs (every `temp_read_every` samples), compensate
//! with rbf-core, emit one output frame. Whatever the sensors do, every call emits exactly
//! one frame and returns; nothing in here can panic on sensor data, and
//! nothing waits on the output: a frame the output cannot take whole is
//! dropped, counted, and flagged on the next frame that goes out
//! ([`Flags::OUTPUT_DROPPED`]).

use embedded_io::Write;
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::frame::{self, MAX_FRAME_LEN, OutputFrame};
use rbf_core::{CompensatedSample, Compensator, CompensatorConfig, Flags, GyroSample, Model};

use crate::sensors::{RateFrontEnd, RateSample, Readings, SensorFault, Thermometers};

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

/// Where the loop's model lives: owned (`Option<Model>`, host tools and
/// tests) or decoded in place into storage the board owns ([`InPlaceModel`]).
pub trait ModelHolder {
    /// The model to run, if there is a usable one.
    fn model(&self) -> Option<&Model>;
}

impl ModelHolder for Option<Model> {
    fn model(&self) -> Option<&Model> {
        self.as_ref()
    }
}

/// A model decoded in place into storage that outlives the loop (the
/// board's `static`): no model is ever moved by value. `M` is a
/// single-axis [`Model`] or an IMU's [`rbf_core::blob::axes::AxisModels`].
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

impl ModelHolder for InPlaceModel<'_, Model> {
    fn model(&self) -> Option<&Model> {
        self.get()
    }
}

/// The loop: owns the model (or holds it in place), the sensors and the output.
pub struct CompensationLoop<T, R, W, M = Option<Model>> {
    model: M,
    config: LoopConfig,
    thermometer: T,
    front_end: R,
    output: W,
    compensator: Compensator,
    latest_temps_c: Readings,
    temp_read_due: bool,
    stats: LoopStats,
    /// The sequence number the next sample should have.
    next_seq: u32,
    /// Flags for the next frame that goes out (a dropped frame, a fault reset).
    pending_flags: Flags,
}

impl<T: Thermometers, R: RateFrontEnd, W: Write, M: ModelHolder> CompensationLoop<T, R, W, M> {
    /// A loop over `model` (none: absent or invalid blob, output flagged 4).
    pub fn new(model: M, config: LoopConfig, thermometer: T, front_end: R, output: W) -> Self {
        CompensationLoop {
            model,
            config,
            thermometer,
            front_end,
            output,
            compensator: Compensator::new(),
            latest_temps_c: [None; THERMOMETERS],
            temp_read_due: true,
            stats: LoopStats::default(),
            next_seq: 0,
            pending_flags: Flags::NONE,
        }
    }

    /// Marks the next frame with `flags` (the board: [`Flags::FAULT_RESET`]
    /// after a reset by the fault handler or the watchdog).
    pub fn flag_next_frame(&mut self, flags: Flags) {
        self.pending_flags |= flags;
    }

    /// Processes the sample data-ready announced; `dt_s` is the time since the
    /// previous one, s. Emits one frame and returns what it holds.
    ///
    /// Budget: one front-end read, one read per thermometer the model uses
    /// (every `temp_read_every` samples), one [`Compensator::process`] and a
    /// ≤ 32-byte write.
    pub fn step(&mut self, dt_s: f32) -> CompensatedSample {
        self.step_at(self.next_seq, dt_s)
    }

    /// [`Self::step`] for the sample whose data-ready edge is number `seq`
    /// (counted by the board from timer timestamps, so edges that passed
    /// while the CPU was stalled count too). Edges between the previous
    /// sample and this one are counted in [`LoopStats::samples_missed`] and
    /// flagged ([`Flags::SAMPLES_MISSED`]); the frame carries `seq`.
    pub fn step_at(&mut self, seq: u32, dt_s: f32) -> CompensatedSample {
        if self.stats.count_sample(&mut self.next_seq, seq) {
            self.pending_flags |= Flags::SAMPLES_MISSED;
        }
        if self.temp_read_due || seq.is_multiple_of(self.config.temp_read_every.max(1)) {
            self.temp_read_due = false;
            let wanted = self
                .model
                .model()
                .map_or(1 << LOOP_THERMOMETER, |m| m.features().set.thermometer_mask());
            let failed = self.thermometer.read_wanted(wanted, &mut self.latest_temps_c);
            self.stats.temp_read_faults = self.stats.temp_read_faults.wrapping_add(failed);
        }
        let (rate_dph, rate_ok) = self.stats.rate_or_fault(self.front_end.read_rate());
        let sample = GyroSample {
            dt_s,
            rate_dph,
            temps_c: self.latest_temps_c,
        };
        let mut out = self
            .compensator
            .process(self.model.model(), &self.config.compensator, &sample);
        if !rate_ok {
            out.flags |= Flags::RATE_INVALID;
        }
        out.flags |= self.pending_flags;
        if self.emit(seq, rate_dph, &out) {
            self.pending_flags = Flags::NONE;
        } else {
            self.stats.output_errors = self.stats.output_errors.wrapping_add(1);
            self.pending_flags = Flags::OUTPUT_DROPPED;
        }
        out
    }

    /// Frames and writes one output frame; false when the output did not take it whole.
    fn emit(&mut self, seq: u32, rate_dph: f32, out: &CompensatedSample) -> bool {
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

    /// Switches to `model` (after a model update) between two samples; the
    /// feature filters start afresh, as the new model may compute others
    /// (and read other thermometers: they are read on the next sample).
    pub fn replace_model(&mut self, model: M) {
        self.update_model(|m| *m = model);
    }

    /// Changes the model in place between two samples (the board rebuilds
    /// its `static` model through [`InPlaceModel::rebuild`]); the feature
    /// filters start afresh as after [`Self::replace_model`].
    pub fn update_model(&mut self, change: impl FnOnce(&mut M)) {
        self.update_model_if(|m| {
            change(m);
            true
        });
    }

    /// Lets `command` act on the model between two samples; the feature
    /// filters start afresh only when it says a model was installed (an
    /// unknown command, a refused blob or line noise changes nothing).
    pub fn update_model_if(&mut self, command: impl FnOnce(&mut M) -> bool) {
        if command(&mut self.model) {
            self.compensator = Compensator::new();
            self.temp_read_due = true;
            self.stats.filter_restarts = self.stats.filter_restarts.wrapping_add(1);
        }
    }

    /// The output (to interleave command replies between frames).
    pub fn output_mut(&mut self) -> &mut W {
        &mut self.output
    }

    /// The model in use.
    pub fn model(&self) -> Option<&Model> {
        self.model.model()
    }

    /// Health counters.
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// The thermometers and the front end (their drivers' counters).
    pub fn sensors(&self) -> (&T, &R) {
        (&self.thermometer, &self.front_end)
    }

    /// Gives the sensors and output back.
    pub fn destroy(self) -> (T, R, W) {
        (self.thermometer, self.front_end, self.output)
    }
}
