//! Fault injection on the host: the campaigns the QEMU fault board runs
//! (firmware_harness::fault_injection), on a fitted model, with their pass criteria.

use e2e_tests::fixtures::model_and_faulty_slice;
use firmware::model_store::{InstallError, ModelStore, SlotState};
use firmware_harness::emulated_flash::EmulatedFlash;
use firmware_harness::fault_injection::{
    EMULATED_LAYOUT, FaultKind, ModelFlash, axis_thermometer_campaign, bit_flip_campaign, command_campaign,
    power_cut_campaign, sensor_campaign,
};
use rbf_core::Model;
use rbf_core::axis::Axis;
use rbf_core::blob::axes::{AxisModels, decode_axes_into, encode_axes};
use rbf_core::blob::{self, MAX_BLOB_LEN};

fn encode(model: &Model) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let n = blob::encode(model, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// (fitted RBF model, its blob, a cubic model's blob).
fn models() -> (Model, Vec<u8>, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = model_and_faulty_slice(dir.path());
    let cubic = e2e_tests::fixtures::cubic_model();
    let blob = encode(&model);
    (model, blob, encode(&cubic))
}

#[test]
fn sensor_and_bus_faults_lose_no_sample_and_are_flagged() {
    let (model, _, _) = models();
    let r = sensor_campaign(Some(model), 20_000, 0x1234_5678);
    assert!(r.faults() > 300, "{r:?}");
    for (kind, n) in FaultKind::ALL.iter().zip(r.episodes) {
        assert!(n > 10, "{kind:?} injected {n} times");
    }
    assert_eq!(r.frames, 20_000, "one frame per sample");
    assert_eq!(r.samples_lost, 0, "{r:?}");
    assert_eq!(r.missing_flags, 0, "every fault flagged: {r:?}");
    assert_eq!(r.non_finite, 0, "{r:?}");
}

#[test]
fn every_bit_flip_of_the_model_blob_is_refused() {
    let (_, blob, cubic) = models();
    for b in [blob, cubic] {
        let (flips, accepted) = bit_flip_campaign(&b);
        assert_eq!(flips as usize, b.len() * 8);
        assert_eq!(accepted, 0);
    }
}

#[test]
fn a_reset_at_any_step_of_an_update_leaves_a_valid_model() {
    let (_, old, new) = models();
    let r = power_cut_campaign(&old, &new);
    // Erase of 5 pages, the blob's words, the 4 words of the commit record.
    assert_eq!(
        r.operations_per_install as usize,
        5 + new.len().div_ceil(4) + 4,
        "{r:?}"
    );
    assert_eq!(r.resets, 2 * (r.operations_per_install + 1), "{r:?}");
    assert_eq!(r.booted_invalid, 0, "{r:?}");
    assert_eq!(r.retry_failures, 0, "{r:?}");
    assert_eq!(r.booted_old + r.booted_new, r.resets);
    assert!(r.booted_old > 0 && r.booted_new >= 2, "{r:?}");
}

#[test]
fn uart_commands_are_answered_and_the_loop_switches_to_the_new_model() {
    let (_, old, new) = models();
    let r = command_campaign(&old, &new);
    assert_eq!((r.commands, r.expected_replies), (5, 5), "{r:?}");
    assert!(r.switched, "{r:?}");
}

#[test]
fn the_store_alternates_slots_and_boots_the_newest_commit() {
    let (model, old, new) = models();
    let mut store = ModelStore::open(ModelFlash::new(), EMULATED_LAYOUT);
    assert_eq!(store.active_slot(), None);
    assert_eq!(
        store.load(),
        Err(blob::DecodeError::BadMagic),
        "erased flash: the reason, no panic"
    );
    store.install(&old).unwrap();
    assert_eq!(store.slot_states()[0], SlotState::Committed(1));
    store.install(&new).unwrap();
    assert_eq!(store.slot_states()[1], SlotState::Committed(2));
    store.install(&old).unwrap();
    assert_eq!(store.slot_states(), [SlotState::Committed(3), SlotState::Committed(2)]);
    // Reboot: the newest commit runs.
    let mut flash = store.into_flash();
    let mut store = ModelStore::open(flash.clone(), EMULATED_LAYOUT);
    assert_eq!((store.active_slot(), store.load()), (Some(0), Ok(model)));
    // Corrupt slot A's blob: B's older commit runs.
    flash.contents_mut()[20] ^= 0x01;
    let store = ModelStore::open(flash, EMULATED_LAYOUT);
    assert_eq!(store.active_slot(), Some(1));
    assert!(matches!(store.slot_states()[0], SlotState::Invalid(_)));
}

#[test]
fn a_refused_blob_leaves_the_flash_untouched() {
    let (_, old, _) = models();
    let mut store = ModelStore::open(EmulatedFlash::<10240>::new(), EMULATED_LAYOUT);
    store.install(&old).unwrap();
    let before = store.into_flash();
    let mut store = ModelStore::open(before.clone(), EMULATED_LAYOUT);
    let mut bad = old.clone();
    bad[30] ^= 0x80;
    assert!(store.install(&bad).is_err());
    assert_eq!(store.into_flash().contents(), before.contents());
}

/// Three axes as the multi-axis board holds them: x the fitted model, y the
/// cubic, z the fitted model again; and their format-3 blob.
fn axis_models() -> (Box<AxisModels<{ firmware::AXIS_CENTERS }>>, Vec<u8>) {
    let (model, _, _) = models();
    let mut all = Box::new(AxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    all.insert(Axis::X, model.clone());
    all.insert(Axis::Y, e2e_tests::fixtures::cubic_model());
    all.insert(Axis::Z, model);
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let n = encode_axes(&all, &mut buf).unwrap();
    buf.truncate(n);
    let mut board = Box::new(AxisModels::EMPTY);
    decode_axes_into(&mut board, &buf).unwrap();
    (board, buf)
}

#[test]
fn one_axis_thermometer_failing_flags_that_axis_while_the_others_keep_compensating() {
    let (models, _) = axis_models();
    for (failing, seed) in [(Axis::Y, 0x1234_5678), (Axis::X, 0x0BAD_CAFE), (Axis::Z, 7)] {
        let r = axis_thermometer_campaign(Some(&*models), failing, 20_000, seed);
        assert_eq!((r.frames, r.samples_lost), (20_000, 0), "{failing:?}: {r:?}");
        assert!(r.faulty_samples > 1_000, "{failing:?}: {r:?}");
        assert_eq!(
            r.missing_flags, 0,
            "{failing:?}: every failed read flagged on its axis: {r:?}"
        );
        assert!(
            r.failing_uncompensated > 0,
            "{failing:?}: outages past the hold stop that axis: {r:?}"
        );
        assert_eq!(r.healthy_disturbed, 0, "{failing:?}: the other axes run on: {r:?}");
        for axis in Axis::ALL {
            let faults = r.temp_read_faults_per_axis[axis.index()];
            if axis == failing {
                assert_eq!(faults, r.faulty_samples, "{r:?}");
            } else {
                assert_eq!(faults, 0, "{axis:?}: {r:?}");
            }
        }
    }
}

#[test]
fn the_store_and_the_uart_update_carry_either_blob_format_and_refuse_what_the_board_cannot_hold() {
    use firmware::update::{UpdateStatus, execute_into};
    use gyro_wire::command::CMD_INSTALL_MODEL;
    let (board_models, axes_blob) = axis_models();
    let (_, single_blob, _) = models();
    let mut running = Box::new(AxisModels::<{ firmware::AXIS_CENTERS }>::EMPTY);
    let mut store = ModelStore::open_with(ModelFlash::new(), EMULATED_LAYOUT, &mut *running);
    assert_eq!(store.active_slot(), None);

    // A format-3 blob through the UART command path: installed and running.
    let mut payload = vec![CMD_INSTALL_MODEL];
    payload.extend_from_slice(&axes_blob);
    assert_eq!(
        execute_into(&mut store, &payload, &mut *running),
        UpdateStatus::Installed
    );
    assert_eq!(*running, *board_models);
    assert_eq!(store.slot_states()[0], SlotState::Committed(1));

    // A single-axis blob runs on the multi-axis board as axis x alone.
    let mut payload = vec![CMD_INSTALL_MODEL];
    payload.extend_from_slice(&single_blob);
    let mut x_only = Box::new(AxisModels::<{ firmware::AXIS_CENTERS }>::EMPTY);
    let mut single_only = ModelStore::open_with(store.into_flash(), EMULATED_LAYOUT, &mut *x_only);
    assert_eq!(
        execute_into(&mut single_only, &payload, &mut *x_only),
        UpdateStatus::Installed
    );
    assert_eq!(single_only.slot_states()[1], SlotState::Committed(2));
    assert_eq!(x_only.mask(), 0b001);
    assert_eq!(
        x_only.get(Axis::X),
        board_models.get(Axis::X),
        "the fitted model, as axis x"
    );
    // Back to the three-axis blob (the newest commit runs).
    let mut payload = vec![CMD_INSTALL_MODEL];
    payload.extend_from_slice(&axes_blob);
    assert_eq!(
        execute_into(&mut single_only, &payload, &mut *running),
        UpdateStatus::Installed
    );
    assert_eq!(single_only.slot_states()[0], SlotState::Committed(3));
    let before = single_only.into_flash();
    let mut store = ModelStore::open_with(before.clone(), EMULATED_LAYOUT, &mut *running);
    store.load_into(&mut *running).unwrap();
    assert_eq!(*running, *board_models);
    // A single-axis firmware refuses the multi-axis blob with the reason.
    let mut single_model: Model = Model::EMPTY;
    assert_eq!(
        execute_into(&mut store, &payload, &mut single_model),
        UpdateStatus::Refused
    );

    // An axis with more centres than the board holds: refused, flash untouched.
    let mut big = Box::new(AxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    big.insert(Axis::X, wide_model(firmware::AXIS_CENTERS + 1));
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let n = encode_axes(&big, &mut buf).unwrap();
    let mut small = Box::new(AxisModels::<{ firmware::AXIS_CENTERS }>::EMPTY);
    assert!(matches!(
        store.install_into(&buf[..n], &mut *small),
        Err(InstallError::Refused(blob::DecodeError::ShapeOverCapacity { .. }))
    ));
    let after = store.into_flash();
    assert_eq!(
        after.contents(),
        before.contents(),
        "refused blobs leave the flash untouched"
    );

    // Reboot: the multi-axis slot is found and loaded; a single-axis reader refuses it with the reason.
    let mut store = ModelStore::open_with(after, EMULATED_LAYOUT, &mut *running);
    store.load_into(&mut *running).unwrap();
    assert_eq!(*running, *board_models);
    assert_eq!(store.load(), Err(blob::DecodeError::MultiAxis));
}

/// A valid RBF model over (T, ΔT, T×ΔT) with `centers` centres.
fn wide_model(centers: usize) -> Model {
    use rbf_core::model::{ModelBody, ModelInfo};
    use rbf_core::rbf::{RbfNetwork, RbfParams};
    use rbf_core::{FeatureConfig, FeatureSet};
    let c: Vec<f32> = (0..centers * 3).map(|i| (i as f32 * 0.37).sin()).collect();
    let net = RbfNetwork::new(&RbfParams {
        offset: &[25.0, 0.0, 0.0],
        scale: &[10.0, 0.5, 12.0],
        kernel_inputs: 3,
        centers: &c,
        widths: &vec![1.0; centers],
        weights: &vec![0.01; centers],
        linear: &[0.0; 3],
        constant: 0.0,
    })
    .unwrap();
    Model::new(
        FeatureConfig::single(FeatureSet::TempRateProduct, 60.0),
        &[(10.0, 40.0), (-1.5, 1.5), (-60.0, 60.0)],
        ModelBody::Rbf(net),
        ModelInfo::default(),
    )
    .unwrap()
}

/// The shared-basis model (16-centre basis, every axis) as the
/// shared-basis board holds it, and its blob.
fn shared_models() -> (
    Box<rbf_core::shared_basis::SharedAxisModels<{ firmware::SHARED_AXIS_CENTERS }>>,
    Vec<u8>,
) {
    let dir = tempfile::TempDir::new().unwrap();
    let (blob_path, _) = e2e_tests::fixtures::shared_blob_and_slice(dir.path());
    let blob = std::fs::read(blob_path).unwrap();
    let mut board = Box::new(rbf_core::shared_basis::SharedAxisModels::EMPTY);
    assert_eq!(
        rbf_core::blob::shared_layout::decode_shared_into(&mut *board, &blob),
        Ok(blob.len())
    );
    (board, blob)
}

#[test]
fn under_a_shared_basis_the_one_thermometer_failing_flags_every_axis_and_the_others_go_unread() {
    let (models, _) = shared_models();
    // x's thermometer is the one every axis reads: every axis fails with it.
    let r = axis_thermometer_campaign(Some(&*models), Axis::X, 20_000, 0x1234_5678);
    assert_eq!((r.frames, r.samples_lost), (20_000, 0), "{r:?}");
    assert!(r.faulty_samples > 1_000, "{r:?}");
    assert_eq!(r.missing_flags, 0, "every failed read flagged on every axis: {r:?}");
    assert!(
        r.failing_uncompensated > 0,
        "outages past the hold stop every axis: {r:?}"
    );
    assert_eq!(r.healthy_disturbed, 0, "{r:?}");
    assert_eq!(r.temp_read_faults_per_axis, [r.faulty_samples; 3], "{r:?}");
    // y's or z's coil thermometer is not read by a shared-basis model: nothing changes.
    for failing in [Axis::Y, Axis::Z] {
        let r = axis_thermometer_campaign(Some(&*models), failing, 20_000, 7);
        assert!(r.faulty_samples > 1_000, "{failing:?}: {r:?}");
        assert_eq!((r.frames, r.samples_lost), (20_000, 0), "{failing:?}: {r:?}");
        assert_eq!(r.healthy_disturbed, 0, "{failing:?}: {r:?}");
        assert_eq!(r.temp_read_faults_per_axis, [0; 3], "{failing:?}: {r:?}");
    }
}

#[test]
fn the_store_and_the_uart_update_carry_a_shared_basis_blob_and_refuse_the_other_layouts() {
    use firmware::update::{UpdateStatus, execute_into};
    use gyro_wire::command::CMD_INSTALL_MODEL;
    use rbf_core::shared_basis::SharedAxisModels;
    let (board_models, shared_blob) = shared_models();
    let (_, axes_blob) = axis_models();
    let (_, single_blob, _) = models();
    let mut running = Box::new(SharedAxisModels::<{ firmware::SHARED_AXIS_CENTERS }>::EMPTY);
    let mut store = ModelStore::open_with(ModelFlash::new(), EMULATED_LAYOUT, &mut *running);
    assert_eq!(store.active_slot(), None);

    // The shared-basis blob through the UART command path: installed and running.
    let mut payload = vec![CMD_INSTALL_MODEL];
    payload.extend_from_slice(&shared_blob);
    assert_eq!(
        execute_into(&mut store, &payload, &mut *running),
        UpdateStatus::Installed
    );
    assert_eq!(*running, *board_models);
    assert_eq!(store.slot_states()[0], SlotState::Committed(1));
    let before = store.into_flash();

    // A model per axis or a single-axis blob: refused with the reason, flash untouched.
    let mut store = ModelStore::open_with(before.clone(), EMULATED_LAYOUT, &mut *running);
    for other in [&axes_blob, &single_blob] {
        assert!(matches!(
            store.install_into(other, &mut *running),
            Err(InstallError::Refused(
                blob::DecodeError::NotSharedBasis | blob::DecodeError::UnsupportedVersion(_)
            ))
        ));
        let mut payload = vec![CMD_INSTALL_MODEL];
        payload.extend_from_slice(other);
        assert_eq!(execute_into(&mut store, &payload, &mut *running), UpdateStatus::Refused);
        assert_eq!(*running, *board_models, "the running model stays");
    }
    // The per-axis board refuses the shared-basis blob with its reason.
    let mut per_axis = Box::new(AxisModels::<{ firmware::AXIS_CENTERS }>::EMPTY);
    assert!(matches!(
        store.install_into(&shared_blob, &mut *per_axis),
        Err(InstallError::Refused(blob::DecodeError::SharedBasis))
    ));
    let after = store.into_flash();
    assert_eq!(
        after.contents(),
        before.contents(),
        "refused blobs leave the flash untouched"
    );

    // Reboot: the shared-basis slot is found and loaded.
    let mut fresh = Box::new(SharedAxisModels::<{ firmware::SHARED_AXIS_CENTERS }>::EMPTY);
    let mut store = ModelStore::open_with(after, EMULATED_LAYOUT, &mut *fresh);
    store.load_into(&mut *fresh).unwrap();
    assert_eq!(*fresh, *board_models);
}
