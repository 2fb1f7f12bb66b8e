//! Link-time proof that nothing the board image runs after init can panic.
//!
//! Built only with the `panic-free-check` feature, under which the panic
//! handler ([`firmware::board`]) calls `hot_path_can_panic`, a symbol that is
//! defined nowhere. This image runs what the stm32f405 board runs: boot-time
//! model selection and validation over a flash device, the boot report, and
//! then forever [`CompensationLoop::step_at`] through the real TMP117 and
//! front-end drivers, command bytes through the update receiver (COBS), the
//! update command with the two-slot model store (erase, write, verify,
//! commit, rescan) and its reply. Buses, flash, time steps, edge numbers and
//! model slots are volatile reads the optimiser knows nothing about, and the
//! UART output behaves as the stm32f4xx-hal driver does: it may take nothing
//! (`Ok(0)`), part of a buffer, or refuse (`WouldBlock`). If any panic (index out of
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
    use embedded_storage::nor_flash;
    use firmware::compensation::{CompensationLoop, InPlaceModel, LoopConfig, write_frame};
    use firmware::fault::{self, FaultRecord};
    use firmware::frontend::FrontEnd;
    use firmware::model_store::{MappedFlash, ModelStore, SlotLayout};
    use firmware::tmp117::{self, Tmp117};
    use firmware::update::{self, CommandReceiver, Received};
    use rbf_core::{CompensatorConfig, Flags, Model};

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

    /// A UART like the real driver: takes nothing (`Ok(0)`, data register
    /// full), part of the buffer, all of it, or refuses (`WouldBlock`, an
    /// overrun), as the opaque word says.
    struct OpaqueUart;

    impl embedded_io::ErrorType for OpaqueUart {
        type Error = embedded_io::ErrorKind;
    }

    impl embedded_io::Write for OpaqueUart {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            for &b in buf {
                BUS[usize::from(b) % BUS.len()].store(b, Ordering::Relaxed);
            }
            match opaque_word() & 0xC {
                0 => Ok(0),
                4 => Err(embedded_io::ErrorKind::Other),
                8 => Ok(buf.len().min(opaque_word() as usize)),
                _ => Ok(buf.len()),
            }
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    /// NOR flash whose reads return opaque bytes and whose operations fail
    /// or succeed as the opaque word says.
    struct OpaqueFlash;

    impl nor_flash::ErrorType for OpaqueFlash {
        type Error = nor_flash::NorFlashErrorKind;
    }

    impl nor_flash::ReadNorFlash for OpaqueFlash {
        const READ_SIZE: usize = 1;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            if opaque_word() & 16 != 0 {
                return Err(nor_flash::NorFlashErrorKind::Other);
            }
            for (i, b) in bytes.iter_mut().enumerate() {
                *b = opaque_byte(i + offset as usize);
            }
            Ok(())
        }
        fn capacity(&self) -> usize {
            opaque_word() as usize
        }
    }

    impl nor_flash::NorFlash for OpaqueFlash {
        const WRITE_SIZE: usize = 1;
        const ERASE_SIZE: usize = 128 * 1024;
        fn erase(&mut self, _: u32, _: u32) -> Result<(), Self::Error> {
            if opaque_word() & 32 != 0 {
                return Err(nor_flash::NorFlashErrorKind::Other);
            }
            Ok(())
        }
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            for (i, b) in bytes.iter().enumerate() {
                BUS[(offset as usize + i) % BUS.len()].store(*b, Ordering::Relaxed);
            }
            if opaque_word() & 64 != 0 {
                return Err(nor_flash::NorFlashErrorKind::Other);
            }
            Ok(())
        }
    }

    impl MappedFlash for OpaqueFlash {
        /// Any bytes: the model slot the linker places, from an opaque offset.
        fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
            let start = (offset ^ opaque_word()) as usize;
            firmware::board::model_slot_a().get(start..start.checked_add(len)?)
        }
    }

    /// The running model and the command buffer, as the board keeps them.
    static mut MODEL: Model = Model::EMPTY;
    static mut COMMANDS: CommandReceiver = CommandReceiver::new();

    const SLOTS: SlotLayout = SlotLayout {
        offsets: [0x000C_0000, 0x000E_0000],
        len: firmware::MODEL_SLOT_LEN as u32,
    };

    #[entry]
    fn main() -> ! {
        // Boot: the fault record and its report, model selection over the
        // flash (any bytes), the model slot A as the QEMU boards read it,
        // the devices (any answers).
        let cause = fault::boot_cause(FaultRecord::from_words([opaque_word(); 4]), opaque_word() & 1 != 0);
        let (model, commands) = (&raw mut MODEL, &raw mut COMMANDS);
        // SAFETY: main runs once; the only references to the two statics.
        let (model, commands) = unsafe { (&mut *model, &mut *commands) };
        let mut store = ModelStore::open_with(OpaqueFlash, SLOTS, model);
        let loaded = store.load_into(model).is_ok();
        let model = InPlaceModel::new(model, loaded);
        let mut thermometer = Tmp117::new(OpaqueI2c, tmp117::DEFAULT_ADDRESS);
        let _ = thermometer.init();
        let mut front_end = FrontEnd::new(OpaqueSpi);
        let _ = front_end.init();
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(f32::from_bits(opaque_word())),
            temp_read_every: opaque_word(),
        };
        let mut compensation = CompensationLoop::new(model, config, thermometer, front_end, OpaqueUart);
        if let Some(cause) = cause {
            let mut report = [0u8; 16];
            if let Some(n) = fault::encode_boot_report(cause, opaque_byte(3), &mut report) {
                write_frame(compensation.output_mut(), report.get(..n).unwrap_or(&[]));
            }
            compensation.flag_next_frame(Flags::FAULT_RESET);
        }
        loop {
            // A sample, as the board runs it from a data-ready stamp.
            let [out] = compensation.step_at(opaque_word(), f32::from_bits(opaque_word()));
            WORD.store(out.bias_dph.to_bits() ^ u32::from(out.flags.bits()), Ordering::Relaxed);
            // A command byte, as the board takes it from the receive queue.
            let reply = match commands.push(opaque_byte(7)) {
                None => None,
                Some(Received::Rejected(status)) => Some((0, status)),
                Some(Received::Command(payload)) => {
                    let mut status = update::UpdateStatus::UnknownCommand;
                    compensation.update_model(|model| {
                        model.rebuild(|m| {
                            status = update::execute_into(&mut store, payload, m);
                            store.model_loaded()
                        })
                    });
                    Some((payload.first().copied().unwrap_or(0), status))
                }
            };
            if let Some((command, status)) = reply {
                let mut bytes = [0u8; 8];
                if let Some(n) = gyro_wire::command::encode_reply(command, status, &mut bytes) {
                    write_frame(compensation.output_mut(), bytes.get(..n).unwrap_or(&[]));
                }
            }
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
