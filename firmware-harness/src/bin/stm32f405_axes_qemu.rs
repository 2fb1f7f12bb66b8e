//! The `stm32f405-axes` board image under QEMU (feature `board-qemu`;
//! `cargo xtask bench-fw` measures its stack): three coils on the built-in
//! ramp, each half a degree warmer than the last.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::AXIS_CENTERS;
    use rbf_core::blob::axes::AxisModels;

    firmware_harness::qemu::run_axes_on_ramp::<AxisModels<AXIS_CENTERS>, AXIS_CENTERS>()
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes-qemu image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
