//! The `stm32f405` board image with defmt logging over RTT (feature
//! `board-debug`; `cargo flash-board-debug`): boot cause, model updates and
//! bench reports. The same wiring as `stm32f405`.
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
    eprintln!("the stm32f405-debug image runs on the MCU (probe-rs): see docs/firmware.md");
}
