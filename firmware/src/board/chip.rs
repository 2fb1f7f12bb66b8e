//! The STM32F405 itself behind the board's few chip-or-QEMU choices (the
//! QEMU images take `super::qemu`'s instead): the bounded clock setup,
//! I2C1 through the bounded master; and the model slots in flash through
//! the flash controller, the board's [`super::BoardFlash`] unless an image
//! picks another (the QEMU images' emulated flash).

use stm32f4xx_hal::gpio::{PB6, PB7};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Rcc};

use super::hw::{self, ClockTree, Tim2Clock};
use crate::flash_ctl::ControllerFlash;
use crate::i2c_master::BoundedI2c;
use crate::model_store::SlotLayout;

/// The board's own clock setup, every wait bounded (a dead crystal: the HSI).
#[inline(always)]
pub fn clocks() -> ClockTree {
    hw::setup_clocks()
}

/// I2C1 (PB6 SCL, PB7 SDA) through the bounded master.
pub type I2c1 = BoundedI2c<hw::I2c1Regs, Tim2Clock>;

/// I2C1 through the bounded master: the bus is recovered before first use.
#[inline(always)]
pub fn i2c1(pb6: PB6, pb7: PB7, rcc: &mut Rcc, clocks: &ClockTree, tim2: Tim2Clock) -> I2c1 {
    let _scl = pb6.into_alternate_open_drain::<4>();
    let _sda = pb7.into_alternate_open_drain::<4>();
    pac::I2C1::enable(rcc);
    let pclk1_mhz = (clocks.pclk1_hz / 1_000_000) as u16;
    BoundedI2c::new(hw::I2c1Regs { pclk1_mhz }, tim2)
}

/// The model slots' flash: the flash controller.
pub type SlotFlash = ControllerFlash<hw::FlashRegs, Tim2Clock, hw::Iwdg>;

impl super::BoardFlash for SlotFlash {
    /// MODEL_A and MODEL_B (memory.x) as offsets from the start of flash: the
    /// flash controller's registers only ever program or map words inside them.
    const SLOTS: SlotLayout = hw::MODEL_SLOTS;

    /// The flash controller driver over the model slots.
    #[inline(always)]
    fn open(tim2: Tim2Clock) -> Self {
        ControllerFlash::new(hw::FlashRegs, tim2, hw::Iwdg)
    }
}

/// After a byte was written or a frame queued: the transmit-empty
/// interrupt follows by itself on the chip.
#[inline(always)]
pub fn pend_tx() {}
