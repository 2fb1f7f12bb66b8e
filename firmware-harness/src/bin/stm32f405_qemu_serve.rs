//! The `stm32f405-qemu` image serving until stopped (`cargo xtask
//! qemu-board --pty`, the host's `trainer device` tests): TIM2 taken at
//! QEMU's 1 GHz timer clock (no -icount: samples at 1 kHz of real time),
//! the front end emulated too, both answering from `run.csv` over
//! semihosting or the built-in ramp (docs/firmware.md, "The board under QEMU").
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::frontend::FrontEnd;
    use firmware_harness::qemu::{self, Emulation};
    use firmware_harness::replay::EmulatedFrontEnd;
    use rbf_core::Model;

    let (board, source, readings) = qemu::serving::<1>();
    let thermometer = qemu::thermometer(&readings[0]);
    let front_end = FrontEnd::new(EmulatedFrontEnd::new(&readings[0]));
    board.run::<Model, _, _, _, _, _>(thermometer, front_end, Emulation::new(&readings, source))
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-qemu-serve image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
