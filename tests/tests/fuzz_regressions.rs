//! Every input that fuzzing ever found breaking a target stays fixed: the
//! files under tests/fuzz-regressions/<target>/ replay through the same
//! checks the fuzz targets run (e2e_tests::robustness).

use e2e_tests::robustness::{TARGETS, check};
use e2e_tests::workspace_root;

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
    for entry in std::fs::read_dir(dir).expect("regression corpus") {
        let data = std::fs::read(entry.unwrap().path()).unwrap();
        let blob = e2e_tests::robustness::sealed_blob(&data).expect("long enough");
        assert_eq!(
            rbf_core::blob::decode(&blob).map(|_| ()),
            Err(rbf_core::blob::DecodeError::Model(
                rbf_core::ModelError::OutputUnbounded
            ))
        );
    }
}
