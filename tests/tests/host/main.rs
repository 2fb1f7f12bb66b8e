//! The end-to-end tests that run on the host alone (no QEMU, no PyPI): one
//! test binary for every module below, so that the trainer, the firmware
//! library and their dependencies are linked once rather than once per file
//! (`cargo test --test host MODULE::` runs one module). The QEMU, device and
//! allantools tests stay binaries of their own: `cargo xtask ci` names them.

mod approximation;
mod firmware_faults;
mod firmware_mock_hal;
mod firmware_replay;
mod fuzz_regressions;
mod pipeline;
mod probe_flash;
