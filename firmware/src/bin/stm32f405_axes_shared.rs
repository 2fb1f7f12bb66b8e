//! The three-axis board (`stm32f405-axes`'s wiring) for a shared-basis
//! blob (`trainer fit`'s joint model: one basis of up to
//! [`firmware::SHARED_AXIS_CENTERS`] centres, a layer per axis, evaluated
//! once per sample); every axis reads the x coil's TMP117.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use embedded_hal_bus::util::AtomicCell;
    use firmware::SHARED_AXIS_CENTERS;
    use firmware::board::{self, Board};
    use rbf_core::shared_basis::SharedAxisModels;

    let (board, wiring) = Board::setup();
    let i2c = AtomicCell::new(wiring.i2c);
    let spi = AtomicCell::new(wiring.spi);
    let thermometers = board::coil_thermometers(&i2c);
    let front_ends = board::axis_front_ends(&spi, wiring.cs, wiring.delay);
    board.run::<SharedAxisModels<SHARED_AXIS_CENTERS>, _, _, _, _, _>(thermometers, front_ends, ())
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes-shared image runs on the MCU (probe-rs): see docs/firmware.md");
}
