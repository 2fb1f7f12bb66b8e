//! STM32F405 gyro board at 168 MHz: wiring and interrupt handlers only.
//!
//! - TMP117 on I2C1 (PB6 SCL, PB7 SDA, 400 kHz), address 0x48;
//! - IFOG front end on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, PA4 CS, mode 3,
//!   at most 10 MHz: 84 MHz / 16) with data-ready on PB0 (EXTI0, rising
//!   edge), 1 kHz;
//! - output frames on USART1 TX (PA9, 921 600 Bd, 8N1); model-update,
//!   bench and health commands on USART1 RX (PA10, pulled up), replies on
//!   TX (firmware::update, firmware::health);
//! - the model in flash slot MODEL_A (0x080C_0000) or MODEL_B (0x080E_0000),
//!   whichever holds the newest committed blob (firmware::model_store).
//!
//! Timing (docs/firmware.md): the EXTI0 interrupt timestamps every
//! data-ready edge with TIM2 (32 bits at the 84 MHz timer clock) and queues
//! the stamp; the main loop takes stamps from the queue, derives dt and the
//! edge number from them (edges lost while the CPU stalled, as during a
//! flash erase, count and are flagged) and runs one compensation step per
//! stamp (firmware::pacing: glitches rejected, a backlog counted as missed,
//! steps synthesised when data-ready falls silent; SysTick wakes the loop
//! every millisecond to notice). USART1's interrupt moves bytes between the
//! UART and two queues: frames out (firmware::uart::FrameQueue, whole or
//! dropped and flagged) and command bytes in (overruns counted). The
//! independent watchdog starts before the clock tree (firmware::watchdog:
//! ≥ 2 s at the fastest LSI, ≥ 4.5 s around a model install) and is fed
//! once per step. Every wait on I2C, the flash controller and the clock
//! setup is bounded (firmware::i2c_master, firmware::flash_ctl, hw.rs). A
//! panic or HardFault records its cause in RAM that survives the reset
//! (firmware::fault) and resets; the next boot reports it, and every boot
//! sends the health report (firmware::health).
//!
//! With the feature `board-axes` the same board serves a three-axis IMU:
//! three front ends share SPI1 (chip selects PA4 x, PA3 y, PA2 z; the
//! front ends sample together, data-ready from x on PB0), each coil's
//! TMP117 sits on I2C1 (0x48 x, 0x49 y, 0x4A z), the model slots hold a
//! multi-axis blob (format 3, [`firmware::AXIS_CENTERS`] centres per axis)
//! and every sample goes out as one frame with all axes (firmware::compensation,
//! the loop of three axes).
//! With `board-axes-shared` as well, the same three-axis board holds a
//! shared-basis blob instead (one basis of up to
//! [`firmware::SHARED_AXIS_CENTERS`] centres, a layer per axis, evaluated
//! once per sample); every axis then reads the x coil's TMP117.
//!
//! Flash with `cargo run --release -p firmware --features board-stm32f405
//! --bin stm32f405 --target thumbv7em-none-eabihf` (probe-rs, see docs/firmware.md).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    #![allow(unsafe_code)]

    mod hw;

    use core::cell::RefCell;
    use core::sync::atomic::{AtomicU32, Ordering};

    use cortex_m::interrupt::Mutex;
    use cortex_m::peripheral::DWT;
    use cortex_m_rt::{ExceptionFrame, entry, exception};
    #[cfg(feature = "board-debug")]
    use defmt_rtt as _;
    #[cfg(not(feature = "board-axes"))]
    use embedded_hal_bus::spi::ExclusiveDevice;
    #[cfg(feature = "board-axes")]
    use embedded_hal_bus::util::AtomicCell;
    use firmware::bench::{Bench, CMD_BENCH};
    use firmware::compensation::{CompensationLoop, InPlaceModel, LoopConfig, LoopStats, write_frame};
    use firmware::fault::{self, FaultReason, FaultRecord};
    #[cfg(not(feature = "board-qemu"))]
    use firmware::flash_ctl::ControllerFlash;
    use firmware::frontend::{self, FrontEnd};
    use firmware::health::{
        BOARD_ON_HSI, CMD_HEALTH, FirmwareVersion, HEALTH_FRAME_LEN, HealthCounters, HealthReport, ResetCause,
    };
    #[cfg(not(feature = "board-qemu"))]
    use firmware::i2c_master::BoundedI2c;
    use firmware::model_store::ModelStore;
    #[cfg(not(feature = "board-qemu"))]
    use firmware::model_store::SlotLayout;
    use firmware::pacing::{self, Pacer, PacerCounters};
    #[cfg(any(feature = "board-qemu", not(feature = "board-axes")))]
    use firmware::tmp117;
    use firmware::tmp117::Tmp117;
    use firmware::uart::{self, FrameQueue};
    use firmware::update::{self, CommandReceiver, Received, UpdateStatus};
    use firmware::watchdog::{self, Watchdog};
    use heapless::spsc::{Consumer, Producer, Queue};
    #[cfg(not(feature = "board-axes"))]
    use rbf_core::Model;
    #[cfg(all(feature = "board-axes", not(feature = "board-axes-shared")))]
    use rbf_core::blob::axes::AxisModels;
    #[cfg(feature = "board-axes-shared")]
    use rbf_core::shared_basis::SharedAxisModels;
    use rbf_core::{CompensatorConfig, Flags};
    use stm32f4xx_hal::gpio::{Edge, ExtiPin, Input, PB0};
    use stm32f4xx_hal::pac::{self, interrupt};
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::rcc::{Enable, Reset};
    use stm32f4xx_hal::serial::{Rx, RxListen, Tx, TxListen};
    use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};

    /// Logs over RTT in the debug image (`board-debug`); nothing otherwise.
    macro_rules! log {
        ($($arg:tt)*) => {
            #[cfg(feature = "board-debug")]
            defmt::info!($($arg)*);
        };
    }

    /// Front-end output data rate, Hz (paced by its crystal; data-ready marks each sample).
    const GYRO_RATE_HZ: f32 = 1000.0;
    /// Read the TMP117 every 125th sample: 8 Hz, its conversion rate at 8 averages.
    const TEMP_READ_EVERY: u32 = 125;
    /// MODEL_A and MODEL_B (memory.x) as offsets from the start of flash: sectors 10 and 11.
    #[cfg(not(feature = "board-qemu"))]
    const MODEL_SLOTS: SlotLayout = SlotLayout {
        offsets: [0x000C_0000, 0x000E_0000],
        len: firmware::MODEL_SLOT_LEN as u32,
    };
    /// The front end's fastest SPI clock, Hz (docs/frontend.md).
    const SPI_MAX_HZ: u32 = 10_000_000;
    /// Bytes of the transmit queue: 24 output frames (≤ 21 B each at 1 kHz
    /// take 0.23 ms of the 1 ms at 921 600 Bd), or a reply and a burst.
    const TX_QUEUE: usize = 512;
    /// Bytes of the receive queue: commands arrive faster than the loop
    /// takes them only while it is busy (2.8 ms of bytes at 921 600 Bd).
    const RX_QUEUE: usize = 256;
    /// Data-ready stamps waiting for the loop.
    const STAMP_QUEUE: usize = 16;

    /// USART1's halves and the queue ends its interrupt serves.
    struct UartIsr {
        tx: Tx<pac::USART1>,
        rx: Rx<pac::USART1>,
        outgoing: Consumer<'static, u8>,
        incoming: Producer<'static, u8>,
    }

    /// The data-ready pin and the stamp queue its interrupt fills.
    struct DataReadyIsr {
        pin: PB0<Input>,
        stamps: Producer<'static, u32>,
    }

    /// The running model, decoded in place (all bits zero: .bss, no flash).
    #[cfg(not(feature = "board-axes"))]
    static mut MODEL: Model = Model::EMPTY;
    /// The running axis models, decoded in place (all bits zero: .bss, no flash).
    #[cfg(all(feature = "board-axes", not(feature = "board-axes-shared")))]
    static mut MODEL: AxisModels<{ firmware::AXIS_CENTERS }> = AxisModels::EMPTY;
    /// The running shared-basis model of every axis, decoded in place.
    #[cfg(feature = "board-axes-shared")]
    static mut MODEL: SharedAxisModels<{ firmware::SHARED_AXIS_CENTERS }> = SharedAxisModels::EMPTY;
    /// Command bytes collect here between samples (4 KiB: off the stack).
    static mut COMMANDS: CommandReceiver = CommandReceiver::new();

    static UART: Mutex<RefCell<Option<UartIsr>>> = Mutex::new(RefCell::new(None));
    static DATA_READY: Mutex<RefCell<Option<DataReadyIsr>>> = Mutex::new(RefCell::new(None));
    /// Command bytes lost: the UART overran or the receive queue was full.
    static RX_OVERRUNS: AtomicU32 = AtomicU32::new(0);
    /// Data-ready stamps lost to a full stamp queue (the edge count still includes them).
    static STAMP_OVERRUNS: AtomicU32 = AtomicU32::new(0);

    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        firmware::board::store_fault(FaultRecord {
            reason: FaultReason::HardFault,
            pc: frame.pc(),
            lr: frame.lr(),
        });
        cortex_m::peripheral::SCB::sys_reset()
    }

    /// Wakes the main loop every millisecond, so that a silent data-ready
    /// line is noticed (firmware::pacing synthesises the steps).
    #[exception]
    fn SysTick() {}

    #[interrupt]
    fn USART1() {
        cortex_m::interrupt::free(|cs| {
            // `try_borrow_mut`: a critical section on one core cannot find
            // the cell borrowed, and this way no panic path is linked.
            let Ok(mut uart) = UART.borrow(cs).try_borrow_mut() else {
                return;
            };
            let Some(u) = uart.as_mut() else { return };
            // The byte the receiver holds (an error read clears its flag;
            // bounded, so a line full of errors cannot hold the handler).
            for _ in 0..4 {
                match u.rx.read() {
                    Ok(byte) => {
                        if uart::enqueue(&mut u.incoming, byte).is_err() {
                            RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Err(stm32f4xx_hal::nb::Error::WouldBlock) => break,
                    Err(stm32f4xx_hal::nb::Error::Other(_)) => {
                        RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            match u.outgoing.peek().copied() {
                Some(byte) => {
                    if u.tx.write(byte).is_ok() {
                        let _ = uart::dequeue(&mut u.outgoing);
                    }
                    // QEMU's USART never raises its transmit-empty
                    // interrupt (its data register is always empty): the
                    // handler asks for itself again, as TXE would.
                    #[cfg(feature = "board-qemu")]
                    cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
                }
                None => u.tx.unlisten(),
            }
        });
    }

    #[interrupt]
    fn EXTI0() {
        // SAFETY: a read of TIM2's free-running counter, which only this
        // board's setup writes (before interrupts are enabled).
        let stamp = unsafe { (*pac::TIM2::ptr()).cnt().read().bits() };
        cortex_m::interrupt::free(|cs| {
            if let Some(d) = DATA_READY
                .borrow(cs)
                .try_borrow_mut()
                .ok()
                .as_deref_mut()
                .and_then(Option::as_mut)
            {
                d.pin.clear_interrupt_pending_bit();
                if uart::enqueue(&mut d.stamps, stamp).is_err() {
                    STAMP_OVERRUNS.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
    }

    /// Busy-waits on the core clock: the SPI device's delay (embedded-hal-bus's
    /// `NoDelay` would link a panic for a delay operation).
    struct CycleDelay {
        core_hz: u32,
    }

    impl embedded_hal::delay::DelayNs for CycleDelay {
        fn delay_ns(&mut self, ns: u32) {
            // Rounded up to whole µs: 32-bit arithmetic (a 64-bit division would link the
            // soft division routine into the image).
            let cycles = (ns / 1000 + 1).saturating_mul(self.core_hz / 1_000_000);
            cortex_m::asm::delay(cycles);
        }
    }

    /// Everything the board does after init: `serve` once per wake-up,
    /// forever. Its own function (never inlined), so that `cargo xtask
    /// check-board-panics` can prove from the image that no panic is
    /// reachable from here or from the interrupt handlers.
    #[inline(never)]
    fn run_forever(mut serve: impl FnMut()) -> ! {
        loop {
            serve();
        }
    }

    fn halt() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Starts the transmit interrupt after a frame was queued.
    fn start_tx() {
        cortex_m::interrupt::free(|cs| {
            if let Some(u) = UART
                .borrow(cs)
                .try_borrow_mut()
                .ok()
                .as_deref_mut()
                .and_then(Option::as_mut)
            {
                u.tx.listen();
            }
        });
        #[cfg(feature = "board-qemu")]
        cortex_m::peripheral::NVIC::pend(pac::Interrupt::USART1);
    }

    /// The pieces of the board that QEMU's netduinoplus2 lacks, swapped for
    /// the `board-qemu` image (`cargo xtask bench-fw`, board_stack_peak_bytes;
    /// docs/firmware.md): everything else is the board's own code.
    #[cfg(feature = "board-qemu")]
    mod qemu {
        use core::cell::Cell;

        use cortex_m_semihosting::{debug, hprintln};
        use firmware::compensation::LoopStats;
        use firmware::fault_injection::{EMULATED_LAYOUT, EMULATED_SLOT_LEN, ModelFlash};
        use firmware::model_store::SlotLayout;
        use firmware::replay::{EmulatedTmp117, ReplaySample};
        use firmware::update::UpdateStatus;
        use stm32f4xx_hal::pac::{self, interrupt};

        /// Samples the run lasts at least, and at least this many after the update.
        const SAMPLES: u32 = 10_000;
        const SAMPLES_AFTER_UPDATE: u32 = 2_000;
        /// Samples after which a run that never received an update gives up.
        const SAMPLES_WITHOUT_UPDATE: u32 = 200_000;

        /// The model slots: QEMU maps flash as ROM and has no flash
        /// controller, so they live in emulated NOR flash in RAM (the
        /// board's [`firmware::model_store::ModelStore`] code runs on it).
        /// Slot A starts as the blob QEMU's loader placed in flash slot A.
        static mut FLASH: ModelFlash = ModelFlash::new();

        /// The rate QEMU 7.2's STM32F2xx timers count at (their `clock-frequency`), Hz.
        #[cfg(feature = "board-qemu-serve")]
        pub const TIMER_HZ: u32 = 1_000_000_000;

        /// Where the slots lie in [`FLASH`].
        pub const SLOTS: SlotLayout = EMULATED_LAYOUT;

        /// The emulated model flash, slot A seeded from the real slot A.
        pub fn model_flash() -> &'static mut ModelFlash {
            let flash = &raw mut FLASH;
            // SAFETY: called once, from main; the only reference.
            let flash = unsafe { &mut *flash };
            let seed = firmware::board::model_slot_a().get(..EMULATED_SLOT_LEN).unwrap_or(&[]);
            for (d, s) in flash.contents_mut().iter_mut().zip(seed) {
                *d = *s;
            }
            flash
        }

        /// Axis `axis`'s coil TMP117 of sample `seq`: a slow ramp (QEMU has
        /// no I2C), each coil of a three-axis image half a degree warmer than
        /// the last; and the rate the emulated front end of the serving image
        /// (`board-qemu-serve`) sends with it.
        pub fn axis_sample(seq: u32, axis: usize) -> ReplaySample {
            let temp_c = 20.0 + 0.5 * axis as f64 + f64::from(seq % 100_000) * 1e-4;
            ReplaySample::with_loop(Some(temp_c), builtin_rate_dph(temp_c, axis))
        }

        /// The recorded run the serving image's sensors answer from
        /// (`run.csv` in QEMU's directory: `cargo xtask qemu-board --run`),
        /// one row per sample, from its start again after its end, for each of
        /// the image's `AXES` coils (a single-axis run's columns, or a
        /// three-axis run's `rate_<axis>_dph` and `temp_<axis>_c`); without
        /// the file, or for an axis the run lacks, the built-in ramp
        /// ([`axis_sample`]).
        #[cfg(feature = "board-qemu-serve")]
        pub struct RunSource<const AXES: usize> {
            lines: Option<firmware::host_file::HostLines>,
            columns: Option<[Option<rbf_core::record::Columns>; AXES]>,
        }

        #[cfg(feature = "board-qemu-serve")]
        impl<const AXES: usize> RunSource<AXES> {
            /// The run in `run.csv`, if QEMU's directory holds one.
            pub fn open() -> Self {
                RunSource {
                    lines: firmware::host_file::HostLines::open(RUN_FILE),
                    columns: None,
                }
            }

            /// Each axis's columns in a run with `header` (`None` if the
            /// header does not parse).
            fn columns(header: &str) -> Option<[Option<rbf_core::record::Columns>; AXES]> {
                let columns = rbf_core::record::Columns::from_header(header).ok()?;
                Some(core::array::from_fn(|axis| {
                    if AXES == 1 {
                        Some(columns)
                    } else {
                        rbf_core::axis::Axis::ALL.get(axis).and_then(|&a| columns.for_axis(a))
                    }
                }))
            }

            /// What the sensors present for sample `seq`: the run's next
            /// row (rows that do not parse are skipped), else the ramp's.
            pub fn next(&mut self, seq: u32) -> [ReplaySample; AXES] {
                let mut samples = core::array::from_fn(|axis| axis_sample(seq, axis));
                let RunSource { lines, columns } = self;
                // At most one pass to the end and one from the start again.
                for _ in 0..2 {
                    let Some(reader) = lines.as_mut() else { break };
                    while let Some(line) = reader.next_line() {
                        let Ok(text) = line else { continue };
                        let text = text.strip_suffix('\r').unwrap_or(text);
                        if rbf_core::record::is_comment_or_blank(text) {
                            continue;
                        }
                        let Some(axes) = columns else {
                            *columns = Self::columns(text);
                            continue;
                        };
                        let mut parsed = false;
                        for (sample, axis) in samples.iter_mut().zip(axes.iter()) {
                            if let Some(row) = axis.as_ref().and_then(|c| c.parse_row(text).ok()) {
                                *sample = ReplaySample {
                                    temps_c: row.readings_c(),
                                    rate_dph: row.rate_dph as f32,
                                };
                                parsed = true;
                            }
                        }
                        if parsed {
                            return samples;
                        }
                    }
                    *lines = firmware::host_file::HostLines::open(RUN_FILE);
                    *columns = None;
                }
                samples
            }
        }

        /// The run file of [`RunSource`], NUL-terminated for semihosting.
        #[cfg(feature = "board-qemu-serve")]
        const RUN_FILE: &str = "run.csv\0";

        /// The built-in profile's rate, °/h: a constant per axis (an Earth-rate
        /// projection) plus a bias that follows the coil temperature.
        fn builtin_rate_dph(temp_c: f64, axis: usize) -> f32 {
            (10.0 - 5.0 * axis as f64 + 0.05 * (temp_c - 25.0)) as f32
        }

        /// An I2C bus with the loop TMP117 at its default address.
        pub fn thermometer_bus(current: &Cell<ReplaySample>) -> EmulatedTmp117<'_> {
            EmulatedTmp117::new(current, rbf_core::features::LOOP_THERMOMETER)
        }

        /// The run's progress and its end.
        pub struct Run {
            updated: Option<(UpdateStatus, u32)>,
            samples: u32,
        }

        impl Run {
            /// Starts the data-ready source: TIM3 (which QEMU emulates) at
            /// one period of `period_ticks` TIM2 ticks pends EXTI0, whose
            /// handler (the board's) stamps the edge as on the board, where
            /// the front end's data-ready line raises it (QEMU has no GPIO).
            pub fn start(tim3: pac::TIM3, nvic: &mut cortex_m::peripheral::NVIC, period_ticks: u32) -> Run {
                tim3.psc().write(|w| w.psc().set(0));
                tim3.arr().write(|w| unsafe { w.bits(period_ticks.saturating_sub(1)) });
                tim3.dier().write(|w| w.uie().set_bit());
                tim3.cr1().modify(|_, w| w.cen().set_bit());
                // SAFETY: the handler only pends EXTI0, whose state is in place.
                unsafe {
                    nvic.set_priority(pac::Interrupt::TIM3, 0x40);
                    cortex_m::peripheral::NVIC::unmask(pac::Interrupt::TIM3);
                }
                Run {
                    updated: None,
                    samples: 0,
                }
            }

            /// An update command was answered with `status`.
            pub fn replied(&mut self, status: UpdateStatus) {
                self.updated = Some((status, self.samples));
            }

            /// Ends the run once it has done what it is for: reports the
            /// stack's high-water mark and exits (semihosting).
            pub fn check(&mut self, stats: &LoopStats) {
                self.samples = stats.samples;
                // The serving image runs until QEMU is stopped.
                if cfg!(feature = "board-qemu-serve") {
                    return;
                }
                let done = match self.updated {
                    Some((_, at)) => self.samples >= SAMPLES && self.samples - at >= SAMPLES_AFTER_UPDATE,
                    None => self.samples >= SAMPLES_WITHOUT_UPDATE,
                };
                if !done {
                    return;
                }
                hprintln!(
                    "samples {} missed {} output_errors {} update {:?}",
                    stats.samples,
                    stats.samples_missed,
                    stats.output_errors,
                    self.updated.map(|(status, _)| status)
                );
                hprintln!("board_stack_peak_bytes {}", firmware::board::stack_peak_bytes());
                let installed = matches!(self.updated, Some((UpdateStatus::Installed, _)));
                debug::exit(if installed {
                    debug::EXIT_SUCCESS
                } else {
                    debug::EXIT_FAILURE
                });
            }
        }

        #[interrupt]
        fn TIM3() {
            // SAFETY: clears TIM3's update flag, which only this handler reads.
            unsafe { (*pac::TIM3::ptr()).sr().write(|w| w.bits(0)) };
            cortex_m::peripheral::NVIC::pend(pac::Interrupt::EXTI0);
        }
    }

    /// What the boot found out about the last reset.
    #[derive(Clone, Copy)]
    struct Boot {
        cause: ResetCause,
        flags: u8,
        fault: Option<FaultRecord>,
        on_crystal: bool,
    }

    /// Sends the health report: `boot`, then the counters of the loop
    /// `$c`, the model store `$store` and the pacer `$pacer`.
    macro_rules! send_health {
        ($boot:expr, $c:expr, $store:expr, $pacer:expr) => {{
            #[cfg(not(feature = "board-axes"))]
            let inits = $c.sensors().1.inits();
            #[cfg(feature = "board-axes")]
            let inits = $c.sensors().1.iter().map(FrontEnd::inits).sum::<u32>();
            #[cfg(not(feature = "board-qemu"))]
            let flash_errors = $store.flash().errors();
            #[cfg(feature = "board-qemu")]
            let flash_errors = 0;
            let report = HealthReport {
                reset_cause: $boot.cause,
                reset_flags: $boot.flags,
                fault_pc: $boot.fault.map_or(0, |r| r.pc),
                fault_lr: $boot.fault.map_or(0, |r| r.lr),
                counters: health_counters(&$c.stats(), &$pacer.counters(), inits, flash_errors),
                model: $store.identity(),
                board_flags: if $boot.on_crystal { 0 } else { BOARD_ON_HSI },
                firmware_version: FirmwareVersion::CURRENT,
            };
            let mut frame = [0u8; HEALTH_FRAME_LEN];
            if let Some(n) = report.encode(&mut frame) {
                write_frame($c.output_mut(), frame.get(..n).unwrap_or(&[]));
            }
        }};
    }

    /// The counters of the health report, gathered from their owners.
    fn health_counters(
        stats: &LoopStats,
        pacer: &PacerCounters,
        front_end_inits: u32,
        flash_errors: u32,
    ) -> HealthCounters {
        let recoveries = hw::I2C_RECOVERIES.load(Ordering::Relaxed);
        HealthCounters {
            samples: stats.samples,
            samples_missed: stats.samples_missed,
            rate_read_faults: stats.rate_read_faults,
            temp_read_faults: stats.temp_read_faults,
            // Every recovery after the one at boot ends a timed-out transaction.
            sensor_timeouts: recoveries.saturating_sub(1),
            bus_recoveries: recoveries,
            front_end_inits,
            data_ready_glitches: pacer.glitches,
            synthetic_steps: pacer.synthetic,
            overruns: RX_OVERRUNS
                .load(Ordering::Relaxed)
                .wrapping_add(STAMP_OVERRUNS.load(Ordering::Relaxed)),
            output_dropped: stats.output_errors,
            flash_errors,
        }
    }

    #[entry]
    fn main() -> ! {
        let Some(mut dp) = pac::Peripherals::take() else { halt() };
        let Some(mut core) = cortex_m::Peripherals::take() else {
            halt()
        };
        // The watchdog first: a dead crystal or a stuck setup wait must not hang the board.
        let _ = hw::Iwdg::start(watchdog::running_setting());
        let mut watchdog = hw::Iwdg;
        let rcc_csr = dp.RCC.csr().read().bits();
        let reset_flags = (rcc_csr >> 24) as u8;
        let watchdog_reset = dp.RCC.csr().read().wdgrstf().bit_is_set();
        dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
        let fault_record = firmware::board::take_fault();
        let reset_cause = ResetCause::from_boot(fault_record, rcc_csr);
        let boot_cause = fault::boot_cause(fault_record, watchdog_reset);

        #[cfg(feature = "board-qemu")]
        firmware::board::paint_stack();
        // The board's own clock setup, every wait bounded (a dead crystal: the HSI).
        #[cfg(not(feature = "board-qemu"))]
        let clocks = hw::setup_clocks();
        // QEMU has no clock controller (the HSE never reports ready): the reset clocks.
        #[cfg(feature = "board-qemu")]
        let clocks = hw::HSI_TREE;
        // The HAL's RCC only enables and resets peripherals here: it
        // believes in the reset clocks, so the SPI divider and the UART's
        // baud rate are set again below from `clocks`.
        let mut rcc = dp.RCC.constrain();
        // The cycle counter the `bench` command reads (firmware::bench).
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let mut syscfg = dp.SYSCFG.constrain(&mut rcc);

        // TIM2 free-running over 32 bits at the timer clock: the data-ready
        // timestamps and the clock of every bounded wait.
        #[cfg(not(feature = "board-qemu-serve"))]
        let timer_hz = clocks.timclk1_hz;
        // QEMU's timers count at 1 GHz of virtual time whatever the clock
        // tree says; the serving image runs without -icount, where virtual
        // time is the host's, so this makes its samples come at 1 kHz of real time.
        #[cfg(feature = "board-qemu-serve")]
        let timer_hz = {
            let _ = clocks.timclk1_hz;
            qemu::TIMER_HZ
        };
        pac::TIM2::enable(&mut rcc);
        pac::TIM2::reset(&mut rcc);
        dp.TIM2.arr().write(|w| unsafe { w.bits(u32::MAX) });
        dp.TIM2.cr1().modify(|_, w| w.cen().set_bit());
        #[cfg(not(feature = "board-qemu"))]
        let tim2 = hw::Tim2Clock {
            ticks_per_us: (timer_hz / 1_000_000).max(1),
        };

        // I2C1 through the bounded master: the bus is recovered before first use.
        #[cfg(not(feature = "board-qemu"))]
        let i2c = {
            let _scl = gpiob.pb6.into_alternate_open_drain::<4>();
            let _sda = gpiob.pb7.into_alternate_open_drain::<4>();
            pac::I2C1::enable(&mut rcc);
            let pclk1_mhz = (clocks.pclk1_hz / 1_000_000) as u16;
            BoundedI2c::new(hw::I2c1Regs { pclk1_mhz }, tim2)
        };
        let mode = Mode {
            polarity: Polarity::IdleHigh,
            phase: Phase::CaptureOnSecondTransition,
        };
        let spi = Spi::new(
            dp.SPI1,
            (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
            mode,
            frontend::spi_clock_hz(rcc.clocks.pclk2().raw(), SPI_MAX_HZ).Hz(),
            &mut rcc,
        );
        hw::set_spi1_divider(&clocks, SPI_MAX_HZ);
        let core_hz = clocks.sysclk_hz;
        #[cfg(not(feature = "board-axes"))]
        let Ok(spi_device) = ExclusiveDevice::new(spi, gpioa.pa4.into_push_pull_output(), CycleDelay { core_hz });
        // Three front ends on one bus: a busy bus is an error the loop flags, never a wait or a panic.
        #[cfg(feature = "board-axes")]
        let spi_bus = AtomicCell::new(spi);
        #[cfg(feature = "board-axes")]
        let (Ok(spi_x), Ok(spi_y), Ok(spi_z)) = (
            embedded_hal_bus::spi::AtomicDevice::new(
                &spi_bus,
                gpioa.pa4.into_push_pull_output().erase(),
                CycleDelay { core_hz },
            ),
            embedded_hal_bus::spi::AtomicDevice::new(
                &spi_bus,
                gpioa.pa3.into_push_pull_output().erase(),
                CycleDelay { core_hz },
            ),
            embedded_hal_bus::spi::AtomicDevice::new(
                &spi_bus,
                gpioa.pa2.into_push_pull_output().erase(),
                CycleDelay { core_hz },
            ),
        );
        // RX pulled up: an unconnected or floating line reads idle, not noise.
        let rx_pin = gpioa.pa10.internal_pull_up(true);
        let Ok(serial) = dp.USART1.serial::<u8>((gpioa.pa9, rx_pin), 921_600.bps(), &mut rcc) else {
            halt()
        };
        hw::set_usart1_baud(&clocks, 921_600);
        let (tx, mut rx) = serial.split();
        rx.listen();
        #[cfg(not(feature = "board-qemu"))]
        let flash = ControllerFlash::new(hw::FlashRegs, tim2, hw::Iwdg);
        #[cfg(feature = "board-qemu")]
        let flash = qemu::model_flash();

        let Some(out_queue) = cortex_m::singleton!(: Queue<u8, TX_QUEUE> = Queue::new()) else {
            halt()
        };
        let Some(in_queue) = cortex_m::singleton!(: Queue<u8, RX_QUEUE> = Queue::new()) else {
            halt()
        };
        let Some(stamp_queue) = cortex_m::singleton!(: Queue<u32, STAMP_QUEUE> = Queue::new()) else {
            halt()
        };
        let (out_producer, outgoing) = out_queue.split();
        let (incoming, mut in_consumer) = in_queue.split();
        let (stamps, mut stamp_consumer) = stamp_queue.split();
        let mut output = FrameQueue::new(out_producer, start_tx);

        let mut data_ready = gpiob.pb0.into_pull_down_input();
        data_ready.make_interrupt_source(&mut syscfg);
        data_ready.trigger_on_edge(&mut dp.EXTI, Edge::Rising);
        data_ready.enable_interrupt(&mut dp.EXTI);
        cortex_m::interrupt::free(|cs| {
            // `try_borrow_mut`: nothing else holds the cells yet, and no panic path is linked.
            if let Ok(mut uart) = UART.borrow(cs).try_borrow_mut() {
                *uart = Some(UartIsr {
                    tx,
                    rx,
                    outgoing,
                    incoming,
                });
            }
            if let Ok(mut d) = DATA_READY.borrow(cs).try_borrow_mut() {
                *d = Some(DataReadyIsr {
                    pin: data_ready,
                    stamps,
                });
            }
        });

        // The boot report goes out first (a fault or watchdog reset before this boot).
        if let Some(cause) = boot_cause {
            let mut report = [0u8; 16];
            if let Some(n) = fault::encode_boot_report(cause, reset_flags, &mut report) {
                write_frame(&mut output, report.get(..n).unwrap_or(&[]));
            }
        }

        // SAFETY: `main` runs once and these are the only references to the
        // two statics (no interrupt handler touches them).
        let (model, commands) = (&raw mut MODEL, &raw mut COMMANDS);
        let (model, commands) = unsafe { (&mut *model, &mut *commands) };
        // An invalid or absent model is not fatal: every frame then carries flag 4.
        #[cfg(feature = "board-qemu")]
        let mut store = ModelStore::open_with(flash, qemu::SLOTS, model);
        #[cfg(not(feature = "board-qemu"))]
        let mut store = ModelStore::open_with(flash, MODEL_SLOTS, model);
        let loaded = store.load_into(model).is_ok();
        let model = InPlaceModel::new(model, loaded);
        log!(
            "boot: reset flags {=u8:#x}, fault or watchdog reset {=bool}, model loaded {=bool}",
            reset_flags,
            boot_cause.is_some(),
            loaded
        );
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(GYRO_RATE_HZ),
            temp_read_every: TEMP_READ_EVERY,
        };
        // Sensor init failures are not fatal either: the drivers retry on
        // each read until the sensors answer, and the frames are flagged meanwhile.
        #[cfg(all(feature = "board-qemu-serve", not(feature = "board-axes")))]
        let mut run_source = qemu::RunSource::<1>::open();
        #[cfg(all(feature = "board-qemu-serve", not(feature = "board-axes")))]
        let loop_temp = core::cell::Cell::new(run_source.next(0)[0]);
        #[cfg(all(
            feature = "board-qemu",
            not(feature = "board-qemu-serve"),
            not(feature = "board-axes")
        ))]
        let loop_temp = core::cell::Cell::new(qemu::axis_sample(0, 0));
        #[cfg(all(feature = "board-qemu", not(feature = "board-axes")))]
        let i2c = qemu::thermometer_bus(&loop_temp);
        // The serving image's front end answers from the same sample as the thermometer.
        #[cfg(all(feature = "board-qemu-serve", not(feature = "board-axes")))]
        // (SPI1 itself stays configured and unused: QEMU has no front end on it.)
        let (_spi1, spi_device) = (spi_device, firmware::replay::EmulatedFrontEnd::new(&loop_temp));
        #[cfg(not(feature = "board-axes"))]
        let mut compensation = {
            let mut thermometer = Tmp117::new(i2c, tmp117::DEFAULT_ADDRESS);
            let _ = thermometer.init();
            let mut front_end = FrontEnd::new(spi_device);
            let _ = front_end.init();
            CompensationLoop::new(model, config, thermometer, front_end, output)
        };
        #[cfg(all(feature = "board-qemu-serve", feature = "board-axes"))]
        let mut run_source = qemu::RunSource::<3>::open();
        #[cfg(all(feature = "board-qemu-serve", feature = "board-axes"))]
        let coil_temps = run_source.next(0).map(core::cell::Cell::new);
        #[cfg(all(feature = "board-qemu", not(feature = "board-qemu-serve"), feature = "board-axes"))]
        let coil_temps = [0, 1, 2].map(|axis| core::cell::Cell::new(qemu::axis_sample(0, axis)));
        #[cfg(all(feature = "board-qemu", feature = "board-axes"))]
        let coil_buses = [0, 1, 2].map(|axis| qemu::thermometer_bus(&coil_temps[axis]));
        #[cfg(all(feature = "board-qemu", feature = "board-axes"))]
        let coil_addresses = [tmp117::DEFAULT_ADDRESS; 3];
        // One TMP117 per coil on I2C1, each at its own address.
        #[cfg(all(not(feature = "board-qemu"), feature = "board-axes"))]
        let i2c_bus = AtomicCell::new(i2c);
        #[cfg(all(not(feature = "board-qemu"), feature = "board-axes"))]
        let coil_buses = [0, 1, 2].map(|_| embedded_hal_bus::i2c::AtomicDevice::new(&i2c_bus));
        #[cfg(all(not(feature = "board-qemu"), feature = "board-axes"))]
        let coil_addresses = [0x48, 0x49, 0x4A];
        // The serving image's front ends answer from their coils' samples.
        #[cfg(all(feature = "board-qemu-serve", feature = "board-axes"))]
        let (_spi1, [spi_x, spi_y, spi_z]) = (
            (spi_x, spi_y, spi_z),
            [0, 1, 2].map(|axis| firmware::replay::EmulatedFrontEnd::new(&coil_temps[axis])),
        );
        #[cfg(feature = "board-axes")]
        let mut compensation = {
            let [bx, by, bz] = coil_buses;
            let mut thermometers = [
                Tmp117::new(bx, coil_addresses[0]),
                Tmp117::new(by, coil_addresses[1]),
                Tmp117::new(bz, coil_addresses[2]),
            ];
            for t in &mut thermometers {
                let _ = t.init();
            }
            let mut front_ends = [FrontEnd::new(spi_x), FrontEnd::new(spi_y), FrontEnd::new(spi_z)];
            for f in &mut front_ends {
                let _ = f.init();
            }
            CompensationLoop::new(model, config, thermometers, front_ends, output)
        };
        if boot_cause.is_some() {
            compensation.flag_next_frame(Flags::FAULT_RESET);
        }
        let mut pacer = Pacer::new(timer_hz, (timer_hz as f32 / GYRO_RATE_HZ) as u32, hw::Tim2Clock::now());
        let boot = Boot {
            cause: reset_cause,
            flags: reset_flags,
            fault: fault_record,
            on_crystal: clocks.on_crystal,
        };
        // The health report after every reset, before the first output frame.
        send_health!(boot, compensation, store, pacer);
        let mut bench = Bench::default();
        // SysTick wakes the loop every millisecond (a silent data-ready line is noticed).
        core.SYST
            .set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        core.SYST
            .set_reload((core_hz / 1000).saturating_sub(1).min(0x00FF_FFFF));
        core.SYST.clear_current();
        core.SYST.enable_interrupt();
        core.SYST.enable_counter();
        // SAFETY: the handlers' state is in place; enabling their interrupts is all that is left.
        unsafe {
            core.NVIC.set_priority(pac::Interrupt::EXTI0, 0x40);
            core.NVIC.set_priority(pac::Interrupt::USART1, 0x80);
            cortex_m::peripheral::NVIC::unmask(pac::Interrupt::EXTI0);
            cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1);
        }
        // A data-ready line already high (the front end kept its sample over
        // an MCU-only reset) gives no rising edge: take it as one.
        let data_ready_high = cortex_m::interrupt::free(|cs| {
            DATA_READY
                .borrow(cs)
                .try_borrow()
                .ok()
                .as_deref()
                .and_then(Option::as_ref)
                .is_some_and(|d| d.pin.is_high())
        });
        if data_ready_high {
            cortex_m::peripheral::NVIC::pend(pac::Interrupt::EXTI0);
        }
        #[cfg(feature = "board-qemu")]
        let mut run = qemu::Run::start(dp.TIM3, &mut core.NVIC, (timer_hz as f32 / GYRO_RATE_HZ) as u32);
        // The closure below takes the emulated thermometers' readings by reference.
        #[cfg(all(feature = "board-qemu", not(feature = "board-axes")))]
        let loop_temp = &loop_temp;
        #[cfg(all(feature = "board-qemu", feature = "board-axes"))]
        let coil_temps = &coil_temps;
        run_forever(move || {
            // One step per pass for the newest data-ready edge (or the
            // silence); the watchdog is fed by steps only.
            pacing::serve_samples(
                &mut pacer,
                || uart::dequeue(&mut stamp_consumer),
                hw::Tim2Clock::now(),
                &mut watchdog,
                |tick| {
                    let started = DWT::cycle_count();
                    compensation.step_at(tick.seq, tick.dt_s);
                    if let Some(stats) = bench.record(DWT::cycle_count().wrapping_sub(started)) {
                        log!(
                            "bench: {=u32} steps, cycles min {=u32} mean {=u32} max {=u32}",
                            stats.steps,
                            stats.min,
                            stats.mean(),
                            stats.max
                        );
                        let mut report = [0u8; 24];
                        if let Some(n) = stats.encode_report(&mut report) {
                            write_frame(compensation.output_mut(), report.get(..n).unwrap_or(&[]));
                        }
                    }
                    #[cfg(all(feature = "board-qemu-serve", not(feature = "board-axes")))]
                    loop_temp.set(run_source.next(tick.seq)[0]);
                    #[cfg(all(
                        feature = "board-qemu",
                        not(feature = "board-qemu-serve"),
                        not(feature = "board-axes")
                    ))]
                    loop_temp.set(qemu::axis_sample(tick.seq, 0));
                    #[cfg(all(feature = "board-qemu-serve", feature = "board-axes"))]
                    for (cell, sample) in coil_temps.iter().zip(run_source.next(tick.seq)) {
                        cell.set(sample);
                    }
                    #[cfg(all(feature = "board-qemu", not(feature = "board-qemu-serve"), feature = "board-axes"))]
                    for (axis, cell) in coil_temps.iter().enumerate() {
                        cell.set(qemu::axis_sample(tick.seq, axis));
                    }
                },
            );
            // Commands between samples.
            while let Some(byte) = uart::dequeue(&mut in_consumer) {
                let (command, status) = match commands.push(byte) {
                    None => continue,
                    Some(Received::Rejected(status)) => (0, status),
                    // Answered by its report after the timed steps.
                    Some(Received::Command(&[CMD_BENCH])) => {
                        bench.start();
                        continue;
                    }
                    Some(Received::Command(&[CMD_HEALTH])) => {
                        send_health!(boot, compensation, store, pacer);
                        continue;
                    }
                    Some(Received::Command(payload)) => {
                        // The flash driver runs the watchdog at its install period around the erase.
                        watchdog.feed();
                        let mut status = UpdateStatus::UnknownCommand;
                        // The filters restart only for a model actually installed.
                        compensation.update_model_if(|model| {
                            status = update::run_in_place(&mut store, payload, model);
                            status == UpdateStatus::Installed
                        });
                        watchdog.feed();
                        log!(
                            "update: status {=u8}, model loaded {=bool}",
                            status as u8,
                            store.model_loaded()
                        );
                        (payload.first().copied().unwrap_or(0), status)
                    }
                };
                let mut reply = [0u8; 8];
                if let Some(n) = update::encode_reply(command, status, &mut reply) {
                    write_frame(compensation.output_mut(), reply.get(..n).unwrap_or(&[]));
                }
                #[cfg(feature = "board-qemu")]
                run.replied(status);
            }
            #[cfg(feature = "board-qemu")]
            run.check(&compensation.stats());
            // Sleep only if no interrupt queued work since the checks above:
            // with interrupts masked, an edge or byte that arrives now stays
            // pending and ends the WFI at once (unmasked, its handler could
            // run between the check and the WFI, and the stamp would wait a
            // whole sample period for the next wake-up). SysTick ends it
            // within a millisecond in any case.
            cortex_m::interrupt::free(|_| {
                if !stamp_consumer.ready() && !in_consumer.ready() {
                    cortex_m::asm::wfi();
                }
            });
        })
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the stm32f405 board runs on the MCU: see docs/firmware.md (cargo run with probe-rs)");
}
