//! The `stm32f405` board image under QEMU's netduinoplus2 (feature
//! `board-qemu`), whose stack peak `cargo xtask bench-fw` measures: the
//! board's own code with what QEMU lacks swapped (`firmware::board::qemu`:
//! the reset clocks, no I2C) or emulated (`firmware_harness::qemu`: the
//! TMP117 on a built-in ramp, TIM3 as data-ready, the model slots in RAM);
//! it exits after its samples and an update.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::board;
    use firmware_harness::qemu::{self, Emulation};
    use rbf_core::Model;

    let (board, wiring) = qemu::setup();
    let readings = qemu::ramp::<1>();
    let thermometer = qemu::thermometer(&readings[0]);
    let front_end = board::single_front_end(wiring.spi, wiring.cs.pa4, wiring.delay);
    board.run::<Model, _, _, _, _, _>(thermometer, front_end, Emulation::new(&readings, qemu::Ramp))
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-qemu image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
