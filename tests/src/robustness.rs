//! The invariants the fuzz targets (fuzz/fuzz_targets/) check on arbitrary
//! bytes, shared with the regression test that replays every input fuzzing
//! ever broke (`tests/fuzz-regressions/<target>/`, `tests/tests/host/fuzz_regressions.rs`).
//! Each function panics when an invariant fails, which libFuzzer reports.

use std::io::Cursor;
use std::path::Path;

use gyro_wire::frame::{self, MAX_FRAME_LEN};
use rbf_core::blob::{self, FORMAT_VERSION, HEADER_LEN, MAGIC, MAX_BLOB_LEN, axes};
use rbf_core::{Compensator, CompensatorConfig, GyroSample};
use trainer::reading::run::RunReader;
use trainer::reading::run::rows::RunError;
use trainer::reading::run::samples::Run;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// `data` as header fields (kind, inputs, centres, reserved) and payload,
/// given magic, version, length and a valid CRC, so that fuzzing reaches the
/// payload decoder and the model checks behind the CRC.
pub fn sealed_blob(data: &[u8]) -> Option<Vec<u8>> {
    let (fields, payload) = data.split_at_checked(6)?;
    let mut blob = Vec::with_capacity(HEADER_LEN + payload.len() + 4);
    blob.extend_from_slice(&MAGIC);
    blob.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    blob.extend_from_slice(fields);
    blob.extend_from_slice(&u32::try_from(payload.len()).ok()?.to_le_bytes());
    blob.extend_from_slice(payload);
    blob.extend_from_slice(&CRC32.checksum(&blob).to_le_bytes());
    Some(blob)
}

/// Model blobs arrive from files and over the UART: `data`, raw and sealed,
/// must decode to a model or a reason; a decoded model must survive encode →
/// decode unchanged and give a finite bias for any temperature sequence.
pub fn check_blob(data: &[u8]) {
    check_one_blob(data);
    check_axes_blob(data);
    if let Some(blob) = sealed_blob(data) {
        check_one_blob(&blob);
    }
    if let Some(blob) = sealed_axes_blob(data) {
        check_axes_blob(&blob);
        check_shared_blob(&blob);
    }
    check_shared_blob(data);
    if let Some(blob) = sealed_shared_blob(data) {
        check_shared_blob(&blob);
    }
}

/// `data` as a shared-basis blob: its first byte the axis mask, the rest
/// the payload, given magic, version 3, the shared-basis flag, length and a
/// valid CRC.
pub fn sealed_shared_blob(data: &[u8]) -> Option<Vec<u8>> {
    let mut blob = sealed_axes_blob(data)?;
    blob[7] = axes::SHARED_BASIS_FLAG;
    let n = blob.len() - 4;
    let crc = CRC32.checksum(&blob[..n]);
    blob[n..].copy_from_slice(&crc.to_le_bytes());
    Some(blob)
}

/// A decoded shared-basis blob re-encodes to models that decode the same,
/// at the three-axis board's capacity too, and every axis gives a finite
/// bias from one compensator.
fn check_shared_blob(data: &[u8]) {
    use rbf_core::blob::shared_layout::{decode_shared_into, encode_shared};
    use rbf_core::shared_basis::SharedAxisModels;
    let mut models = Box::new(SharedAxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    let Ok(len) = decode_shared_into(&mut models, data) else {
        return;
    };
    assert!(len <= data.len());
    let mut small = Box::new(SharedAxisModels::<{ rbf_core::MAX_AXIS_CENTERS }>::EMPTY);
    let _ = decode_shared_into(&mut small, data);
    let mut buf = [0u8; MAX_BLOB_LEN];
    let len = encode_shared(&models, &mut buf).expect("a decoded blob encodes");
    let mut again = Box::new(SharedAxisModels::EMPTY);
    decode_shared_into(&mut again, &buf[..len]).expect("a re-encoded blob decodes");
    assert_eq!(*again, *models);
    let config = CompensatorConfig::for_sample_rate(1.0);
    let mut compensator = Compensator::new();
    for temp_c in [-1e30, f32::NAN, 25.0, 1e30].into_iter().map(Some).chain([None]) {
        let mut temps = [None; rbf_core::features::THERMOMETERS];
        temps[rbf_core::features::LOOP_THERMOMETER] = temp_c;
        let out = compensator.process_shared(Some(&*models), &config, 1.0, &temps, &[1.0; 3]);
        assert!(
            out.iter()
                .all(|o| o.bias_dph.is_finite() && o.rate_comp_dph.is_finite())
        );
    }
}

/// `data` as a multi-axis blob: its first byte the axis mask, the rest the
/// payload, given magic, version 3, length and a valid CRC.
pub fn sealed_axes_blob(data: &[u8]) -> Option<Vec<u8>> {
    let (&mask, payload) = data.split_first()?;
    let mut blob = Vec::with_capacity(HEADER_LEN + payload.len() + 4);
    blob.extend_from_slice(&MAGIC);
    blob.extend_from_slice(&axes::AXES_FORMAT_VERSION.to_le_bytes());
    blob.extend_from_slice(&[mask, 0, 0, 0, 0, 0]);
    blob.extend_from_slice(&u32::try_from(payload.len()).ok()?.to_le_bytes());
    blob.extend_from_slice(payload);
    blob.extend_from_slice(&CRC32.checksum(&blob).to_le_bytes());
    Some(blob)
}

/// A decoded multi-axis blob re-encodes to models that decode the same, at
/// the firmware's smaller capacity too, and every axis gives a finite bias.
fn check_axes_blob(data: &[u8]) {
    let mut models = Box::new(axes::AxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    let Ok(len) = axes::decode_axes_into(&mut models, data) else {
        return;
    };
    assert!(len <= data.len());
    let mut small = Box::new(axes::AxisModels::<16>::EMPTY);
    let _ = axes::decode_axes_into(&mut small, data);
    let mut buf = [0u8; MAX_BLOB_LEN];
    let len = axes::encode_axes(&models, &mut buf).expect("a decoded blob encodes");
    let mut again = Box::new(axes::AxisModels::EMPTY);
    axes::decode_axes_into(&mut again, &buf[..len]).expect("a re-encoded blob decodes");
    assert_eq!(*again, *models);
    let config = CompensatorConfig::for_sample_rate(1.0);
    for axis in models.axes() {
        let mut compensator = Compensator::new();
        for temp_c in [-1e30, f32::NAN, 25.0, 1e30].into_iter().map(Some).chain([None]) {
            let out = compensator.process_with(models.get(axis), &config, &GyroSample::new(1.0, 1.0, temp_c));
            assert!(out.bias_dph.is_finite() && out.rate_comp_dph.is_finite());
        }
    }
}

fn check_one_blob(data: &[u8]) {
    let Ok(decoded) = blob::decode(data) else { return };
    assert!(decoded.len <= data.len());
    let mut buf = [0u8; MAX_BLOB_LEN];
    let len = blob::encode(&decoded.model, &mut buf).expect("a decoded model encodes");
    let again = blob::decode(&buf[..len]).expect("a re-encoded model decodes");
    assert_eq!(again.model, decoded.model);

    let config = CompensatorConfig::for_sample_rate(1.0);
    let mut compensator = Compensator::new();
    let temps = [-1e30, f32::NAN, 25.0, 1e30, -55.0, 150.0, 0.0, -40.0, 60.0];
    for temp_c in temps.into_iter().map(Some).chain([None]) {
        for dt_s in [1.0, f32::INFINITY, 1.0, 0.5] {
            let sample = GyroSample::new(dt_s, 1.0, temp_c);
            let out = compensator.process(Some(&decoded.model), &config, &sample);
            assert!(out.bias_dph.is_finite(), "bias {} for T {temp_c:?}", out.bias_dph);
            assert!(out.rate_comp_dph.is_finite());
        }
    }
}

/// Output frames are read back from UART captures with lost and damaged
/// bytes: `data` must decode to a frame or an error, and a decoded frame must
/// survive encode → decode bit for bit.
pub fn check_frame(data: &[u8]) {
    let mut bytes = data.to_vec();
    let Ok(decoded) = frame::decode(&mut bytes) else { return };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = frame::encode(&decoded, &mut buf).expect("every frame fits MAX_FRAME_LEN");
    let again = frame::decode(&mut buf[..len]).expect("a re-encoded frame decodes");
    assert_eq!((again.seq, again.flags), (decoded.seq, decoded.flags));
    let bits = |f: &frame::OutputFrame| [f.rate_dph, f.bias_dph, f.rate_comp_dph, f.temp_c].map(f32::to_bits);
    assert_eq!(bits(&again), bits(&decoded));
}

/// Recorded runs come from other tools and people: `data` must be read as a
/// run or refused with an error naming the file and line, streaming (as
/// `trainer compensate` reads) and whole (as `trainer fit` reads).
pub fn check_run(data: &[u8]) {
    let path = Path::new("fuzz.csv");
    let named = |e: &RunError| {
        let message = e.to_string();
        assert!(message.starts_with("fuzz.csv:"), "{message}");
        if let RunError::Format { line, .. } = e {
            assert!(*line >= 1);
        }
    };
    match RunReader::from_reader(path, Cursor::new(data.to_vec())) {
        Err(e) => named(&e),
        Ok(mut reader) => {
            let mut last_line = 0;
            loop {
                match reader.next_row() {
                    Ok(Some(raw)) => {
                        assert!(raw.line > last_line);
                        last_line = raw.line;
                        assert!(raw.row.time_s.is_finite() && raw.row.rate_dph.is_finite());
                    }
                    Ok(None) => break,
                    Err(e) => {
                        named(&e);
                        break;
                    }
                }
            }
        }
    }
    match RunReader::from_reader(path, Cursor::new(data.to_vec())).and_then(Run::read) {
        Err(e) => named(&e),
        Ok(run) => {
            assert!(run.len() >= 2);
            assert!(run.nominal_period_s.is_finite() && run.nominal_period_s > 0.0);
            assert_eq!(run.samples().count(), run.len());
        }
    }
}

/// The check of fuzz target `target`.
pub fn check(target: &str) -> Option<fn(&[u8])> {
    match target {
        "blob_decode" => Some(check_blob),
        "run_reader" => Some(check_run),
        "frame_decode" => Some(check_frame),
        _ => None,
    }
}
