//! The pieces of the board that QEMU's netduinoplus2 lacks, swapped for
//! the QEMU images (feature `board-qemu`): the reset clocks, no I2C, the
//! transmit interrupt pended by hand. Everything else is the board's own
//! code; what the QEMU images emulate around it (the model slots in RAM,
//! the sensors, TIM3 as data-ready, the run's end) is the test harness
//! crate's (`firmware-harness`, its `qemu` module; docs/firmware.md).
use stm32f4xx_hal::pac;

/// The clocks QEMU runs at: it has no clock controller (the HSE never
/// reports ready), so the reset clocks.
#[inline(always)]
pub fn clocks() -> super::hw::ClockTree {
    super::hw::HSI_TREE
}

/// QEMU has no I2C: the emulated thermometers stand in for the bus.
#[derive(Clone, Copy, Debug)]
pub struct NoI2c;

/// The board's I2C1: none under QEMU.
pub type I2c1 = NoI2c;

/// No I2C1 to set up (QEMU has none).
#[inline(always)]
pub fn i2c1(
    _pb6: stm32f4xx_hal::gpio::PB6,
    _pb7: stm32f4xx_hal::gpio::PB7,
    _rcc: &mut stm32f4xx_hal::rcc::Rcc,
    _clocks: &super::hw::ClockTree,
    _tim2: super::hw::Tim2Clock,
) -> I2c1 {
    NoI2c
}

/// QEMU's USART never raises its transmit-empty interrupt (its data
/// register is always empty): its handler is pended, as TXE would.
#[inline(always)]
pub fn pend_tx() {
    cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
}
