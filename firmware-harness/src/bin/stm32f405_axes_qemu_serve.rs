//! The `stm32f405-axes-qemu` image serving until stopped (`cargo xtask
//! qemu-board --axes 3 --pty`): as `stm32f405-qemu-serve`, for three axes
//! (a three-axis run's `rate_<axis>_dph` and `temp_<axis>_c`).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::AXIS_CENTERS;
    use firmware::frontend::FrontEnd;
    use firmware_harness::qemu::{self, Emulation};
    use firmware_harness::replay::EmulatedFrontEnd;
    use rbf_core::blob::axes::AxisModels;

    let (board, source, readings) = qemu::serving::<3>();
    let thermometers = qemu::coil_thermometers(&readings);
    let front_ends = [0, 1, 2].map(|axis| FrontEnd::new(EmulatedFrontEnd::new(&readings[axis])));
    board.run::<AxisModels<AXIS_CENTERS>, _, _, _, _, _>(thermometers, front_ends, Emulation::new(&readings, source))
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes-qemu-serve image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
