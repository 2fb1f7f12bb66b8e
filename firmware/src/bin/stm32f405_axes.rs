//! The STM32F405 board for a three-axis IMU: three front ends on SPI1
//! (chip selects PA4 x, PA3 y, PA2 z; data-ready from x on PB0), each
//! coil's TMP117 on I2C1 (0x48 x, 0x49 y, 0x4A z), a model per axis
//! (blob format 3, [`firmware::AXIS_CENTERS`] centres each); one frame
//! with all axes per sample (docs/firmware.md, "Three axes").
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use embedded_hal_bus::util::AtomicCell;
    use firmware::AXIS_CENTERS;
    use firmware::board::{self, Board};
    use rbf_core::blob::axes::AxisModels;

    let (board, wiring) = Board::setup();
    let i2c = AtomicCell::new(wiring.i2c);
    let spi = AtomicCell::new(wiring.spi);
    let thermometers = board::coil_thermometers(&i2c);
    let front_ends = board::axis_front_ends(&spi, wiring.cs, wiring.delay);
    board.run::<AxisModels<AXIS_CENTERS>, _, _, _, _, _>(thermometers, front_ends, ())
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405-axes image runs on the MCU (probe-rs): see docs/firmware.md");
}
