/* rbf_core.h: rbf-core from C (docs/c-library.md). Generated from rbf-core-c by
 * `cargo xtask c-header` (cbindgen); do not edit: CI fails when it drifts. */

#ifndef RBF_CORE_H
#define RBF_CORE_H

#include <stdint.h>
#include <stddef.h>

/*
 Bytes of memory a single gyro's state needs (`rbf_gyro_*`): the largest
 over the targets (the thumbv7em state is 24 B smaller than the host's).
 */
#define RBF_GYRO_STATE_SIZE 5336

/*
 Alignment, bytes, a single gyro's state needs.
 */
#define RBF_GYRO_STATE_ALIGN 8

/*
 Bytes of memory a three-axis IMU's state needs (`rbf_imu_*`): the
 largest over the targets (the thumbv7em state is 72 B smaller).
 */
#define RBF_IMU_STATE_SIZE 6968

/*
 Alignment, bytes, a three-axis IMU's state needs.
 */
#define RBF_IMU_STATE_ALIGN 8

/*
 Thermometers a sample carries: `temp_a` … `temp_h` of the recorded-run format.
 */
#define RBF_THERMOMETERS 8

/*
 Index of the fiber-loop thermometer (`temp_c`) among them.
 */
#define RBF_LOOP_THERMOMETER 2

/*
 Axes of an IMU: x, y, z.
 */
#define RBF_AXES 3

/*
 Bytes of the unit serial in `rbf_model_info_t` (a provenance names at most this many).
 */
#define RBF_SERIAL_CAPACITY 32

/*
 `rbf_model_info_t.provenance_id` of a blob without provenance (formats 2
 and 3, written before blobs carried one) or of a state without a model;
 `has_provenance` is then 0.
 */
#define RBF_PROVENANCE_NONE 0

/*
 Flag bit: an input lay outside the training range and was clamped.
 */
#define RBF_FLAG_INPUT_CLAMPED 1

/*
 Flag bit: a thermometer failed or read implausibly; its last good value is held.
 */
#define RBF_FLAG_TEMP_SENSOR_FAULT 2

/*
 Flag bit: no valid model or no usable temperature: the rate is passed through.
 */
#define RBF_FLAG_NO_VALID_MODEL 4

/*
 Flag bit: the features are still settling after a start or a gap.
 */
#define RBF_FLAG_WARMING_UP 8

/*
 Flag bit: the rate was NaN or beyond ±1000 °/s; passed through.
 */
#define RBF_FLAG_RATE_INVALID 16

/*
 Success.
 */
#define RBF_OK 0

/*
 A pointer argument is NULL.
 */
#define RBF_ERR_NULL_POINTER -1

/*
 The state buffer is shorter than the state size constant of its kind.
 */
#define RBF_ERR_STATE_TOO_SMALL -2

/*
 The state buffer is not aligned to the state alignment constant of its kind.
 */
#define RBF_ERR_STATE_MISALIGNED -3

/*
 The state buffer was not set up by its kind's load function (or was overwritten).
 */
#define RBF_ERR_STATE_NOT_LOADED -4

/*
 The sample rate is not a finite number above 0 Hz.
 */
#define RBF_ERR_SAMPLE_RATE -5

/*
 The blob is shorter than its header or the length its header states.
 */
#define RBF_ERR_BLOB_TRUNCATED -10

/*
 The blob does not start with `IFOG`: not a model blob (or erased flash).
 */
#define RBF_ERR_BLOB_BAD_MAGIC -11

/*
 The blob's format version is one this library cannot read.
 */
#define RBF_ERR_BLOB_UNSUPPORTED_VERSION -12

/*
 The blob names a model kind this library does not know.
 */
#define RBF_ERR_BLOB_UNKNOWN_KIND -13

/*
 The blob's CRC-32 does not match its bytes: the blob is corrupt.
 */
#define RBF_ERR_BLOB_CRC_MISMATCH -14

/*
 The blob's model has more centres or inputs than the state can hold.
 */
#define RBF_ERR_BLOB_OVER_CAPACITY -15

/*
 The blob's payload does not parse, or disagrees with its header.
 */
#define RBF_ERR_BLOB_MALFORMED -16

/*
 A multi-axis blob given to the single-axis `rbf_gyro_load`: use `rbf_imu_load`.
 */
#define RBF_ERR_BLOB_MULTI_AXIS -17

/*
 A multi-axis blob's axis mask names no axis, or one beyond z.
 */
#define RBF_ERR_BLOB_BAD_AXIS_MASK -18

/*
 A blob of another multi-axis layout than its header announces.
 */
#define RBF_ERR_BLOB_LAYOUT -19

/*
 The model's parameter arrays disagree with its shape.
 */
#define RBF_ERR_MODEL_SHAPE_MISMATCH -20

/*
 A model parameter is NaN or infinite.
 */
#define RBF_ERR_MODEL_NON_FINITE -21

/*
 A model parameter is out of its valid range (a width ≤ 0, a range with min > max, ...).
 */
#define RBF_ERR_MODEL_INVALID_PARAMETER -22

/*
 The model's output could exceed ±1e6 °/h within its input ranges.
 */
#define RBF_ERR_MODEL_OUTPUT_UNBOUNDED -23

/*
 The blob is refused for a reason newer than this list.
 */
#define RBF_ERR_BLOB_OTHER -29

/*
 One sample of a single gyro.
 */
typedef struct {
  /*
   Time since the previous sample, s (ignored on the first sample; a
   step over twice the nominal period is a gap: the features restart).
   */
  float dt_s;
  /*
   Gyro output, °/h.
   */
  float rate_dph;
  /*
   Thermometers `temp_a` … `temp_h`, °C; index `RBF_LOOP_THERMOMETER`
   (`temp_c`) is the fiber loop's. NaN: no reading (the sensor failed
   or is not fitted); a model reads only the thermometers it was fitted on.
   */
  float temps_c[RBF_THERMOMETERS];
} rbf_gyro_sample_t;

/*
 The result of one sample of one axis.
 */
typedef struct {
  /*
   Bias estimate subtracted, °/h (0 when uncompensated).
   */
  float bias_dph;
  /*
   `rate_dph − bias_dph`, °/h.
   */
  float rate_comp_dph;
  /*
   Temperature the features used (held during a fault), °C; NaN if none.
   */
  float temp_c;
  /*
   `RBF_FLAG_*` bits; 0: all is well.
   */
  uint8_t flags;
} rbf_output_t;

/*
 One sample of a three-axis IMU.
 */
typedef struct {
  /*
   Time since the previous sample, s (as in `rbf_gyro_sample_t`).
   */
  float dt_s;
  /*
   Each axis's gyro output, °/h, x first.
   */
  float rates_dph[RBF_AXES];
  /*
   The IMU's thermometers `temp_a` … `temp_h`, °C (NaN: no reading). A
   shared-basis model reads these alone.
   */
  float temps_c[RBF_THERMOMETERS];
  /*
   Each axis's fiber-loop thermometer, °C, x first (NaN: no reading):
   a model per axis reads it in place of `temps_c[RBF_LOOP_THERMOMETER]`.
   An IMU with one loop thermometer gives that value for every axis.
   */
  float loop_temps_c[RBF_AXES];
} rbf_imu_sample_t;

/*
 The result of one sample of every axis of an IMU.
 */
typedef struct {
  /*
   Per axis, x first (an axis without a model: passed through, flag 4).
   */
  rbf_output_t axes[RBF_AXES];
} rbf_imu_output_t;

/*
 What a state's model is.
 */
typedef struct {
  /*
   The status of the last load (`RBF_OK`: a model runs).
   */
  int32_t load_status;
  /*
   The loaded blob's CRC-32 (ISO-HDLC, its trailer), 0 without a model:
   what `trainer inspect` and `trainer device status` show as `crc32`.
   */
  uint32_t crc32;
  /*
   The blob's provenance id: the short model id `trainer fit` wrote
   into its provenance section, which finds the calibration record
   again (`trainer inspect` shows it as `model_id`, eight hex digits,
   as does `trainer device status` for a board). `RBF_PROVENANCE_NONE`
   (0) when `has_provenance` is 0.
   */
  uint32_t provenance_id;
  /*
   Axes with a model: bit 0 x, bit 1 y, bit 2 z (a single gyro: 1); 0 without a model.
   */
  uint8_t axis_mask;
  /*
   1 when the loaded blob carries a provenance section (formats 4 and
   5); 0 for an older blob or without a model.
   */
  uint8_t has_provenance;
  /*
   Bytes of `serial` in use: 0 when the provenance names no serial.
   */
  uint8_t serial_len;
  /*
   The unit serial the provenance names, UTF-8, zero-padded (not
   NUL-terminated when all `RBF_SERIAL_CAPACITY` bytes are used).
   */
  uint8_t serial[RBF_SERIAL_CAPACITY];
} rbf_model_info_t;

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/*
 Sets up a single gyro's state in the caller's memory and loads the model
 blob `blob[0 .. blob_len]` (format 2, one model; trailing bytes, e.g.
 the rest of a flash slot, are ignored) for a gyro sampled at
 `sample_rate_hz`. Returns `RBF_OK`, or why the blob is refused: the
 state then runs without a model (every sample passed through, flag 4).
 A state too small, misaligned or NULL, or a sample rate that is not a
 positive number, leaves no usable state (`rbf_gyro_step` refuses it).

 # Safety
 `state` points at `state_len` bytes the caller owns (at least
 `RBF_GYRO_STATE_SIZE`, aligned to `RBF_GYRO_STATE_ALIGN`), `blob` at
 `blob_len` readable bytes; neither is used elsewhere during the call.
 */
int32_t rbf_gyro_load(void *state,
                      size_t state_len,
                      const uint8_t *blob,
                      size_t blob_len,
                      float sample_rate_hz);

/*
 Sets up a three-axis IMU's state and loads a blob of any kind: one model
 per axis or a shared basis (format 3), or a single-axis model (format 2,
 for axis x). As `rbf_gyro_load` otherwise.

 # Safety
 As `rbf_gyro_load`, with `RBF_IMU_STATE_SIZE` and `RBF_IMU_STATE_ALIGN`.
 */
int32_t rbf_imu_load(void *state,
                     size_t state_len,
                     const uint8_t *blob,
                     size_t blob_len,
                     float sample_rate_hz);

/*
 Compensates one sample of a single gyro: `*out` gets the bias, the
 compensated rate and the flags. Returns `RBF_OK`; a NULL pointer, or a
 state that `rbf_gyro_load` did not set up, returns its code, and `*out`
 (if there is one) then holds the rate passed through with flag 4.
 Takes at most a few thousand instructions, none waiting on anything
 (figures: docs/benchmarks.md, `cargo xtask bench-fw`).

 # Safety
 `state` as for `rbf_gyro_load`; `sample` points at a readable
 `rbf_gyro_sample_t`, `out` at a writable `rbf_output_t` (any alignment).
 */
int32_t rbf_gyro_step(void *state,
                      size_t state_len,
                      const rbf_gyro_sample_t *sample,
                      rbf_output_t *out);

/*
 Compensates one sample of every axis of a three-axis IMU: `out->axes[a]`
 for axis a (x first). Returns as `rbf_gyro_step` does (every axis
 passed through with flag 4 when the state cannot run).

 # Safety
 `state` as for `rbf_imu_load`; `sample` points at a readable
 `rbf_imu_sample_t`, `out` at a writable `rbf_imu_output_t` (any alignment).
 */
int32_t rbf_imu_step(void *state,
                     size_t state_len,
                     const rbf_imu_sample_t *sample,
                     rbf_imu_output_t *out);

/*
 What a single gyro's state runs: `*out` gets the model's CRC-32, axes
 and provenance id and serial (0 and none without a model). Returns
 `RBF_OK`, or the code of a NULL pointer or a state not set up by a load.

 # Safety
 `state` as for `rbf_gyro_load`; `out` points at a writable `rbf_model_info_t`.
 */
int32_t rbf_gyro_model_info(void *state, size_t state_len, rbf_model_info_t *out);

/*
 `rbf_gyro_model_info` of a three-axis IMU's state.

 # Safety
 `state` as for `rbf_imu_load`; `out` points at a writable `rbf_model_info_t`.
 */
int32_t rbf_imu_model_info(void *state, size_t state_len, rbf_model_info_t *out);

/*
 The meaning of status code `status` in words (English, ASCII), as a
 NUL-terminated string that lives as long as the program; an unknown code
 gives "unknown status code".
 */
const char *rbf_status_message(int32_t status);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* RBF_CORE_H */
