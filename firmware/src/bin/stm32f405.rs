//! The STM32F405 gyro board at 168 MHz (`cargo flash-board`): one IFOG
//! front end on SPI1 (chip select PA4, data-ready PB0), its loop TMP117 on
//! I2C1 at 0x48, a single gyro's model ([`rbf_core::Model`]). Setup,
//! handlers and loop: `firmware::board` (pins and timing in its docs and
//! in docs/firmware.md).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    use firmware::board::{self, Board};
    use firmware::tmp117::{self, Tmp117};
    use rbf_core::Model;

    let (board, wiring) = Board::setup();
    let thermometer = Tmp117::new(wiring.i2c, tmp117::DEFAULT_ADDRESS);
    let front_end = board::single_front_end(wiring.spi, wiring.cs.pa4, wiring.delay);
    board.run::<Model, _, _, _, _, _>(thermometer, front_end, ())
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405 image runs on the MCU (probe-rs): see docs/firmware.md");
}
