//! The gyro board: everything an image runs but its own few lines of
//! wiring (`src/bin/stm32f405*.rs`, one small binary per image; the
//! images under QEMU are firmware-harness's, beside their emulation).
//!
//! - [`timing`]: the timer arithmetic (TIM2 rates, the SysTick reload,
//!   delays, elapsed ticks on wrapping counters), host-tested;
//! - [`run_loop`]: the run loop itself (its start, one pass, the health
//!   report), over the library's traits: `Board::run` wires the chip to it
//!   and the fault campaign (`firmware-harness/tests/board_faults`) runs it
//!   on the host against simulated peripherals;
//! - on the MCU (`target_os = "none"`), for every image including the QEMU
//!   test images: the model flash slots, the fault record kept across a
//!   reset, the stack painting and the panic handler;
//! - with the feature `board-stm32f405` (stm32f4xx-hal): `hw` (TIM2, the
//!   IWDG, I2C1, the flash controller and the clock tree at register
//!   level), the board's setup, interrupt and exception handlers and run
//!   loop (`Board`), generic over the model kind and the sensors an image
//!   wires and over the flash of its model slots (`BoardFlash`), and
//!   with `board-qemu` the substitutes for what QEMU's netduinoplus2
//!   lacks (`qemu`).
#![allow(unsafe_code)]

pub mod run_loop;
pub mod timing;

#[cfg(target_os = "none")]
mod rt;
#[cfg(target_os = "none")]
pub use rt::*;

#[cfg(all(target_os = "none", feature = "board-stm32f405"))]
pub mod chip;
#[cfg(all(target_os = "none", feature = "board-stm32f405"))]
pub mod hw;
// On the MCU with the board; on the host in the tests, over zeroed register blocks.
#[cfg(all(target_os = "none", feature = "board-stm32f405"))]
mod image;
#[cfg(all(target_os = "none", feature = "board-stm32f405"))]
mod isr;
#[cfg(any(
    all(target_os = "none", feature = "board-stm32f405"),
    all(test, not(target_os = "none"))
))]
pub mod registers;
#[cfg(all(target_os = "none", feature = "board-stm32f405"))]
pub use image::*;
#[cfg(all(target_os = "none", feature = "board-qemu"))]
pub mod qemu;
