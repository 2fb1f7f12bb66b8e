//! The `stm32f405-axes-shared` board image under QEMU (feature
//! `board-qemu`; `cargo xtask bench-fw` measures its stack).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::SHARED_AXIS_CENTERS;
    use rbf_core::shared_basis::SharedAxisModels;

    firmware_harness::qemu::run_axes_on_ramp::<SharedAxisModels<SHARED_AXIS_CENTERS>, SHARED_AXIS_CENTERS>()
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes-shared-qemu image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
