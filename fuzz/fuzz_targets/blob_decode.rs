//! Fuzz target `blob_decode`: the invariants of [`e2e_tests::robustness::check_blob`]
//! on arbitrary bytes (regressions replay in tests/tests/host/fuzz_regressions.rs).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| e2e_tests::robustness::check_blob(data));
