//! The loop state a C caller keeps in memory of its own: a single gyro's
//! ([`Gyro`]) or a three-axis IMU's ([`Imu`]), each the decoded model(s),
//! rbf-core's [`Compensator`] per loop and the deployment's
//! [`CompensatorConfig`]. Every step is rbf-core's own
//! ([`Compensator::process`], [`Compensator::process_with`],
//! [`Compensator::process_shared`]): the steps `trainer compensate` runs,
//! so the bits agree.

use rbf_core::axis::{Axis, MAX_AXES};
use rbf_core::blob::axes::{AxisModels, decode_any_into};
use rbf_core::blob::shared_layout::decode_shared_into;
use rbf_core::blob::{self, BlobKind, CRC_LEN, DecodeError};
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::model::SERIAL_CAPACITY;
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::{
    CompensatedSample, Compensator, CompensatorConfig, GyroSample, MAX_AXIS_CENTERS, MAX_SHARED_AXIS_CENTERS, Model,
};

/// What the loads and steps of one kind of state share (the C functions
/// are written once over it).
pub trait LoopState {
    /// First word of a state set up by a load (any other value: not loaded).
    /// A byte repeated four times: a Thumb-2 immediate, so the check that
    /// every step makes is one compare.
    const TAG: u32;

    /// Sets up the state at `p` without a model, for the deployment
    /// `config`, field by field in place (no state-sized value on the stack).
    ///
    /// # Safety
    /// `p` is valid for writes of `Self` and aligned for it.
    unsafe fn init(p: *mut Self, config: CompensatorConfig);

    /// Decodes `blob` into the state's model storage, in place; returns the
    /// blob's length. On error the state holds no model.
    fn load(&mut self, blob: &[u8]) -> Result<usize, DecodeError>;

    /// What the last load gave: the blob it loaded, or its status code.
    fn load_result(&self) -> Result<Loaded, i32>;

    /// Records what a load gave.
    fn set_load_result(&mut self, result: Result<Loaded, i32>);
}

/// What a successful load keeps of the blob besides the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct Loaded {
    /// The blob's CRC-32 (its trailer, checked by the decoder).
    pub crc32: u32,
    /// Axes the model compensates: bit 0 x, bit 1 y, bit 2 z (a single gyro: 1).
    pub axis_mask: u8,
    /// The blob's provenance section (formats 4 and 5), `None` for a blob
    /// written before provenance existed (formats 2 and 3).
    pub provenance: Option<LoadedProvenance>,
}

/// What the state keeps of a loaded blob's provenance: the id that finds
/// the calibration record again and the unit serial it names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct LoadedProvenance {
    /// The short model id (`trainer inspect`'s `model_id`).
    pub model_id: u32,
    /// Bytes of `serial` in use.
    pub serial_len: u8,
    /// The serial, UTF-8, zero-padded.
    pub serial: [u8; SERIAL_CAPACITY],
}

impl Loaded {
    /// What the state keeps of the `len`-byte blob at the start of `bytes`
    /// (the decoder checked it): its CRC-32 trailer and its provenance, with `axis_mask`.
    pub fn of(bytes: &[u8], len: usize, axis_mask: u8) -> Loaded {
        let blob = bytes.get(..len).unwrap_or(&[]);
        let crc = len
            .checked_sub(CRC_LEN)
            .and_then(|at| blob.get(at..))
            .and_then(|b| <[u8; CRC_LEN]>::try_from(b).ok())
            .map_or(0, u32::from_le_bytes);
        let provenance = blob::provenance(blob).ok().flatten().map(|p| {
            let mut serial = [0u8; SERIAL_CAPACITY];
            let bytes = p.serial.as_bytes();
            let n = bytes.len().min(SERIAL_CAPACITY);
            if let (Some(to), Some(from)) = (serial.get_mut(..n), bytes.get(..n)) {
                to.copy_from_slice(from);
            }
            LoadedProvenance {
                model_id: p.model_id,
                serial_len: n as u8,
                serial,
            }
        });
        Loaded {
            crc32: crc,
            axis_mask,
            provenance,
        }
    }
}

/// A thermometer reading as rbf-core takes it: the C side's NaN ("no
/// reading") passes as it is. rbf-core judges `Some(NaN)` exactly as
/// `None` (a NaN is not a plausible temperature, so the reading fails and
/// the last good value is held), so no per-sample test is spent on it.
#[inline(always)]
fn reading(temp_c: f32) -> Option<f32> {
    Some(temp_c)
}

/// Every thermometer of a C sample as rbf-core takes it: the C side's NaN ("no
/// reading") passes as it is, and rbf-core holds the last good value.
#[inline(always)]
pub fn readings(temps_c: &[f32; THERMOMETERS]) -> [Option<f32>; THERMOMETERS] {
    temps_c.map(reading)
}

/// A single gyro: one model (up to [`rbf_core::MAX_CENTERS`] centres) and its loop.
#[repr(C)]
pub struct Gyro {
    tag: u32,
    load: Result<Loaded, i32>,
    config: CompensatorConfig,
    compensator: Compensator,
    /// The sample handed to rbf-core, kept here so that a step writes only
    /// what changed: the time step, the rate and the thermometers in `reads`
    /// (the others stay `None`; rbf-core reads no thermometer outside them).
    sample: GyroSample,
    /// The thermometers the step reads (bit i: `temps_c[i]`), set by the
    /// load: the model's, or the loop thermometer without a model (as
    /// rbf-core's step runs then).
    reads: u8,
    /// The index of the one thermometer in `reads`, or [`SEVERAL`] (most
    /// models read one: their step takes no loop over `reads`).
    only: u8,
    model: Model,
}

/// The sample of a state before its first step: no thermometer read.
const EMPTY_SAMPLE: GyroSample = GyroSample {
    dt_s: 0.0,
    rate_dph: 0.0,
    temps_c: [None; THERMOMETERS],
};

/// The thermometers rbf-core's step reads for `model` (bit i: `temps_c[i]`).
fn thermometers_read<const K: usize>(model: Option<&Model<K>>) -> u8 {
    model.map_or(1 << LOOP_THERMOMETER, |m| m.features().set.thermometers().bits())
}

/// `Gyro::only` of a model that reads more than one thermometer.
const SEVERAL: u8 = u8::MAX;

/// The index of the one thermometer in `reads`, or [`SEVERAL`].
fn only_thermometer(reads: u8) -> u8 {
    if reads.is_power_of_two() {
        reads.trailing_zeros() as u8
    } else {
        SEVERAL
    }
}

/// Writes the thermometers in `reads` into `sample`, as rbf-core takes
/// them ([`reading`]); `temp_c(i)` reads thermometer i of the C sample.
#[inline(always)]
fn write_readings(sample: &mut GyroSample, reads: u8, temp_c: impl Fn(usize) -> f32) {
    let mut unvisited = reads;
    while unvisited != 0 {
        let i = unvisited.trailing_zeros() as usize;
        unvisited &= unvisited - 1;
        if let Some(slot) = sample.temps_c.get_mut(i) {
            *slot = reading(temp_c(i));
        }
    }
}

impl LoopState for Gyro {
    const TAG: u32 = 0x6767_6767; // "gggg"

    unsafe fn init(p: *mut Self, config: CompensatorConfig) {
        // SAFETY: the caller's promise; each field written once, in place.
        unsafe {
            (&raw mut (*p).model).write(Model::EMPTY);
            (&raw mut (*p).compensator).write(Compensator::new());
            (&raw mut (*p).sample).write(EMPTY_SAMPLE);
            let reads = thermometers_read::<{ rbf_core::MAX_CENTERS }>(None);
            (&raw mut (*p).reads).write(reads);
            (&raw mut (*p).only).write(only_thermometer(reads));
            (&raw mut (*p).config).write(config);
            (&raw mut (*p).load).write(Err(crate::RBF_ERR_STATE_NOT_LOADED));
            (&raw mut (*p).tag).write(Self::TAG);
        }
    }

    fn load(&mut self, blob: &[u8]) -> Result<usize, DecodeError> {
        let result = blob::decode_into(&mut self.model, blob);
        self.sample = EMPTY_SAMPLE;
        self.reads = thermometers_read(result.is_ok().then_some(&self.model));
        self.only = only_thermometer(self.reads);
        result
    }

    fn load_result(&self) -> Result<Loaded, i32> {
        self.load
    }

    fn set_load_result(&mut self, result: Result<Loaded, i32>) {
        self.load = result;
    }
}

impl Gyro {
    /// One sample (`dt_s`, s; `rate_dph`, °/h; `temp_c(i)` thermometer i,
    /// °C, NaN: no reading, read only for the thermometers the model reads)
    /// through [`Compensator::process`], the step `trainer compensate` runs.
    #[inline(always)]
    pub fn step(&mut self, dt_s: f32, rate_dph: f32, temp_c: impl Fn(usize) -> f32) -> CompensatedSample {
        self.sample.dt_s = dt_s;
        self.sample.rate_dph = rate_dph;
        match self.sample.temps_c.get_mut(usize::from(self.only)) {
            Some(slot) => *slot = reading(temp_c(usize::from(self.only))),
            None => write_readings(&mut self.sample, self.reads, temp_c),
        }
        let model = self.load.is_ok().then_some(&self.model);
        self.compensator.process(model, &self.config, &self.sample)
    }
}

/// The models an IMU's blob gives: one per axis (as the `stm32f405-axes`
/// board holds them) or one shared basis (as `stm32f405-axes-shared`).
#[allow(
    clippy::large_enum_variant,
    reason = "the state lives in the caller's memory, sized for the larger kind; a box would need a heap"
)]
enum ImuModels {
    PerAxis(AxisModels<MAX_AXIS_CENTERS>),
    Shared(SharedAxisModels<MAX_SHARED_AXIS_CENTERS>),
}

/// A three-axis IMU: a model per axis (up to [`MAX_AXIS_CENTERS`] centres
/// each) or one shared basis (up to [`MAX_SHARED_AXIS_CENTERS`]), and the loops.
#[repr(C)]
pub struct Imu {
    tag: u32,
    load: Result<Loaded, i32>,
    config: CompensatorConfig,
    compensators: [Compensator; MAX_AXES],
    models: ImuModels,
}

impl LoopState for Imu {
    const TAG: u32 = 0x6969_6969; // "iiii"

    unsafe fn init(p: *mut Self, config: CompensatorConfig) {
        // SAFETY: the caller's promise; each field written once, in place.
        unsafe {
            (&raw mut (*p).models).write(ImuModels::PerAxis(AxisModels::EMPTY));
            (&raw mut (*p).compensators).write([Compensator::new(); MAX_AXES]);
            (&raw mut (*p).config).write(config);
            (&raw mut (*p).load).write(Err(crate::RBF_ERR_STATE_NOT_LOADED));
            (&raw mut (*p).tag).write(Self::TAG);
        }
    }

    fn load(&mut self, blob: &[u8]) -> Result<usize, DecodeError> {
        // The storage of the blob's kind (replaced only when the kind changes).
        let shared = blob::blob_kind(blob) == Ok(BlobKind::SharedBasis);
        match (&self.models, shared) {
            (ImuModels::PerAxis(_), true) => self.models = ImuModels::Shared(SharedAxisModels::EMPTY),
            (ImuModels::Shared(_), false) => self.models = ImuModels::PerAxis(AxisModels::EMPTY),
            _ => {}
        }
        match &mut self.models {
            ImuModels::Shared(models) => decode_shared_into(models, blob),
            ImuModels::PerAxis(models) => decode_any_into(models, blob),
        }
    }

    fn load_result(&self) -> Result<Loaded, i32> {
        self.load
    }

    fn set_load_result(&mut self, result: Result<Loaded, i32>) {
        self.load = result;
    }
}

impl Imu {
    /// The axes the decoded models cover (bit 0 x).
    pub fn axis_mask(&self) -> u8 {
        match &self.models {
            ImuModels::PerAxis(m) => m.mask(),
            ImuModels::Shared(m) => m.mask(),
        }
    }

    /// One sample of every axis: `temps_c` the shared thermometers
    /// (`temp_a` … `temp_h`), `loop_temps_c` each axis's fiber-loop
    /// thermometer, which stands at `temp_c`'s place in that axis's
    /// readings, as `trainer compensate` reads `temp_<axis>_c`. A model per
    /// axis: each axis through [`Compensator::process_with`]; a shared
    /// basis: all axes through one [`Compensator::process_shared`] on
    /// `temps_c` alone (such a model reads one thermometer set).
    #[inline(always)]
    pub fn step(
        &mut self,
        dt_s: f32,
        rates_dph: &[f32; MAX_AXES],
        temps_c: &[f32; THERMOMETERS],
        loop_temps_c: &[f32; MAX_AXES],
    ) -> [CompensatedSample; MAX_AXES] {
        let loaded = self.load.is_ok();
        let temps = readings(temps_c);
        match &self.models {
            ImuModels::Shared(models) => {
                let [compensator, ..] = &mut self.compensators;
                compensator.process_shared(loaded.then_some(models), &self.config, dt_s, &temps, rates_dph)
            }
            ImuModels::PerAxis(models) => {
                let mut out = [CompensatedSample {
                    bias_dph: 0.0,
                    rate_comp_dph: 0.0,
                    temp_c: f32::NAN,
                    flags: rbf_core::Flags::NONE,
                }; MAX_AXES];
                for (((axis, compensator), slot), (&rate_dph, &loop_c)) in Axis::ALL
                    .into_iter()
                    .zip(&mut self.compensators)
                    .zip(&mut out)
                    .zip(rates_dph.iter().zip(loop_temps_c))
                {
                    let mut temps_c = temps;
                    if let Some(t) = temps_c.get_mut(LOOP_THERMOMETER) {
                        *t = reading(loop_c);
                    }
                    let sample = GyroSample {
                        dt_s,
                        rate_dph,
                        temps_c,
                    };
                    let model = models.get(axis).filter(|_| loaded);
                    *slot = compensator.process_with(model, &self.config, &sample);
                }
                out
            }
        }
    }
}
