//! Every input that fuzzing ever found breaking a target stays fixed: the
//! files under tests/fuzz-regressions/<target>/ replay through the same
//! checks the fuzz targets run (e2e_tests::robustness).

use e2e_tests::robustness::check;
use e2e_tests::workspace_root;
use xtask::fuzz::TARGETS;

#[test]
fn every_past_fuzz_finding_is_handled() {
    let mut replayed = 0;
    for target in TARGETS {
        let check = check(target).expect("a check per target");
        let dir = workspace_root().join("tests/fuzz-regressions").join(target);
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries {
            let path = entry.expect("readable directory").path();
            let data = std::fs::read(&path).expect("readable regression input");
            let outcome = std::panic::catch_unwind(|| check(&data));
            assert!(outcome.is_ok(), "{target}: {} breaks the target again", path.display());
            replayed += 1;
        }
    }
    assert!(replayed >= 2, "the regression corpus went missing ({replayed} files)");
}

#[test]
fn the_first_findings_are_refused_as_unbounded_models() {
    // Both blobs fuzzing found on its first run: valid CRC and shape, but
    // weights so large that the bias overflowed to ±∞ at the range limits.
    let dir = workspace_root().join("tests/fuzz-regressions/blob_decode");
    for name in [
        "crash-9e3b25ef7669c723dab8ac7298cf760b46fd61d1",
        "crash-a69ec42a74c582a366bfe25427520ba019abc2e0",
    ] {
        let data = std::fs::read(dir.join(name)).unwrap();
        let blob = e2e_tests::robustness::sealed_blob(&data).expect("long enough");
        assert_eq!(
            rbf_core::blob::decode(&blob).map(|_| ()),
            Err(rbf_core::blob::DecodeError::Model(
                rbf_core::ModelError::OutputUnbounded
            ))
        );
    }
}

#[test]
fn a_lag_bank_with_a_nan_in_an_unused_time_constant_is_refused() {
    // Found once the default (lag-bank) model seeded the fuzzer: the NaN sat
    // in a slot no filter uses, so the model decoded but did not equal itself
    // after a round trip. Unused slots must be 0.
    let path = workspace_root().join("tests/fuzz-regressions/blob_decode/lag-bank-nan-in-an-unused-time-constant.bin");
    let blob = e2e_tests::robustness::sealed_blob(&std::fs::read(path).unwrap()).expect("long enough");
    assert_eq!(
        rbf_core::blob::decode(&blob).map(|_| ()),
        Err(rbf_core::blob::DecodeError::Model(
            rbf_core::ModelError::InvalidParameter
        ))
    );
}
