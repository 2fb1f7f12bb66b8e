//! STM32F405 gyro board at 168 MHz: wiring only.
//!
//! - TMP117 on I2C1 (PB6 SCL, PB7 SDA, 400 kHz), address 0x48;
//! - IFOG front end on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, PA4 CS, mode 3,
//!   8 MHz) with data-ready on PB0 (EXTI, rising edge), 1 kHz;
//! - output frames on USART1 TX (PA9, 921 600 Bd, 8N1); model-update
//!   commands on USART1 RX (PA10), replies on TX (firmware::update);
//! - the model in flash slot MODEL_A (0x080C_0000) or MODEL_B (0x080E_0000),
//!   whichever holds the newest committed blob (firmware::model_store).
//!
//! Known limits of this board's update path: RX is polled between samples
//! (a byte every 10.9 µs at 921 600 Bd, about one compensation step), so the
//! host paces command bytes ≥ 20 µs apart; erasing a 128 KiB sector stalls
//! the CPU (code runs from flash) for about a second, so output frames pause
//! during an install (their sequence numbers show the gap). DMA reception and
//! a RAM-resident flash routine are the next steps.
//!
//! Flash with `cargo run --release -p firmware --features board-stm32f405
//! --bin stm32f405 --target thumbv7em-none-eabihf` (probe-rs, see README).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    use cortex_m_rt::entry;
    use embedded_hal_bus::spi::ExclusiveDevice;
    use firmware::compensation::{CompensationLoop, LoopConfig};
    use firmware::frontend::FrontEnd;
    use firmware::model_store::{ModelStore, SlotLayout};
    use firmware::tmp117::{self, Tmp117};
    use firmware::update::{self, CommandReceiver, Received};
    use rbf_core::CompensatorConfig;
    use stm32f4xx_hal::flash::{FlashExt, LockedFlash};
    use stm32f4xx_hal::gpio::{Edge, ExtiPin};
    use stm32f4xx_hal::i2c::{self, I2c};
    use stm32f4xx_hal::pac;
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::rcc::Config;
    use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};

    /// Front-end output data rate, Hz (paced by its crystal; data-ready marks each sample).
    const GYRO_RATE_HZ: f32 = 1000.0;
    /// Read the TMP117 every 125th sample: 8 Hz, its conversion rate at 8 averages.
    const TEMP_READ_EVERY: u32 = 125;
    /// MODEL_A and MODEL_B (memory.x) as offsets from the start of flash: sectors 10 and 11.
    const MODEL_SLOTS: SlotLayout = SlotLayout {
        offsets: [0x000C_0000, 0x000E_0000],
        len: firmware::MODEL_SLOT_LEN as u32,
    };

    fn halt() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[entry]
    fn main() -> ! {
        let Some(mut dp) = pac::Peripherals::take() else { halt() };
        let mut rcc = dp.RCC.freeze(Config::hse(8.MHz()).sysclk(168.MHz()));
        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let mut syscfg = dp.SYSCFG.constrain(&mut rcc);

        let i2c = I2c::new(
            dp.I2C1,
            (gpiob.pb6, gpiob.pb7),
            i2c::Mode::fast(400.kHz(), i2c::DutyCycle::Ratio2to1),
            &mut rcc,
        );
        let mode = Mode {
            polarity: Polarity::IdleHigh,
            phase: Phase::CaptureOnSecondTransition,
        };
        let spi = Spi::new(
            dp.SPI1,
            (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
            mode,
            8.MHz(),
            &mut rcc,
        );
        let Ok(spi_device) = ExclusiveDevice::new_no_delay(spi, gpioa.pa4.into_push_pull_output());
        let mut data_ready = gpiob.pb0.into_pull_down_input();
        data_ready.make_interrupt_source(&mut syscfg);
        data_ready.trigger_on_edge(&mut dp.EXTI, Edge::Rising);
        data_ready.enable_interrupt(&mut dp.EXTI);
        let Ok(serial) = dp.USART1.serial::<u8>((gpioa.pa9, gpioa.pa10), 921_600.bps(), &mut rcc) else {
            halt()
        };
        let (uart, mut uart_rx) = serial.split();
        let mut flash = LockedFlash::new(dp.FLASH);

        // An invalid or absent model is not fatal: every frame then carries flag 4.
        let model = ModelStore::open(flash.unlocked(), MODEL_SLOTS).load().ok();
        // Sensor init failures are not fatal either: the loop's reads fail and flag them.
        let mut thermometer = Tmp117::new(i2c, tmp117::DEFAULT_ADDRESS);
        let _ = thermometer.init();
        let mut front_end = FrontEnd::new(spi_device);
        let _ = front_end.init();

        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(GYRO_RATE_HZ),
            temp_read_every: TEMP_READ_EVERY,
        };
        let mut compensation = CompensationLoop::new(model, config, thermometer, front_end, uart);
        let period_s = 1.0 / GYRO_RATE_HZ;
        let mut commands = CommandReceiver::new();
        loop {
            // Model-update commands arrive between samples.
            while let Ok(byte) = uart_rx.read() {
                let (command, status, model) = match commands.push(byte) {
                    None => continue,
                    Some(Received::Rejected(status)) => (0, status, None),
                    Some(Received::Command(payload)) => {
                        // Unlocked only for the command; relocked when the store drops.
                        let mut store = ModelStore::open(flash.unlocked(), MODEL_SLOTS);
                        let (status, model) = update::execute(&mut store, payload);
                        (payload.first().copied().unwrap_or(0), status, model)
                    }
                };
                if model.is_some() {
                    compensation.replace_model(model);
                }
                let mut reply = [0u8; 8];
                if let Some(n) = update::encode_reply(command, status, &mut reply) {
                    let _ = embedded_io::Write::write_all(compensation.output_mut(), reply.get(..n).unwrap_or(&[]));
                }
            }
            // The EXTI pending bit latches the data-ready edge, so none is missed
            // while the previous sample is processed (≈ 11 µs at K = 32).
            if data_ready.check_interrupt() {
                data_ready.clear_interrupt_pending_bit();
                compensation.step(period_s);
            }
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405 board runs on the MCU: see README (cargo run with probe-rs)");
}
