//! Fault injection: the real drivers and loop on emulated buses that fail on a
//! seeded schedule, a checker that decodes every output frame, and the
//! model-store campaigns (bit flips, power cuts, UART commands); for a
//! multi-axis IMU, one axis's thermometer failing while the others run on
//! ([`axis_thermometer_campaign`]).
//!
//! The QEMU fault board (`src/bin/qemu_faults.rs`) runs these on the target
//! and prints `faults injected N, samples lost 0, panics 0`; host tests run
//! the same code.

use core::cell::Cell;

use embedded_hal::spi::{self, SpiDevice};
use gyro_wire::frame::{self, AXES_FRAME_TAG, AxesFrame, AxisOutput, MAX_AXES_FRAME_LEN};
use rbf_core::axis::{Axis, MAX_AXES};
use rbf_core::blob;
use rbf_core::{CompensatorConfig, Flags, Model};

use crate::emulated_flash::{EmulatedFlash, PAGE};
use crate::replay::{EmulatedFrontEnd, EmulatedTmp117, ReplaySample};
use firmware::compensation::{CompensationLoop, LoopConfig, ModelHolder};
use firmware::frontend::FrontEnd;
use firmware::model_store::{COMMIT_LEN, ModelStore, SlotLayout};
use firmware::tmp117::{self, Tmp117};
use firmware::update::{self, CommandReceiver, Received, UpdateStatus};
use gyro_wire::command;

/// A model any board test can install: a static cubic in the loop
/// temperature about 25 °C, trained range 10 … 40 °C, no filters (so no
/// warm-up). `None` only if rbf-core refused it.
pub fn cubic_model() -> Option<Model> {
    use rbf_core::model::{ModelBody, ModelInfo};
    use rbf_core::poly::Poly3;
    use rbf_core::{FeatureConfig, FeatureSet};
    Model::new(
        FeatureConfig::single(FeatureSet::Temp, 0.0),
        &[(10.0, 40.0)],
        ModelBody::Poly3(Poly3::new(25.0, [0.3, 0.01, 0.0, 0.0]).ok()?),
        ModelInfo::default(),
    )
    .ok()
}

/// The loop sensor (`temp_c`) sits at its multi-point-board address: bus 1, third address.
const LOOP_SENSOR_ADDRESS: u8 = tmp117::ADDRESSES[rbf_core::features::LOOP_THERMOMETER];

/// The sample period of the sensor campaigns' loops, s.
const CAMPAIGN_PERIOD_S: f32 = 0.1;

/// The sensor campaigns' loop: filters for [`CAMPAIGN_PERIOD_S`], every
/// sample's thermometers read.
fn campaign_loop_config() -> LoopConfig {
    LoopConfig {
        compensator: CompensatorConfig::for_sample_rate(1.0 / CAMPAIGN_PERIOD_S),
        temp_read_every: 1,
    }
}

/// The kinds of sensor and bus fault the campaign injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKind {
    /// The TMP117 does not acknowledge (1–40 samples).
    I2cNackBurst,
    /// The TMP117 keeps returning one reading (50–200 samples): undetectable
    /// from the value alone, so no flag is expected; the loop must carry on.
    StuckReading,
    /// The TMP117 reads its reset value −256 °C (a bus stuck at 0x8000).
    StuckAtRail,
    /// One reading 30 °C off.
    TempSpike,
    /// Readings of 180 °C (beyond the TMP117's range, 1–20 samples).
    OutOfRangeTemp,
    /// The front-end SPI transaction fails (1–10 samples).
    SpiError,
    /// The front end sends NaN as a valid rate (1–5 samples).
    NanRate,
    /// A bit of the front-end sample flips on the wire (CRC-8 fails).
    CorruptSample,
}

impl FaultKind {
    /// Every kind, in schedule order.
    pub const ALL: [FaultKind; 8] = [
        FaultKind::I2cNackBurst,
        FaultKind::StuckReading,
        FaultKind::StuckAtRail,
        FaultKind::TempSpike,
        FaultKind::OutOfRangeTemp,
        FaultKind::SpiError,
        FaultKind::NanRate,
        FaultKind::CorruptSample,
    ];

    fn duration_range(self) -> (u32, u32) {
        match self {
            FaultKind::I2cNackBurst => (1, 40),
            FaultKind::StuckReading => (50, 200),
            FaultKind::StuckAtRail => (5, 30),
            FaultKind::TempSpike | FaultKind::CorruptSample => (1, 1),
            FaultKind::OutOfRangeTemp => (1, 20),
            FaultKind::SpiError => (1, 10),
            FaultKind::NanRate => (1, 5),
        }
    }

    /// The flag the output must carry while this fault is active, if any.
    pub fn expected_flag(self) -> Option<Flags> {
        match self {
            FaultKind::StuckReading => None,
            FaultKind::I2cNackBurst | FaultKind::StuckAtRail | FaultKind::TempSpike | FaultKind::OutOfRangeTemp => {
                Some(Flags::TEMP_SENSOR_FAULT)
            }
            FaultKind::SpiError | FaultKind::NanRate | FaultKind::CorruptSample => Some(Flags::RATE_INVALID),
        }
    }
}

/// Deterministic xorshift32.
#[derive(Clone, Copy, Debug)]
struct Rng(u32);

impl Rng {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0
    }

    fn between(&mut self, lo: u32, hi: u32) -> u32 {
        lo + self.next() % (hi - lo + 1)
    }
}

/// What the front end does for the current sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpiFault {
    /// Answers normally.
    #[default]
    None,
    /// The transaction fails.
    Error,
    /// One bit of the reply flips.
    FlipBit,
}

/// The emulated front end with an SPI fault switch.
#[derive(Debug)]
pub struct FaultySpi<'c> {
    inner: EmulatedFrontEnd<'c>,
    fault: &'c Cell<SpiFault>,
}

impl spi::ErrorType for FaultySpi<'_> {
    type Error = spi::ErrorKind;
}

impl SpiDevice for FaultySpi<'_> {
    fn transaction(&mut self, operations: &mut [spi::Operation<'_, u8>]) -> Result<(), Self::Error> {
        match self.fault.get() {
            SpiFault::None => self.inner.transaction(operations),
            SpiFault::Error => Err(spi::ErrorKind::Other),
            SpiFault::FlipBit => {
                self.inner.transaction(operations)?;
                if let Some(spi::Operation::Read(buf)) = operations.last_mut()
                    && let Some(b) = buf.get_mut(3)
                {
                    *b ^= 0x10;
                }
                Ok(())
            }
        }
    }
}

/// Decodes every output frame of a loop of `N` axes as it is written and
/// checks it: a single gyro's frames (`N = 1`) or an IMU's
/// [`AxesFrame`]s, each axis the frame carries checked alike.
#[derive(Debug)]
pub struct FrameChecker<'c, const N: usize = 1> {
    buf: [u8; MAX_AXES_FRAME_LEN],
    len: usize,
    expected_flag: &'c Cell<Option<Flags>>,
    next_seq: u32,
    /// Frames decoded (those out of sequence included, and counted bad).
    pub frames: u32,
    /// Frames that did not decode or broke the sequence.
    pub bad_frames: u32,
    /// Frames in which an axis lacks the flag its sample's fault calls for.
    pub missing_flags: u32,
    /// Frames in which an axis has a non-finite bias or an unflagged non-finite output.
    pub non_finite: u32,
    /// The last frame decoded in sequence (a single gyro's as axis x of an
    /// [`AxesFrame`]); none after a frame that did not decode or broke the sequence.
    pub last: Option<AxesFrame>,
}

impl<'c, const N: usize> FrameChecker<'c, N> {
    /// A checker expecting sequence 0 first; while `expected_flag` holds a
    /// flag, every axis of every frame must carry it.
    pub fn new(expected_flag: &'c Cell<Option<Flags>>) -> Self {
        FrameChecker {
            buf: [0; MAX_AXES_FRAME_LEN],
            len: 0,
            expected_flag,
            next_seq: 0,
            frames: 0,
            bad_frames: 0,
            missing_flags: 0,
            non_finite: 0,
            last: None,
        }
    }

    /// The frame in the buffer, decoded as the loop of `N` axes writes it.
    fn decode(bytes: &mut [u8]) -> Option<AxesFrame> {
        if N == 1 {
            let f = frame::decode(bytes).ok()?;
            let mut axes = [AxisOutput::default(); MAX_AXES];
            axes[0] = AxisOutput {
                rate_dph: f.rate_dph,
                bias_dph: f.bias_dph,
                rate_comp_dph: f.rate_comp_dph,
                temp_c: f.temp_c,
                flags: f.flags,
            };
            Some(AxesFrame {
                tag: AXES_FRAME_TAG,
                seq: f.seq,
                axis_mask: 1,
                axes,
            })
        } else {
            frame::decode_axes(bytes).ok()
        }
    }

    fn frame_done(&mut self) {
        let bytes = self.buf.get_mut(..self.len).unwrap_or(&mut []);
        self.len = 0;
        let Some(f) = Self::decode(bytes) else {
            self.bad_frames += 1;
            self.last = None;
            return;
        };
        let in_sequence = f.seq == self.next_seq;
        if !in_sequence {
            self.bad_frames += 1;
        }
        self.next_seq = f.seq.wrapping_add(1);
        self.frames += 1;
        let carried = f
            .axes
            .iter()
            .enumerate()
            .filter(|&(i, _)| f.axis_mask & (1 << i) != 0)
            .map(|(_, a)| a);
        let (mut missing, mut non_finite) = (false, false);
        for a in carried {
            if let Some(flag) = self.expected_flag.get()
                && !a.flags().contains(flag)
            {
                missing = true;
            }
            let rate_ok = a.rate_comp_dph.is_finite() || a.flags().contains(Flags::RATE_INVALID);
            non_finite |= !a.bias_dph.is_finite() || !rate_ok;
        }
        self.missing_flags += u32::from(missing);
        self.non_finite += u32::from(non_finite);
        self.last = in_sequence.then_some(f);
    }
}

impl<const N: usize> embedded_io::ErrorType for FrameChecker<'_, N> {
    type Error = embedded_io::ErrorKind;
}

impl<const N: usize> embedded_io::Write for FrameChecker<'_, N> {
    fn write(&mut self, data: &[u8]) -> Result<usize, Self::Error> {
        for &b in data {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = b;
                self.len += 1;
            } else {
                self.bad_frames += 1;
                self.len = 0;
            }
            if b == 0 {
                self.frame_done();
            }
        }
        Ok(data.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// What the sensor-fault campaign found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensorCampaign {
    /// Gyro samples stepped.
    pub samples: u32,
    /// Fault episodes injected, per [`FaultKind::ALL`] entry.
    pub episodes: [u32; 8],
    /// Samples during which a fault was active.
    pub faulty_samples: u32,
    /// Frames decoded in sequence.
    pub frames: u32,
    /// Samples without a good frame (undecodable, out of sequence or missing).
    pub samples_lost: u32,
    /// Frames without the flag their fault calls for.
    pub missing_flags: u32,
    /// Frames with an unflagged non-finite value.
    pub non_finite: u32,
}

impl SensorCampaign {
    /// Fault episodes of all kinds.
    pub fn faults(&self) -> u32 {
        self.episodes.iter().sum()
    }
}

/// Runs `samples` gyro samples of a 20 → 45 → 20 °C chamber cycle at 10 Hz
/// through the real TMP117 and front-end drivers and the compensation loop,
/// with faults from a schedule seeded by `seed`; checks every frame.
pub fn sensor_campaign(model: Option<Model>, samples: u32, seed: u32) -> SensorCampaign {
    let current = Cell::new(ReplaySample::default());
    let spi_fault = Cell::new(SpiFault::None);
    let expected = Cell::new(None);
    let mut report = SensorCampaign {
        samples,
        ..SensorCampaign::default()
    };
    let mut thermometer = Tmp117::new(EmulatedTmp117::new(&current, 0), LOOP_SENSOR_ADDRESS);
    let mut front_end = FrontEnd::new(FaultySpi {
        inner: EmulatedFrontEnd::new(&current),
        fault: &spi_fault,
    });
    if thermometer.init().is_err() || front_end.init().is_err() {
        report.samples_lost = samples;
        return report;
    }
    let (period_s, config) = (CAMPAIGN_PERIOD_S, campaign_loop_config());
    let checker = FrameChecker::<1>::new(&expected);
    let mut compensation = CompensationLoop::new(model, config, thermometer, front_end, checker);
    let mut rng = Rng(seed | 1);
    let (mut kind, mut left, mut stuck_c) = (None::<FaultKind>, 0u32, 0.0f64);
    for i in 0..samples {
        // The truth: a 25 °C triangle over the run, a bias following it, noise.
        let phase = f64::from(i) / f64::from(samples.max(1));
        let temp_c = 20.0 + 25.0 * (1.0 - (2.0 * phase - 1.0).abs());
        let noise = (f64::from(rng.next() % 1000) - 500.0) * 1e-5;
        let rate_dph = 15.04 + 0.02 * (temp_c - 20.0) + noise;
        if left == 0 {
            kind = None;
            // About one fault episode every 40 samples, kinds in turn at random.
            if rng.next().is_multiple_of(40) {
                let k = FaultKind::ALL[(rng.next() % 8) as usize];
                let (lo, hi) = k.duration_range();
                left = rng.between(lo, hi);
                stuck_c = temp_c;
                if let Some(n) = FaultKind::ALL
                    .iter()
                    .position(|&x| x == k)
                    .and_then(|n| report.episodes.get_mut(n))
                {
                    *n += 1;
                }
                kind = Some(k);
            }
        }
        if left > 0 {
            left -= 1;
            report.faulty_samples += 1;
        }
        let mut sample = ReplaySample::with_loop(Some(temp_c), rate_dph as f32);
        let mut spi = SpiFault::None;
        match kind {
            Some(FaultKind::I2cNackBurst) => *sample.loop_temp_c_mut() = None,
            Some(FaultKind::StuckReading) => *sample.loop_temp_c_mut() = Some(stuck_c),
            Some(FaultKind::StuckAtRail) => *sample.loop_temp_c_mut() = Some(-256.0),
            Some(FaultKind::TempSpike) => *sample.loop_temp_c_mut() = Some(temp_c + 30.0),
            Some(FaultKind::OutOfRangeTemp) => *sample.loop_temp_c_mut() = Some(180.0),
            Some(FaultKind::SpiError) => spi = SpiFault::Error,
            Some(FaultKind::NanRate) => sample.rate_dph = f32::NAN,
            Some(FaultKind::CorruptSample) => spi = SpiFault::FlipBit,
            None => {}
        }
        current.set(sample);
        spi_fault.set(spi);
        expected.set(kind.and_then(FaultKind::expected_flag));
        compensation.step(if i == 0 { 0.0 } else { period_s });
    }
    let (_, _, checker) = compensation.destroy();
    report.frames = checker.frames;
    report.samples_lost = samples.saturating_sub(checker.frames) + checker.bad_frames;
    report.missing_flags = checker.missing_flags;
    report.non_finite = checker.non_finite;
    report
}

/// What the one-axis thermometer campaign found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AxisThermometerCampaign {
    /// Samples stepped (each one frame with every axis).
    pub samples: u32,
    /// Frames decoded in sequence.
    pub frames: u32,
    /// Samples without a good frame.
    pub samples_lost: u32,
    /// Samples on which the failing axis's thermometer did not answer.
    pub faulty_samples: u32,
    /// Faulty samples whose frame lacks flag 2 on a failing axis (must be 0;
    /// under a shared-basis model every axis fails with x's thermometer).
    pub missing_flags: u32,
    /// Samples on which the failing axis ran uncompensated (flag 4: an
    /// outage past the hold).
    pub failing_uncompensated: u32,
    /// Frames in which a healthy axis carried flag 2 or flag 4, or any
    /// axis a non-finite bias or compensated rate (must be 0).
    pub healthy_disturbed: u32,
    /// Thermometer read failures the loop counted, per axis (x first).
    pub temp_read_faults_per_axis: [u32; MAX_AXES],
}

/// Runs `samples` samples of a three-axis IMU at 10 Hz through a TMP117
/// and a front end per axis and the multi-axis loop with `models`; the
/// thermometer of `failing` stops answering (I2C NACK) in bursts of 1–40
/// samples and outages of 150 (past the 10-s hold), on a schedule seeded
/// by `seed`. Checks every frame: flag 2 on the failing axis whenever its
/// thermometer failed, the other axes compensating undisturbed. Under a
/// shared-basis model ([`ModelHolder::SHARED`]) the loop reads axis x's thermometer
/// for every axis: when that one fails, every axis counts as failing (flag
/// 2 on each, flag 4 past the hold); when y's or z's fails, which that
/// model does not read, no axis may be disturbed.
pub fn axis_thermometer_campaign<M: ModelHolder<K, MAX_AXES>, const K: usize>(
    models: M,
    failing: Axis,
    samples: u32,
    seed: u32,
) -> AxisThermometerCampaign {
    let current: [Cell<ReplaySample>; MAX_AXES] = Default::default();
    let mut report = AxisThermometerCampaign {
        samples,
        ..AxisThermometerCampaign::default()
    };
    let [cx, cy, cz] = &current;
    let mut thermometers = [cx, cy, cz].map(|c| Tmp117::new(EmulatedTmp117::new(c, 0), LOOP_SENSOR_ADDRESS));
    let mut front_ends = [cx, cy, cz].map(|c| FrontEnd::new(EmulatedFrontEnd::new(c)));
    for t in &mut thermometers {
        if t.init().is_err() {
            report.samples_lost = samples;
            return report;
        }
    }
    for f in &mut front_ends {
        if f.init().is_err() {
            report.samples_lost = samples;
            return report;
        }
    }
    let (period_s, config) = (CAMPAIGN_PERIOD_S, campaign_loop_config());
    let no_expected_flag = Cell::new(None);
    let checker = FrameChecker::<MAX_AXES>::new(&no_expected_flag);
    let has_models = models.loaded();
    let affected = |axis: Axis| {
        if M::SHARED { failing == Axis::X } else { axis == failing }
    };
    let mut axes = CompensationLoop::new(models, config, thermometers, front_ends, checker);
    let mut rng = Rng(seed | 1);
    let mut left = 0u32;
    for i in 0..samples {
        let phase = f64::from(i) / f64::from(samples.max(1));
        let temp_c = 20.0 + 25.0 * (1.0 - (2.0 * phase - 1.0).abs());
        if left == 0 && i > 0 && rng.next().is_multiple_of(60) {
            left = if rng.next().is_multiple_of(4) {
                150
            } else {
                rng.between(1, 40)
            };
        }
        let fails = left > 0;
        left = left.saturating_sub(1);
        for (axis, cell) in Axis::ALL.into_iter().zip(&current) {
            // Each coil a little warmer than the last, each its own bias.
            let coil_c = temp_c + 0.5 * axis.index() as f64;
            let rate_dph = 15.0 + 0.02 * (coil_c - 20.0) * (1.0 + axis.index() as f64);
            let reading = (!(fails && axis == failing)).then_some(coil_c);
            cell.set(ReplaySample::with_loop(reading, rate_dph as f32));
        }
        if fails {
            report.faulty_samples += 1;
        }
        axes.step(if i == 0 { 0.0 } else { period_s });
        let Some(f) = axes.output_mut().last.take() else {
            continue;
        };
        for (axis, out) in Axis::ALL.into_iter().zip(f.axes) {
            let flags = out.flags();
            let finite = out.bias_dph.is_finite() && out.rate_comp_dph.is_finite();
            if affected(axis) {
                if fails && !flags.contains(Flags::TEMP_SENSOR_FAULT) {
                    report.missing_flags += 1;
                }
                if flags.contains(Flags::NO_VALID_MODEL) {
                    report.failing_uncompensated += 1;
                }
                if !finite {
                    report.healthy_disturbed += 1;
                }
            } else if flags.contains(Flags::TEMP_SENSOR_FAULT)
                || (has_models && flags.contains(Flags::NO_VALID_MODEL))
                || !finite
            {
                report.healthy_disturbed += 1;
            }
        }
    }
    report.temp_read_faults_per_axis = axes.temp_read_faults_per_axis();
    let (_, _, checker) = axes.destroy();
    report.frames = checker.frames;
    report.samples_lost = samples.saturating_sub(checker.frames) + checker.bad_frames;
    report
}

/// Flips every bit of `blob` in turn; returns (flips, flips accepted by the decoder).
pub fn bit_flip_campaign(blob_bytes: &[u8]) -> (u32, u32) {
    let mut copy = [0u8; blob::MAX_BLOB_LEN];
    let Some(work) = copy.get_mut(..blob_bytes.len()) else {
        return (0, 0);
    };
    work.copy_from_slice(blob_bytes);
    let (mut flips, mut accepted) = (0, 0);
    for bit in 0..work.len() * 8 {
        if let Some(byte) = work.get_mut(bit / 8) {
            *byte ^= 1 << (bit % 8);
            flips += 1;
            if blob::decode(work).is_ok() {
                accepted += 1;
            }
            if let Some(byte) = work.get_mut(bit / 8) {
                *byte ^= 1 << (bit % 8);
            }
        }
    }
    (flips, accepted)
}

/// Slot length of the emulated model flash: five 1-KiB pages (a blob of at
/// most 4096 bytes and the commit record).
pub const EMULATED_SLOT_LEN: usize = 5 * PAGE;
/// The emulated model flash: slot A then slot B.
pub type ModelFlash = EmulatedFlash<{ 2 * EMULATED_SLOT_LEN }>;
/// Where the slots lie in [`ModelFlash`].
pub const EMULATED_LAYOUT: SlotLayout = SlotLayout {
    offsets: [0, EMULATED_SLOT_LEN as u32],
    len: EMULATED_SLOT_LEN as u32,
};
const _: () = assert!(EMULATED_SLOT_LEN >= blob::MAX_BLOB_LEN + COMMIT_LEN);

/// What the power-cut campaign found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateCampaign {
    /// Flash operations of one complete install.
    pub operations_per_install: u32,
    /// Resets injected (during every flash operation of an install and once
    /// after its last, starting from either slot).
    pub resets: u32,
    /// Boots after a reset that ran the old model.
    pub booted_old: u32,
    /// Boots after a reset that ran the new model.
    pub booted_new: u32,
    /// Boots that ran no model or a model that is neither (must be 0).
    pub booted_invalid: u32,
    /// Installs retried after the reset that failed (must be 0).
    pub retry_failures: u32,
}

/// Installs `new` over `old` with power cut after every flash operation in
/// turn, starting once with `old` running from slot A (flashed by a
/// programmer, uncommitted) and once from slot B (committed by an earlier
/// update); after each cut boots the store and checks it runs `old` or
/// `new`, then retries the install.
pub fn power_cut_campaign(old: &[u8], new: &[u8]) -> UpdateCampaign {
    let mut report = UpdateCampaign::default();
    let (Ok(old_model), Ok(new_model)) = (blob::decode(old), blob::decode(new)) else {
        report.booted_invalid = 1;
        return report;
    };
    let (old_model, new_model) = (old_model.model, new_model.model);
    for start_in_b in [false, true] {
        // The starting flash: `old` in A as a programmer leaves it, or moved to B by an update.
        let mut base = ModelFlash::new();
        if let Some(a) = base.contents_mut().get_mut(..old.len()) {
            a.copy_from_slice(old);
        }
        if start_in_b {
            let mut store = ModelStore::open(base, EMULATED_LAYOUT);
            if store.install(old).is_err() {
                report.booted_invalid += 1;
                return report;
            }
            base = store.into_flash();
        }
        // A full install, to count its operations.
        let before = base.operations();
        let mut store = ModelStore::open(base.clone(), EMULATED_LAYOUT);
        if store.install(new).is_err() {
            report.retry_failures += 1;
            return report;
        }
        let ops = store.into_flash().operations() - before;
        report.operations_per_install = ops;
        // Cut after each operation, and once more after the last (during the read-back).
        for cut in 0..=ops {
            let mut flash = base.clone();
            flash.cut_power_after(cut);
            let mut store = ModelStore::open(flash, EMULATED_LAYOUT);
            let interrupted = store.install(new).is_err();
            let mut flash = store.into_flash();
            flash.power_cycle();
            report.resets += 1;
            // Boot.
            let mut store = ModelStore::open(flash, EMULATED_LAYOUT);
            match store.load() {
                Ok(m) if m == old_model && interrupted => report.booted_old += 1,
                Ok(m) if m == new_model => report.booted_new += 1,
                _ => report.booted_invalid += 1,
            }
            // The update is simply sent again.
            match store.install(new) {
                Ok(m) if m == new_model && store.load().is_ok_and(|m| m == new_model) => {}
                _ => report.retry_failures += 1,
            }
        }
    }
    report
}

/// What the UART command campaign found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CommandCampaign {
    /// Commands sent.
    pub commands: u32,
    /// Replies that matched the expected status.
    pub expected_replies: u32,
    /// The loop ran the new model afterwards and compensated (flag 4 gone).
    pub switched: bool,
}

/// Sends, through [`CommandReceiver`] into a store running `old`: a garbage
/// frame, an unknown command, an install of `new` with one bit flipped, an
/// oversized frame, then the intact install; checks the replies and that a
/// loop that started without a model compensates with `new` afterwards.
pub fn command_campaign(old: &[u8], new: &[u8]) -> CommandCampaign {
    let mut report = CommandCampaign::default();
    let mut flash = ModelFlash::new();
    if let Some(a) = flash.contents_mut().get_mut(..old.len()) {
        a.copy_from_slice(old);
    }
    let mut store = ModelStore::open(flash, EMULATED_LAYOUT);
    let mut receiver = CommandReceiver::new();
    let mut frame = [0u8; command::MAX_COMMAND_FRAME_LEN];
    let Some(n) = command::encode_install_command(new, &mut frame) else {
        return report;
    };
    let intact = frame.get(..n).unwrap_or(&[]);
    // The same blob with one bit flipped, framed correctly: the CRC must refuse it.
    let mut damaged = [0u8; blob::MAX_BLOB_LEN];
    let Some(damaged) = damaged.get_mut(..new.len()) else {
        return report;
    };
    damaged.copy_from_slice(new);
    if let Some(b) = damaged.get_mut(new.len() / 2) {
        *b ^= 0x04;
    }
    let mut corrupt = [0u8; command::MAX_COMMAND_FRAME_LEN];
    let Some(m) = command::encode_install_command(damaged, &mut corrupt) else {
        return report;
    };
    let corrupt = corrupt.get(..m).unwrap_or(&[]);
    let oversized = [0x11u8; command::MAX_COMMAND_FRAME_LEN + 8];
    let sends: [(&[u8], UpdateStatus); 5] = [
        (&[0x05, 0x00], UpdateStatus::Malformed),
        (&[0x02, 0x7E, 0x00], UpdateStatus::UnknownCommand),
        (corrupt, UpdateStatus::Refused),
        (&oversized, UpdateStatus::TooLong),
        (intact, UpdateStatus::Installed),
    ];
    let mut installed = None;
    for (bytes, want) in sends {
        report.commands += 1;
        let mut got = None;
        for &b in bytes
            .iter()
            .chain(if bytes.last() == Some(&0) { &[][..] } else { &[0][..] })
        {
            match receiver.push(b) {
                Some(Received::Command(payload)) => {
                    let (status, model) = update::execute(&mut store, payload);
                    installed = model.or(installed.take());
                    got = Some(status);
                }
                Some(Received::Rejected(status)) => got = Some(status),
                None => {}
            }
        }
        let mut reply = [0u8; 8];
        if got == Some(want) && command::encode_reply(0, want, &mut reply).is_some() {
            report.expected_replies += 1;
        }
    }
    // A loop that booted without a model switches to the installed one.
    let new_model = blob::decode(new).ok().map(|d| d.model);
    if installed.is_some() && installed == new_model {
        let expected = Cell::new(None);
        let current = Cell::new(ReplaySample::with_loop(Some(25.0), 15.0));
        let mut lp = CompensationLoop::new(
            None::<Model>,
            LoopConfig {
                compensator: CompensatorConfig::for_sample_rate(10.0),
                temp_read_every: 1,
            },
            Tmp117::new(EmulatedTmp117::new(&current, 0), LOOP_SENSOR_ADDRESS),
            FrontEnd::new(EmulatedFrontEnd::new(&current)),
            FrameChecker::<1>::new(&expected),
        );
        let [before] = lp.step(0.0);
        lp.replace_model(store.load().ok());
        let [after] = lp.step(0.1);
        let (before, after) = (
            before.flags.contains(Flags::NO_VALID_MODEL),
            after.flags.contains(Flags::NO_VALID_MODEL),
        );
        report.switched = before && !after;
    }
    report
}
