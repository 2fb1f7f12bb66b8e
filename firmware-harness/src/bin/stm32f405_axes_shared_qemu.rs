//! The `stm32f405-axes-shared` board image under QEMU (feature
//! `board-qemu`; `cargo xtask bench-fw` measures its stack).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use embedded_hal_bus::util::AtomicCell;
    use firmware::SHARED_AXIS_CENTERS;
    use firmware::board;
    use firmware_harness::qemu::{self, Emulation};
    use rbf_core::shared_basis::SharedAxisModels;

    let (board, wiring) = qemu::setup();
    let readings = qemu::ramp::<3>();
    let thermometers = qemu::coil_thermometers(&readings);
    let spi = AtomicCell::new(wiring.spi);
    let front_ends = board::axis_front_ends(&spi, wiring.cs, wiring.delay);
    board.run::<SharedAxisModels<SHARED_AXIS_CENTERS>, _, _, _, _, _>(
        thermometers,
        front_ends,
        Emulation::new(&readings, qemu::Ramp),
    )
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes-shared-qemu image runs on QEMU's netduinoplus2 (cargo xtask): see docs/firmware.md");
}
