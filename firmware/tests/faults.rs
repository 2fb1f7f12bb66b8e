//! Fault injection on the host: the campaigns the QEMU fault board runs
//! (firmware::fault_injection), on a fitted model, with their pass criteria.

use e2e_tests::fixtures::model_and_faulty_slice;
use firmware::emulated_flash::EmulatedFlash;
use firmware::fault_injection::{
    EMULATED_LAYOUT, FaultKind, ModelFlash, bit_flip_campaign, command_campaign, power_cut_campaign, sensor_campaign,
};
use firmware::model_store::{ModelStore, SlotState};
use rbf_core::Model;
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
