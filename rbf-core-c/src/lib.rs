//! # rbf-core-c: the model from C firmware
//!
//! A static library (`librbf_core_c.a`, for `thumbv7em-none-eabihf` and the
//! host) and one header, `include/rbf_core.h`, generated from this crate by
//! cbindgen (`cargo xtask c-header`; CI fails when the checked-in header
//! drifts). The interface a C loop needs and nothing more (docs/c-library.md):
//!
//! - the state's size and alignment as constants: the caller owns the
//!   memory (a `static` buffer), there is no heap;
//! - `rbf_gyro_load` / `rbf_imu_load`: a model from blob bytes, with every
//!   check of rbf-core's decoder, returning a documented status code
//!   (`rbf_status_message` gives it in words); a refused blob leaves the
//!   state without a model: every sample is passed through with flag 4;
//! - `rbf_gyro_step` / `rbf_imu_step`: one call per gyro sample, through
//!   rbf-core's own compensator step (the one `trainer compensate` runs, so
//!   the bits agree);
//! - `rbf_gyro_model_info` / `rbf_imu_model_info`: the loaded blob's CRC-32
//!   and its provenance id and serial (`RBF_PROVENANCE_NONE` for a blob
//!   without provenance).
//!
//! Every pointer and length is checked; no panic is reachable from any
//! exported function (on the target the link-time check of the
//! `panic-free-check` feature proves it: docs/panic-free.md).
#![cfg_attr(target_os = "none", no_std)]
// The C interface is raw pointers: every unsafe block is in this file and
// says why it holds.
#![allow(unsafe_code)]

use core::ffi::{c_char, c_void};

use rbf_core::axis::MAX_AXES;
use rbf_core::blob::MAX_BLOB_LEN;
use rbf_core::features::THERMOMETERS;
use rbf_core::{CompensatedSample, CompensatorConfig, Flags};

pub mod state;
pub mod status;

pub use status::*;

use state::{Gyro, Imu, Loaded, LoopState};

/// Bytes of memory a single gyro's state needs (`rbf_gyro_*`): the largest
/// over the targets (the thumbv7em state is 24 B smaller than the host's).
pub const RBF_GYRO_STATE_SIZE: usize = 5336;
/// Alignment, bytes, a single gyro's state needs.
pub const RBF_GYRO_STATE_ALIGN: usize = 8;
/// Bytes of memory a three-axis IMU's state needs (`rbf_imu_*`): the
/// largest over the targets (the thumbv7em state is 72 B smaller).
pub const RBF_IMU_STATE_SIZE: usize = 6968;
/// Alignment, bytes, a three-axis IMU's state needs.
pub const RBF_IMU_STATE_ALIGN: usize = 8;
/// Thermometers a sample carries: `temp_a` … `temp_h` of the recorded-run format.
pub const RBF_THERMOMETERS: usize = 8;
/// Index of the fiber-loop thermometer (`temp_c`) among them.
pub const RBF_LOOP_THERMOMETER: usize = 2;
/// Axes of an IMU: x, y, z.
pub const RBF_AXES: usize = 3;
/// Bytes of the unit serial in `rbf_model_info_t` (a provenance names at most this many).
pub const RBF_SERIAL_CAPACITY: usize = 32;
/// `rbf_model_info_t.provenance_id` of a blob without provenance (formats 2
/// and 3, written before blobs carried one) or of a state without a model;
/// `has_provenance` is then 0.
pub const RBF_PROVENANCE_NONE: u32 = 0;
/// Flag bit: an input lay outside the training range and was clamped.
pub const RBF_FLAG_INPUT_CLAMPED: u8 = 1;
/// Flag bit: a thermometer failed or read implausibly; its last good value is held.
pub const RBF_FLAG_TEMP_SENSOR_FAULT: u8 = 2;
/// Flag bit: no valid model or no usable temperature: the rate is passed through.
pub const RBF_FLAG_NO_VALID_MODEL: u8 = 4;
/// Flag bit: the features are still settling after a start or a gap.
pub const RBF_FLAG_WARMING_UP: u8 = 8;
/// Flag bit: the rate was NaN or beyond ±1000 °/s; passed through.
pub const RBF_FLAG_RATE_INVALID: u8 = 16;

// The constants are literals (cbindgen writes them into the header as
// they stand); these checks hold them to the real layout on every target.
const _: () = {
    assert!(core::mem::size_of::<Gyro>() <= RBF_GYRO_STATE_SIZE);
    assert!(core::mem::align_of::<Gyro>() <= RBF_GYRO_STATE_ALIGN);
    assert!(core::mem::size_of::<Imu>() <= RBF_IMU_STATE_SIZE);
    assert!(core::mem::align_of::<Imu>() <= RBF_IMU_STATE_ALIGN);
    assert!(RBF_THERMOMETERS == THERMOMETERS);
    assert!(RBF_LOOP_THERMOMETER == rbf_core::features::LOOP_THERMOMETER);
    assert!(RBF_AXES == MAX_AXES);
    assert!(RBF_SERIAL_CAPACITY == rbf_core::model::SERIAL_CAPACITY);
    assert!(RBF_FLAG_INPUT_CLAMPED == Flags::INPUT_CLAMPED.bits());
    assert!(RBF_FLAG_TEMP_SENSOR_FAULT == Flags::TEMP_SENSOR_FAULT.bits());
    assert!(RBF_FLAG_NO_VALID_MODEL == Flags::NO_VALID_MODEL.bits());
    assert!(RBF_FLAG_WARMING_UP == Flags::WARMING_UP.bits());
    assert!(RBF_FLAG_RATE_INVALID == Flags::RATE_INVALID.bits());
};

/// One sample of a single gyro.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RbfGyroSample {
    /// Time since the previous sample, s (ignored on the first sample; a
    /// step over twice the nominal period is a gap: the features restart).
    pub dt_s: f32,
    /// Gyro output, °/h.
    pub rate_dph: f32,
    /// Thermometers `temp_a` … `temp_h`, °C; index `RBF_LOOP_THERMOMETER`
    /// (`temp_c`) is the fiber loop's. NaN: no reading (the sensor failed
    /// or is not fitted); a model reads only the thermometers it was fitted on.
    pub temps_c: [f32; RBF_THERMOMETERS],
}

/// One sample of a three-axis IMU.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RbfImuSample {
    /// Time since the previous sample, s (as in `rbf_gyro_sample_t`).
    pub dt_s: f32,
    /// Each axis's gyro output, °/h, x first.
    pub rates_dph: [f32; RBF_AXES],
    /// The IMU's thermometers `temp_a` … `temp_h`, °C (NaN: no reading). A
    /// shared-basis model reads these alone.
    pub temps_c: [f32; RBF_THERMOMETERS],
    /// Each axis's fiber-loop thermometer, °C, x first (NaN: no reading):
    /// a model per axis reads it in place of `temps_c[RBF_LOOP_THERMOMETER]`.
    /// An IMU with one loop thermometer gives that value for every axis.
    pub loop_temps_c: [f32; RBF_AXES],
}

/// The result of one sample of one axis.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RbfOutput {
    /// Bias estimate subtracted, °/h (0 when uncompensated).
    pub bias_dph: f32,
    /// `rate_dph − bias_dph`, °/h.
    pub rate_comp_dph: f32,
    /// Temperature the features used (held during a fault), °C; NaN if none.
    pub temp_c: f32,
    /// `RBF_FLAG_*` bits; 0: all is well.
    pub flags: u8,
}

/// The result of one sample of every axis of an IMU.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RbfImuOutput {
    /// Per axis, x first (an axis without a model: passed through, flag 4).
    pub axes: [RbfOutput; RBF_AXES],
}

/// What a state's model is.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RbfModelInfo {
    /// The status of the last load (`RBF_OK`: a model runs).
    pub load_status: i32,
    /// The loaded blob's CRC-32 (ISO-HDLC, its trailer), 0 without a model:
    /// what `trainer inspect` and `trainer device status` show as `crc32`.
    pub crc32: u32,
    /// The blob's provenance id: the short model id `trainer fit` wrote
    /// into its provenance section, which finds the calibration record
    /// again (`trainer inspect` shows it as `model_id`, eight hex digits,
    /// as does `trainer device status` for a board). `RBF_PROVENANCE_NONE`
    /// (0) when `has_provenance` is 0.
    pub provenance_id: u32,
    /// Axes with a model: bit 0 x, bit 1 y, bit 2 z (a single gyro: 1); 0 without a model.
    pub axis_mask: u8,
    /// 1 when the loaded blob carries a provenance section (formats 4 and
    /// 5); 0 for an older blob or without a model.
    pub has_provenance: u8,
    /// Bytes of `serial` in use: 0 when the provenance names no serial.
    pub serial_len: u8,
    /// The unit serial the provenance names, UTF-8, zero-padded (not
    /// NUL-terminated when all `RBF_SERIAL_CAPACITY` bytes are used).
    pub serial: [u8; RBF_SERIAL_CAPACITY],
}

impl From<CompensatedSample> for RbfOutput {
    #[inline(always)]
    fn from(s: CompensatedSample) -> Self {
        RbfOutput {
            bias_dph: s.bias_dph,
            rate_comp_dph: s.rate_comp_dph,
            temp_c: s.temp_c,
            flags: s.flags.bits(),
        }
    }
}

/// The state at `state`, checked to be there, long enough and aligned for `T`.
fn storage<T>(state: *mut c_void, state_len: usize) -> Result<*mut T, i32> {
    if state.is_null() {
        return Err(refused(RBF_ERR_NULL_POINTER));
    }
    if state_len < core::mem::size_of::<T>() {
        return Err(refused(RBF_ERR_STATE_TOO_SMALL));
    }
    if !(state as usize).is_multiple_of(core::mem::align_of::<T>()) {
        return Err(refused(RBF_ERR_STATE_MISALIGNED));
    }
    Ok(state.cast())
}

/// `code`, on the path of a refused call: out of line, so that the checks
/// of every step cost their compares and nothing more.
#[cold]
#[inline(never)]
fn refused(code: i32) -> i32 {
    code
}

/// The loaded state at `state` ([`storage`], and its tag says a load set it up).
///
/// # Safety
/// `state` is valid for reads and writes of `state_len` bytes, and nothing
/// else uses them during the call.
unsafe fn loaded_state<'s, T: LoopState>(state: *mut c_void, state_len: usize) -> Result<&'s mut T, i32> {
    let p = storage::<T>(state, state_len)?;
    // SAFETY: `p` is aligned and points at ≥ size_of::<T>() readable bytes
    // (the caller's promise, checked above); every `#[repr(C)]` state starts
    // with its u32 tag, and any bytes are a valid u32.
    let tag = unsafe { p.cast::<u32>().read() };
    if tag != T::TAG {
        return Err(refused(RBF_ERR_STATE_NOT_LOADED));
    }
    // SAFETY: the tag is written last by `LoopState::init`, so the memory
    // holds a state that a load set up; the caller's promise makes the
    // borrow exclusive.
    Ok(unsafe { &mut *p })
}

/// The load of either kind of state (see `rbf_gyro_load`).
///
/// # Safety
/// As `rbf_gyro_load`.
unsafe fn load<T: LoopState>(
    state: *mut c_void,
    state_len: usize,
    blob: *const u8,
    blob_len: usize,
    sample_rate_hz: f32,
    axis_mask: impl FnOnce(&T) -> u8,
) -> i32 {
    let p = match storage::<T>(state, state_len) {
        Ok(p) => p,
        Err(code) => return code,
    };
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        // SAFETY: `p` is checked and the caller promises the bytes; a state
        // that cannot run is marked not loaded.
        unsafe { p.cast::<u32>().write(0) };
        return RBF_ERR_SAMPLE_RATE;
    }
    // SAFETY: as above: aligned, long enough, exclusively the caller's.
    unsafe { T::init(p, CompensatorConfig::for_sample_rate(sample_rate_hz)) };
    // SAFETY: `init` set up every field.
    let state = unsafe { &mut *p };
    if blob.is_null() {
        return RBF_ERR_NULL_POINTER;
    }
    // A blob is at most MAX_BLOB_LEN bytes and the decoders ignore what
    // follows it: a caller may pass a whole flash slot.
    let len = blob_len.min(MAX_BLOB_LEN);
    // SAFETY: the caller promises `blob_len` readable bytes at `blob`, not
    // written during the call; `len` ≤ that and ≤ 4096 (< isize::MAX).
    let bytes = unsafe { core::slice::from_raw_parts(blob, len) };
    let result = match state.load(bytes) {
        Ok(used) => Ok(Loaded::of(bytes, used, axis_mask(state))),
        Err(e) => Err(status::from_decode(e)),
    };
    state.set_load_result(result);
    result.err().unwrap_or(RBF_OK)
}

/// Sets up a single gyro's state in the caller's memory and loads the model
/// blob `blob[0 .. blob_len]` (format 2, one model; trailing bytes, e.g.
/// the rest of a flash slot, are ignored) for a gyro sampled at
/// `sample_rate_hz`. Returns `RBF_OK`, or why the blob is refused: the
/// state then runs without a model (every sample passed through, flag 4).
/// A state too small, misaligned or NULL, or a sample rate that is not a
/// positive number, leaves no usable state (`rbf_gyro_step` refuses it).
///
/// # Safety
/// `state` points at `state_len` bytes the caller owns (at least
/// `RBF_GYRO_STATE_SIZE`, aligned to `RBF_GYRO_STATE_ALIGN`), `blob` at
/// `blob_len` readable bytes; neither is used elsewhere during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_gyro_load(
    state: *mut c_void,
    state_len: usize,
    blob: *const u8,
    blob_len: usize,
    sample_rate_hz: f32,
) -> i32 {
    // SAFETY: the caller's promise, passed on.
    unsafe { load::<Gyro>(state, state_len, blob, blob_len, sample_rate_hz, |_| 1) }
}

/// Sets up a three-axis IMU's state and loads a blob of any kind: one model
/// per axis or a shared basis (format 3), or a single-axis model (format 2,
/// for axis x). As `rbf_gyro_load` otherwise.
///
/// # Safety
/// As `rbf_gyro_load`, with `RBF_IMU_STATE_SIZE` and `RBF_IMU_STATE_ALIGN`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_imu_load(
    state: *mut c_void,
    state_len: usize,
    blob: *const u8,
    blob_len: usize,
    sample_rate_hz: f32,
) -> i32 {
    // SAFETY: the caller's promise, passed on.
    unsafe { load::<Imu>(state, state_len, blob, blob_len, sample_rate_hz, Imu::axis_mask) }
}

/// An output a step writes into the caller's memory (any alignment).
trait CallerOutput: Sized {
    /// Writes `self` to `out`.
    ///
    /// # Safety
    /// `out` is non-null and writable for the call.
    unsafe fn write_to(self, out: *mut Self);
}

impl CallerOutput for RbfOutput {
    /// Field by field as words (unaligned word stores straight from the
    /// step's result, not through the FPU's registers).
    #[inline(always)]
    unsafe fn write_to(self, out: *mut Self) {
        // SAFETY: the caller's promise; each field inside `*out`.
        unsafe {
            (&raw mut (*out).bias_dph)
                .cast::<u32>()
                .write_unaligned(self.bias_dph.to_bits());
            (&raw mut (*out).rate_comp_dph)
                .cast::<u32>()
                .write_unaligned(self.rate_comp_dph.to_bits());
            (&raw mut (*out).temp_c)
                .cast::<u32>()
                .write_unaligned(self.temp_c.to_bits());
            (&raw mut (*out).flags).write(self.flags);
        }
    }
}

impl CallerOutput for RbfImuOutput {
    #[inline(always)]
    unsafe fn write_to(self, out: *mut Self) {
        for (a, axis) in self.axes.into_iter().enumerate() {
            // SAFETY: the caller's promise; axis `a` inside `*out`.
            unsafe { axis.write_to((&raw mut (*out).axes).cast::<RbfOutput>().add(a)) };
        }
    }
}

/// The rate of a sample passed through uncompensated (flag 4), for a
/// state that cannot run.
fn passed_through(rate_dph: f32) -> RbfOutput {
    RbfOutput {
        bias_dph: 0.0,
        rate_comp_dph: rate_dph,
        temp_c: f32::NAN,
        flags: Flags::NO_VALID_MODEL.bits(),
    }
}

/// A sample in the caller's memory (any alignment), read field by field
/// where a step needs it: a whole copy of it would cost a `memcpy` per
/// sample. Made only by [`step`], from a non-null pointer the caller
/// promises readable for the call.
#[derive(Clone, Copy)]
struct CallerSample<S>(*const S);

impl CallerSample<RbfGyroSample> {
    #[inline(always)]
    fn dt_s(self) -> f32 {
        // SAFETY: non-null and readable during the call ([`CallerSample`]).
        unsafe { (&raw const (*self.0).dt_s).read_unaligned() }
    }
    #[inline(always)]
    fn rate_dph(self) -> f32 {
        // SAFETY: as above.
        unsafe { (&raw const (*self.0).rate_dph).read_unaligned() }
    }
    /// Thermometer `i` (`i` < `RBF_THERMOMETERS`; NaN past them).
    #[inline(always)]
    fn temp_c(self, i: usize) -> f32 {
        if i >= RBF_THERMOMETERS {
            return f32::NAN;
        }
        // SAFETY: as above; `i` is inside the array.
        unsafe { (&raw const (*self.0).temps_c).cast::<f32>().add(i).read_unaligned() }
    }
}

impl CallerSample<RbfImuSample> {
    /// The whole sample (an IMU's step reads every field).
    #[inline(always)]
    fn read(self) -> RbfImuSample {
        // SAFETY: as above.
        unsafe { self.0.read_unaligned() }
    }
}

/// The step of either kind of state: `run` on the loaded state and the
/// sample, or `pass` (the rate passed through with flag 4) when the state
/// cannot run; the result into `*out`.
///
/// # Safety
/// As [`rbf_gyro_step`].
#[inline(always)]
unsafe fn step<T: LoopState, S, O: CallerOutput>(
    state: *mut c_void,
    state_len: usize,
    sample: *const S,
    out: *mut O,
    run: impl FnOnce(&mut T, CallerSample<S>) -> O,
    pass: impl FnOnce(CallerSample<S>) -> O,
) -> i32 {
    if sample.is_null() || out.is_null() {
        return refused(RBF_ERR_NULL_POINTER);
    }
    // Non-null and readable for the call (the caller's promise).
    let sample = CallerSample(sample);
    // Each arm writes its own output (one write after the match would
    // send the step's result through the FPU's registers to meet the other's).
    // SAFETY: the caller's promise, passed on.
    match unsafe { loaded_state::<T>(state, state_len) } {
        Ok(loaded) => {
            // SAFETY: `out` is non-null and writable (the caller's promise).
            unsafe { run(loaded, sample).write_to(out) };
            RBF_OK
        }
        Err(code) => {
            // SAFETY: as above.
            unsafe { pass(sample).write_to(out) };
            code
        }
    }
}

/// Compensates one sample of a single gyro: `*out` gets the bias, the
/// compensated rate and the flags. Returns `RBF_OK`; a NULL pointer, or a
/// state that `rbf_gyro_load` did not set up, returns its code, and `*out`
/// (if there is one) then holds the rate passed through with flag 4.
/// Takes at most a few thousand instructions, none waiting on anything
/// (figures: docs/benchmarks.md, `cargo xtask bench-fw`).
///
/// # Safety
/// `state` as for `rbf_gyro_load`; `sample` points at a readable
/// `rbf_gyro_sample_t`, `out` at a writable `rbf_output_t` (any alignment).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_gyro_step(
    state: *mut c_void,
    state_len: usize,
    sample: *const RbfGyroSample,
    out: *mut RbfOutput,
) -> i32 {
    let run =
        |gyro: &mut Gyro, s: CallerSample<RbfGyroSample>| gyro.step(s.dt_s(), s.rate_dph(), |i| s.temp_c(i)).into();
    // SAFETY: the caller's promise, passed on.
    unsafe { step(state, state_len, sample, out, run, |s| passed_through(s.rate_dph())) }
}

/// Compensates one sample of every axis of a three-axis IMU: `out->axes[a]`
/// for axis a (x first). Returns as `rbf_gyro_step` does (every axis
/// passed through with flag 4 when the state cannot run).
///
/// # Safety
/// `state` as for `rbf_imu_load`; `sample` points at a readable
/// `rbf_imu_sample_t`, `out` at a writable `rbf_imu_output_t` (any alignment).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_imu_step(
    state: *mut c_void,
    state_len: usize,
    sample: *const RbfImuSample,
    out: *mut RbfImuOutput,
) -> i32 {
    let run = |imu: &mut Imu, s: CallerSample<RbfImuSample>| {
        let s = s.read();
        RbfImuOutput {
            axes: imu
                .step(s.dt_s, &s.rates_dph, &s.temps_c, &s.loop_temps_c)
                .map(RbfOutput::from),
        }
    };
    let pass = |s: CallerSample<RbfImuSample>| RbfImuOutput {
        axes: s.read().rates_dph.map(passed_through),
    };
    // SAFETY: the caller's promise, passed on.
    unsafe { step(state, state_len, sample, out, run, pass) }
}

/// The info of either kind of state (see `rbf_gyro_model_info`).
///
/// # Safety
/// As `rbf_gyro_model_info`.
unsafe fn model_info<T: LoopState>(state: *mut c_void, state_len: usize, out: *mut RbfModelInfo) -> i32 {
    if out.is_null() {
        return RBF_ERR_NULL_POINTER;
    }
    // SAFETY: the caller's promise, passed on.
    let (code, load) = match unsafe { loaded_state::<T>(state, state_len) } {
        Ok(s) => (RBF_OK, s.load_result()),
        Err(code) => (code, Err(code)),
    };
    let loaded = load.ok();
    let provenance = loaded.and_then(|l| l.provenance);
    let info = RbfModelInfo {
        load_status: load.err().unwrap_or(RBF_OK),
        crc32: loaded.map_or(0, |l| l.crc32),
        provenance_id: provenance.map_or(RBF_PROVENANCE_NONE, |p| p.model_id),
        axis_mask: loaded.map_or(0, |l| l.axis_mask),
        has_provenance: u8::from(provenance.is_some()),
        serial_len: provenance.map_or(0, |p| p.serial_len),
        serial: provenance.map_or([0; RBF_SERIAL_CAPACITY], |p| p.serial),
    };
    // SAFETY: non-null and writable (the caller's promise); written unaligned.
    unsafe { out.write_unaligned(info) };
    code
}

/// What a single gyro's state runs: `*out` gets the model's CRC-32, axes
/// and provenance id and serial (0 and none without a model). Returns
/// `RBF_OK`, or the code of a NULL pointer or a state not set up by a load.
///
/// # Safety
/// `state` as for `rbf_gyro_load`; `out` points at a writable `rbf_model_info_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_gyro_model_info(state: *mut c_void, state_len: usize, out: *mut RbfModelInfo) -> i32 {
    // SAFETY: the caller's promise, passed on.
    unsafe { model_info::<Gyro>(state, state_len, out) }
}

/// `rbf_gyro_model_info` of a three-axis IMU's state.
///
/// # Safety
/// `state` as for `rbf_imu_load`; `out` points at a writable `rbf_model_info_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn rbf_imu_model_info(state: *mut c_void, state_len: usize, out: *mut RbfModelInfo) -> i32 {
    // SAFETY: the caller's promise, passed on.
    unsafe { model_info::<Imu>(state, state_len, out) }
}

/// The meaning of status code `status` in words (English, ASCII), as a
/// NUL-terminated string that lives as long as the program; an unknown code
/// gives "unknown status code".
#[unsafe(no_mangle)]
pub extern "C" fn rbf_status_message(status: i32) -> *const c_char {
    status::message(status).as_ptr()
}

#[cfg(target_os = "none")]
mod panic;

/// The panic-free check's canary: one deliberate bounds check on an index
/// the optimiser cannot see, which must make the check's link fail (the
/// check would prove nothing otherwise). Never in a real build.
#[cfg(feature = "panic-free-check-canary")]
#[unsafe(no_mangle)]
pub extern "C" fn rbf_panic_canary(index: usize) -> u8 {
    let table = [1u8, 2, 3, 4];
    table[core::hint::black_box(index)]
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "a cubic in T at exact temperatures: the bits are what the C side gets"
)]
mod tests {
    use super::*;
    use rbf_core::model::{ModelBody, ModelInfo};
    use rbf_core::poly::Poly3;
    use rbf_core::{FeatureConfig, FeatureSet, GyroSample, Model};

    /// Caller-owned state memory, aligned as the header asks.
    #[repr(C, align(8))]
    struct Buffer([u8; RBF_IMU_STATE_SIZE + 8]);

    /// A blob of a model whose bias is 2 °/h per °C.
    fn blob() -> Vec<u8> {
        blob_with(None)
    }

    /// The same model's blob with `provenance` (format 4) or without (format 2).
    fn blob_with(provenance: Option<&rbf_core::blob::Provenance<'_>>) -> Vec<u8> {
        let body = ModelBody::Poly3(Poly3::new(0.0, [0.0, 2.0, 0.0, 0.0]).unwrap());
        let model = Model::new(
            FeatureConfig::single(FeatureSet::Temp, 0.0),
            &[(-40.0, 80.0)],
            body,
            ModelInfo::default(),
        )
        .unwrap();
        let mut out = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
        let n = rbf_core::blob::encode_with(&model, provenance, &mut out).unwrap();
        out.truncate(n);
        out
    }

    /// The info of a gyro state after loading `blob`.
    fn info_after_loading(blob: &[u8]) -> RbfModelInfo {
        let mut state = Buffer([0; RBF_IMU_STATE_SIZE + 8]);
        let p = state.0.as_mut_ptr().cast();
        // SAFETY: a live, aligned buffer and the blob.
        let code = unsafe { rbf_gyro_load(p, RBF_GYRO_STATE_SIZE, blob.as_ptr(), blob.len(), 1000.0) };
        assert_eq!(code, RBF_OK);
        let mut info = core::mem::MaybeUninit::<RbfModelInfo>::uninit();
        // SAFETY: a loaded state and a writable info.
        assert_eq!(
            unsafe { rbf_gyro_model_info(p, RBF_GYRO_STATE_SIZE, info.as_mut_ptr()) },
            RBF_OK
        );
        // SAFETY: written by the call.
        unsafe { info.assume_init() }
    }

    #[test]
    fn a_blob_with_provenance_gives_its_model_id_and_serial_and_one_without_gives_none() {
        let provenance = rbf_core::blob::Provenance {
            model_id: 0x6e48_3868,
            serial: "FOG-0001",
            record: b"{}",
        };
        let info = info_after_loading(&blob_with(Some(&provenance)));
        assert_eq!((info.has_provenance, info.provenance_id), (1, 0x6e48_3868));
        assert_eq!(&info.serial[..usize::from(info.serial_len)], b"FOG-0001");
        assert!(info.serial[8..].iter().all(|&b| b == 0), "zero-padded");
        let info = info_after_loading(&blob());
        assert_eq!(
            (info.has_provenance, info.provenance_id, info.serial_len, info.serial),
            (0, RBF_PROVENANCE_NONE, 0, [0; RBF_SERIAL_CAPACITY])
        );
    }

    fn sample(temp_c: f32) -> RbfGyroSample {
        let mut temps_c = [f32::NAN; RBF_THERMOMETERS];
        temps_c[RBF_LOOP_THERMOMETER] = temp_c;
        RbfGyroSample {
            dt_s: 0.001,
            rate_dph: 100.0,
            temps_c,
        }
    }

    fn step(state: &mut Buffer, s: &RbfGyroSample) -> (i32, RbfOutput) {
        let mut out = passed_through(f32::NAN);
        // SAFETY: a live, aligned buffer, a sample and an output.
        let code = unsafe { rbf_gyro_step(state.0.as_mut_ptr().cast(), RBF_GYRO_STATE_SIZE, s, &mut out) };
        (code, out)
    }

    #[test]
    fn a_loaded_gyro_compensates_and_reports_the_blobs_crc() {
        let mut state = Buffer([0; RBF_IMU_STATE_SIZE + 8]);
        let blob = blob();
        let p = state.0.as_mut_ptr().cast();
        // SAFETY: as above; the blob is followed by nothing.
        let code = unsafe { rbf_gyro_load(p, RBF_GYRO_STATE_SIZE, blob.as_ptr(), blob.len(), 1000.0) };
        assert_eq!(code, RBF_OK);
        let (code, out) = step(&mut state, &sample(25.0));
        assert_eq!((code, out.bias_dph, out.rate_comp_dph), (RBF_OK, 50.0, 50.0));
        let mut info = core::mem::MaybeUninit::<RbfModelInfo>::uninit();
        // SAFETY: a loaded state and a writable info.
        let code = unsafe { rbf_gyro_model_info(p, RBF_GYRO_STATE_SIZE, info.as_mut_ptr()) };
        // SAFETY: written by the call.
        let info = unsafe { info.assume_init() };
        let trailer = u32::from_le_bytes(blob[blob.len() - 4..].try_into().unwrap());
        assert_eq!(
            (code, info.load_status, info.crc32, info.axis_mask),
            (RBF_OK, RBF_OK, trailer, 1)
        );
        assert_eq!(
            (info.has_provenance, info.provenance_id, info.serial_len),
            (0, RBF_PROVENANCE_NONE, 0),
            "a blob without provenance: none"
        );
    }

    #[test]
    fn a_nan_thermometer_gives_the_bits_of_a_missing_reading_in_rbf_core() {
        // The C step passes NaN as `Some(NaN)` (state::readings); rbf-core
        // must judge it exactly as `None`: held, then expired, then restarted.
        let blob = blob();
        let model = rbf_core::blob::decode(&blob).unwrap().model;
        let config = CompensatorConfig::for_sample_rate(1000.0);
        let (mut nan, mut none) = (rbf_core::Compensator::new(), rbf_core::Compensator::new());
        for i in 0..12_000u32 {
            let fault = (100..11_200).contains(&i);
            let temp_c = 25.0 + i as f32 * 1e-4;
            let mut a = GyroSample::new(0.001, 100.0, Some(if fault { f32::NAN } else { temp_c }));
            let mut b = GyroSample::new(0.001, 100.0, (!fault).then_some(temp_c));
            a.temps_c[0] = Some(f32::NAN);
            b.temps_c[0] = None;
            let (x, y) = (
                nan.process(Some(&model), &config, &a),
                none.process(Some(&model), &config, &b),
            );
            assert_eq!(
                (
                    x.bias_dph.to_bits(),
                    x.rate_comp_dph.to_bits(),
                    x.temp_c.to_bits(),
                    x.flags
                ),
                (
                    y.bias_dph.to_bits(),
                    y.rate_comp_dph.to_bits(),
                    y.temp_c.to_bits(),
                    y.flags
                ),
                "sample {i}"
            );
        }
    }

    #[test]
    fn a_corrupt_blob_is_refused_with_its_code_and_the_rate_passes_through_with_flag_4() {
        let mut state = Buffer([0; RBF_IMU_STATE_SIZE + 8]);
        let mut blob = blob();
        blob[20] ^= 1;
        let p = state.0.as_mut_ptr().cast();
        // SAFETY: as above.
        let code = unsafe { rbf_gyro_load(p, RBF_GYRO_STATE_SIZE, blob.as_ptr(), blob.len(), 1000.0) };
        assert_eq!(code, RBF_ERR_BLOB_CRC_MISMATCH);
        let (code, out) = step(&mut state, &sample(25.0));
        assert_eq!((code, out.bias_dph, out.rate_comp_dph), (RBF_OK, 0.0, 100.0));
        assert_eq!(out.flags & RBF_FLAG_NO_VALID_MODEL, RBF_FLAG_NO_VALID_MODEL);
    }

    #[test]
    fn every_pointer_length_and_alignment_is_checked() {
        let mut state = Buffer([0; RBF_IMU_STATE_SIZE + 8]);
        let blob = blob();
        let p: *mut c_void = state.0.as_mut_ptr().cast();
        let load = |p: *mut c_void, len: usize, b: *const u8, rate: f32| {
            // SAFETY: every pointer is null or live for the length given.
            unsafe { rbf_gyro_load(p, len, b, blob.len(), rate) }
        };
        assert_eq!(
            load(core::ptr::null_mut(), RBF_GYRO_STATE_SIZE, blob.as_ptr(), 1000.0),
            RBF_ERR_NULL_POINTER
        );
        assert_eq!(load(p, 16, blob.as_ptr(), 1000.0), RBF_ERR_STATE_TOO_SMALL);
        // SAFETY: one byte into the buffer, which is still long enough.
        let odd = unsafe { p.cast::<u8>().add(1) }.cast();
        assert_eq!(
            load(odd, RBF_GYRO_STATE_SIZE, blob.as_ptr(), 1000.0),
            RBF_ERR_STATE_MISALIGNED
        );
        assert_eq!(
            load(p, RBF_GYRO_STATE_SIZE, blob.as_ptr(), f32::NAN),
            RBF_ERR_SAMPLE_RATE
        );
        // Not loaded (the failed load cleared the tag): refused, the rate passed through.
        let (code, out) = step(&mut state, &sample(25.0));
        assert_eq!(
            (code, out.rate_comp_dph, out.flags),
            (RBF_ERR_STATE_NOT_LOADED, 100.0, 4)
        );
        assert_eq!(
            load(p, RBF_GYRO_STATE_SIZE, core::ptr::null(), 1000.0),
            RBF_ERR_NULL_POINTER
        );
        // SAFETY: null sample and output are refused before any use.
        let code = unsafe { rbf_gyro_step(p, RBF_GYRO_STATE_SIZE, core::ptr::null(), core::ptr::null_mut()) };
        assert_eq!(code, RBF_ERR_NULL_POINTER);
        // An IMU's load of the same memory makes it no gyro state.
        // SAFETY: as above.
        let code = unsafe { rbf_imu_load(p, RBF_IMU_STATE_SIZE, blob.as_ptr(), blob.len(), 1000.0) };
        assert_eq!(code, RBF_OK);
        assert_eq!(step(&mut state, &sample(25.0)).0, RBF_ERR_STATE_NOT_LOADED);
    }
}
