//! Link-time proof that the per-sample path cannot panic.
//!
//! Built only with the `panic-free-check` feature, under which the panic
//! handler ([`firmware::board`]) calls `hot_path_can_panic`, a symbol that is
//! defined nowhere. This image runs boot-time model validation and then
//! [`CompensationLoop::step`] forever, through the real TMP117 and front-end
//! drivers, on buses whose bytes, time steps and model slot are volatile
//! reads the optimiser knows nothing about. If any panic (index out of
//! bounds, unwrap, overflow check, arithmetic panic, formatting) survives
//! optimisation on that path, the link fails naming the symbol. CI builds it
//! (`xtask::firmware::check_panic_free`), and its canary (feature
//! `panic-free-check-canary`: one deliberate bounds check), which must fail
//! to link. Never flashed or run. How to find a path that fails it:
//! docs/panic-free.md.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    #![allow(unsafe_code)]

    use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};

    use cortex_m_rt::entry;
    use embedded_hal::i2c::{self, I2c};
    use embedded_hal::spi::{self, SpiDevice};
    use firmware::compensation::{CompensationLoop, LoopConfig};
    use firmware::frontend::FrontEnd;
    use firmware::tmp117::{self, Tmp117};
    use rbf_core::CompensatorConfig;

    /// Bytes the fake buses return, unknown to the optimiser.
    static BUS: [AtomicU8; 64] = [const { AtomicU8::new(0) }; 64];
    /// A word unknown to the optimiser (time steps, bus failures).
    static WORD: AtomicU32 = AtomicU32::new(0);

    fn opaque_byte(i: usize) -> u8 {
        BUS[i % BUS.len()].load(Ordering::Relaxed)
    }

    fn opaque_word() -> u32 {
        WORD.load(Ordering::Relaxed)
    }

    /// I2C that answers anything, or fails, as the opaque bytes say.
    struct OpaqueI2c;

    impl i2c::ErrorType for OpaqueI2c {
        type Error = i2c::ErrorKind;
    }

    impl I2c for OpaqueI2c {
        fn transaction(&mut self, _: u8, operations: &mut [i2c::Operation<'_>]) -> Result<(), Self::Error> {
            if opaque_word() & 1 != 0 {
                return Err(i2c::ErrorKind::Bus);
            }
            for op in operations {
                if let i2c::Operation::Read(buf) = op {
                    for (i, b) in buf.iter_mut().enumerate() {
                        *b = opaque_byte(i);
                    }
                }
            }
            Ok(())
        }
    }

    /// SPI that answers anything, or fails, as the opaque bytes say.
    struct OpaqueSpi;

    impl spi::ErrorType for OpaqueSpi {
        type Error = spi::ErrorKind;
    }

    impl SpiDevice for OpaqueSpi {
        fn transaction(&mut self, operations: &mut [spi::Operation<'_, u8>]) -> Result<(), Self::Error> {
            if opaque_word() & 2 != 0 {
                return Err(spi::ErrorKind::Other);
            }
            for op in operations {
                if let spi::Operation::Read(buf) = op {
                    for (i, b) in buf.iter_mut().enumerate() {
                        *b = opaque_byte(i + 16);
                    }
                }
            }
            Ok(())
        }
    }

    /// A UART that accepts or refuses bytes as the opaque word says.
    struct OpaqueUart;

    impl embedded_io::ErrorType for OpaqueUart {
        type Error = embedded_io::ErrorKind;
    }

    impl embedded_io::Write for OpaqueUart {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            for &b in buf {
                BUS[usize::from(b) % BUS.len()].store(b, Ordering::Relaxed);
            }
            if opaque_word() & 4 != 0 {
                Err(embedded_io::ErrorKind::Other)
            } else {
                Ok(buf.len())
            }
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    #[entry]
    fn main() -> ! {
        // Boot: validate the model slot (any bytes) and the devices (any answers).
        let model = firmware::load_model(firmware::board::model_slot_a()).ok();
        let mut thermometer = Tmp117::new(OpaqueI2c, tmp117::DEFAULT_ADDRESS);
        let _ = thermometer.init();
        let mut front_end = FrontEnd::new(OpaqueSpi);
        let _ = front_end.init();
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(f32::from_bits(opaque_word())),
            temp_read_every: opaque_word(),
        };
        let mut compensation = CompensationLoop::new(model, config, thermometer, front_end, OpaqueUart);
        loop {
            let out = compensation.step(f32::from_bits(opaque_word()));
            WORD.store(out.bias_dph.to_bits() ^ u32::from(out.flags.bits()), Ordering::Relaxed);
            #[cfg(feature = "panic-free-check-canary")]
            {
                // A bounds check the optimiser cannot remove: this must not link.
                let table = [1u32, 2, 3, 4];
                WORD.store(table[opaque_word() as usize], Ordering::Relaxed);
            }
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("panic-free-check is a link-time check for thumbv7em-none-eabihf: see its source");
}
