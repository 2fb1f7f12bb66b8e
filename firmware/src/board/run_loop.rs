//! The board's run loop as host code: what `Board::run` does between its
//! wiring and its sleep, written over the library's traits, so that the
//! fault campaign (`firmware-harness/tests/board_faults`) runs the very
//! loop the image runs, pass by pass, against simulated peripherals.
//!
//! [`BoardLoop::start`] is the start of `Board::run` (the boot report, the
//! model from its slots, the sensors' init, the pacer, the health report);
//! [`BoardLoop::serve_once`] is one pass of its loop (one step per
//! data-ready stamp or silence, then the commands between samples, then
//! the image's hooks); [`BoardLoop::idle`] is the check the image sleeps
//! on. On the MCU `Board::run` wires TIM2, the DWT cycle counter, the
//! interrupt handlers' queues and counters ([`LoopPlatform`]) to it and
//! calls `serve_once` forever, sleeping when `idle`.

use embedded_hal::i2c::I2c;
use embedded_hal::spi::SpiDevice;
use embedded_io::Write;
use gyro_wire::health::{BOARD_ON_HSI, FirmwareVersion, HEALTH_FRAME_LEN, HealthCounters, HealthReport, ResetCause};
use heapless::spsc::Consumer;
use rbf_core::{CompensatorConfig, Flags};

use super::timing::{self, ClockTree};
use crate::bench::{Bench, CycleStats};
use crate::clock::Clock;
use crate::commands::{self, Report};
use crate::compensation::{CompensationLoop, InPlaceModel, LoopConfig, LoopStats, ModelHolder, write_frame};
use crate::fault::{self, FaultRecord};
use crate::flash_ctl::{ControllerFlash, FlashRegisters};
use crate::frontend::FrontEnd;
use crate::health::brown_out_flag;
use crate::model_store::{MappedFlash, ModelStore, SlotLayout, StoredModel};
use crate::pacing::{Pacer, PacerCounters};
use crate::samples;
use crate::sensors::{AxisFrontEnds, AxisThermometers};
use crate::tmp117::Tmp117;
use crate::uart;
use crate::update::{CommandReceiver, UpdateStatus};
use crate::watchdog::Watchdog;

/// Front-end output data rate, Hz (paced by its crystal; data-ready marks each sample).
pub const GYRO_RATE_HZ: f32 = 1000.0;
/// Read the TMP117 every 125th sample: 8 Hz, its conversion rate at 8 averages.
pub const TEMP_READ_EVERY: u32 = 125;

/// An image's thermometers: one TMP117, or one per coil.
pub trait BoardThermometers: AxisThermometers {
    /// Tries each thermometer's init once (a failure is not fatal: the
    /// driver retries on each read, and the frames are flagged meanwhile).
    fn init_all(&mut self);
}

impl<I: I2c> BoardThermometers for Tmp117<I> {
    #[inline(always)]
    fn init_all(&mut self) {
        let _ = self.init();
    }
}

impl<I: I2c, const N: usize> BoardThermometers for [Tmp117<I>; N] {
    #[inline(always)]
    fn init_all(&mut self) {
        for t in self {
            let _ = t.init();
        }
    }
}

/// An image's rate front ends: one, or one per axis.
pub trait BoardFrontEnds: AxisFrontEnds {
    /// Tries each front end's init once (retried on reads, as the thermometers').
    fn init_all(&mut self);
    /// Initialisations so far, every front end's (the health report).
    fn inits(&self) -> u32;
}

impl<S: SpiDevice> BoardFrontEnds for FrontEnd<S> {
    #[inline(always)]
    fn init_all(&mut self) {
        let _ = self.init();
    }
    #[inline(always)]
    fn inits(&self) -> u32 {
        FrontEnd::inits(self)
    }
}

impl<S: SpiDevice, const N: usize> BoardFrontEnds for [FrontEnd<S>; N] {
    #[inline(always)]
    fn init_all(&mut self) {
        for f in self {
            let _ = f.init();
        }
    }
    #[inline(always)]
    fn inits(&self) -> u32 {
        self.iter().map(FrontEnd::inits).sum::<u32>()
    }
}

/// The flash of the model slots as the health report sees it.
pub trait FlashHealth {
    /// Flash operations that failed so far.
    fn errors(&self) -> u32;
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> FlashHealth for ControllerFlash<R, C, W> {
    #[inline(always)]
    fn errors(&self) -> u32 {
        ControllerFlash::errors(self)
    }
}

/// What the loop reads from the chip beside its sensors: TIM2, the cycle
/// counter, the stack's peak and the counters the interrupt handlers and
/// the I2C bus recovery keep (statics on the MCU; simulated on the host).
pub trait LoopPlatform {
    /// The data-ready stamps' timer now, ticks.
    fn now_ticks(&mut self) -> u32;
    /// A free-running cycle counter (the `bench` command's).
    fn cycles(&mut self) -> u32;
    /// The stack's high-water mark so far, bytes.
    fn stack_peak_bytes(&self) -> u32;
    /// I2C bus recoveries, the one at boot included.
    fn i2c_recoveries(&self) -> u32;
    /// Command bytes lost (receive errors, a full receive queue).
    fn rx_overruns(&self) -> u32;
    /// Data-ready stamps lost to a full stamp queue.
    fn stamp_overruns(&self) -> u32;
}

/// What an image adds to the board's loop, pass by pass (none on the
/// chip: `()`; the QEMU images' emulated sensors and run end; the fault
/// campaign's records).
pub trait LoopHooks {
    /// Sample `seq` was compensated and its frame queued.
    #[inline(always)]
    fn stepped(&mut self, seq: u32) {
        let _ = seq;
    }
    /// The `bench` command's last timed step: its statistics (the report frame is queued).
    #[inline(always)]
    fn benched(&mut self, stats: &CycleStats) {
        let _ = stats;
    }
    /// A command was answered with `status`; whether a model runs after it.
    #[inline(always)]
    fn replied(&mut self, status: UpdateStatus, model_loaded: bool) {
        let _ = (status, model_loaded);
    }
    /// One pass of the loop is done; `stats` are the loop's counters.
    #[inline(always)]
    fn served(&mut self, stats: &LoopStats) {
        let _ = stats;
    }
}

/// The gyro board's own image: nothing added.
impl LoopHooks for () {}

/// What the boot found out about the last reset.
#[derive(Clone, Copy, Debug)]
pub struct BootState {
    /// Why the chip last reset.
    pub cause: ResetCause,
    /// RCC_CSR's reset flags (its top byte).
    pub flags: u8,
    /// The fault record kept across the reset, if a fault caused it.
    pub fault: Option<FaultRecord>,
    /// The clock tree the setup ended in.
    pub tree: ClockTree,
    /// FLASH_OPTCR at boot (its brown-out level).
    pub option_bytes: u32,
}

/// The parts `Board::run` hands the loop at its start.
pub struct LoopParts<'a, M, T, R, W, F, D, P, H> {
    /// The boot's findings.
    pub boot: BootState,
    /// The boot report's cause (a fault or watchdog reset before this boot).
    pub boot_cause: Option<FaultRecord>,
    /// The model's storage (decoded in place from the slots).
    pub model: &'a mut M,
    /// The command bytes' buffer.
    pub receiver: &'a mut CommandReceiver,
    /// The model slots' flash and where they lie in it.
    pub flash: F,
    /// The slots in `flash`.
    pub slots: SlotLayout,
    /// The image's thermometers.
    pub thermometers: T,
    /// The image's front ends.
    pub front_ends: R,
    /// Where the frames go (the transmit queue USART1's handler drains).
    pub output: W,
    /// The data-ready stamps EXTI0's handler queues.
    pub stamps: Consumer<'a, u32>,
    /// The command bytes USART1's handler queues.
    pub commands: Consumer<'a, u8>,
    /// The watchdog, fed by the steps.
    pub watchdog: D,
    /// TIM2, the cycle counter and the handlers' counters.
    pub platform: P,
    /// The stamps' timer rate, Hz.
    pub timer_hz: u32,
    /// The image's additions.
    pub hooks: H,
}

/// The board's loop after its start: the compensation loop on the model
/// from the slots, the pacer, the command path, the `bench` timing.
pub struct BoardLoop<'a, M, T, R, W, F, D, P, H, const K: usize, const N: usize> {
    compensation: CompensationLoop<T, R, W, InPlaceModel<'a, M>, K, N>,
    store: ModelStore<F>,
    receiver: &'a mut CommandReceiver,
    pacer: Pacer,
    bench: Bench,
    boot: BootState,
    stamps: Consumer<'a, u32>,
    commands: Consumer<'a, u8>,
    watchdog: D,
    platform: P,
    hooks: H,
    period_ticks: u32,
}

impl<'a, M, T, R, W, F, D, P, H, const K: usize, const N: usize> BoardLoop<'a, M, T, R, W, F, D, P, H, K, N>
where
    M: StoredModel,
    InPlaceModel<'a, M>: ModelHolder<K, N>,
    T: BoardThermometers,
    R: BoardFrontEnds,
    W: Write,
    F: MappedFlash + FlashHealth,
    D: Watchdog,
    P: LoopPlatform,
    H: LoopHooks,
{
    /// The start of `Board::run`: the boot report first (a fault or
    /// watchdog reset before this boot), the model from the newest
    /// committed slot (none or an invalid one is not fatal: every frame
    /// then carries flag 4), the sensors' init (failures not fatal
    /// either: the drivers retry on each read, the frames flagged
    /// meanwhile), the pacer, and the health report before the first
    /// output frame.
    #[inline(always)]
    pub fn start(parts: LoopParts<'a, M, T, R, W, F, D, P, H>) -> Self {
        let LoopParts {
            boot,
            boot_cause,
            model,
            receiver,
            flash,
            slots,
            mut thermometers,
            mut front_ends,
            mut output,
            stamps,
            commands,
            watchdog,
            mut platform,
            timer_hz,
            hooks,
        } = parts;
        if let Some(cause) = boot_cause {
            let mut report = [0u8; 16];
            if let Some(n) = fault::encode_boot_report(cause, boot.flags, &mut report) {
                write_frame(&mut output, report.get(..n).unwrap_or(&[]));
            }
        }
        let mut store = ModelStore::open_with(flash, slots, model);
        let loaded = store.load_into(model).is_ok();
        let model = InPlaceModel::new(model, loaded);
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(GYRO_RATE_HZ),
            temp_read_every: TEMP_READ_EVERY,
        };
        thermometers.init_all();
        front_ends.init_all();
        let mut compensation = CompensationLoop::new(model, config, thermometers, front_ends, output);
        if boot_cause.is_some() {
            compensation.flag_next_frame(Flags::FAULT_RESET);
        }
        let period_ticks = timing::sample_period_ticks(timer_hz, GYRO_RATE_HZ);
        let pacer = timing::sample_pacer(&boot.tree, timer_hz, period_ticks, platform.now_ticks());
        send_health(&boot, &mut compensation, &store, &pacer, &platform);
        BoardLoop {
            compensation,
            store,
            receiver,
            pacer,
            bench: Bench::default(),
            boot,
            stamps,
            commands,
            watchdog,
            platform,
            hooks,
            period_ticks,
        }
    }

    /// One pass of the loop: one step for the newest data-ready stamp (or
    /// for the silence; the watchdog is fed by steps only), then the
    /// commands the UART queued between samples (crate::commands), then
    /// the image's hooks.
    #[inline(always)]
    pub fn serve_once(&mut self) {
        let BoardLoop {
            compensation,
            store,
            receiver,
            pacer,
            bench,
            boot,
            stamps,
            commands,
            watchdog,
            platform,
            hooks,
            ..
        } = self;
        let now = platform.now_ticks();
        samples::serve_samples_timed(
            pacer,
            || uart::dequeue(stamps),
            now,
            watchdog,
            compensation,
            bench,
            || platform.cycles(),
            |seq, stats| {
                if let Some(stats) = stats {
                    hooks.benched(&stats);
                }
                hooks.stepped(seq);
            },
        );
        commands::serve_commands(
            || uart::dequeue(commands),
            receiver,
            compensation,
            store,
            watchdog,
            |report, compensation, store| match report {
                // Answered by its report after the timed steps.
                Report::Bench => bench.start(),
                Report::Health => send_health(boot, compensation, store, pacer, platform),
            },
            |status, store| hooks.replied(status, store.model_loaded()),
        );
        hooks.served(&compensation.stats());
    }

    /// Nothing queued for the loop: no stamp, no command byte (the image
    /// sleeps then, interrupts masked, until the next interrupt).
    #[inline(always)]
    pub fn idle(&self) -> bool {
        !self.stamps.ready() && !self.commands.ready()
    }

    /// Samples come every this many timer ticks.
    pub fn period_ticks(&self) -> u32 {
        self.period_ticks
    }

    /// The image's additions.
    pub fn hooks_mut(&mut self) -> &mut H {
        &mut self.hooks
    }

    /// The compensation loop (its counters, sensors and output).
    pub fn compensation(&mut self) -> &mut CompensationLoop<T, R, W, InPlaceModel<'a, M>, K, N> {
        &mut self.compensation
    }

    /// The model store (its slots and the running model's identity).
    pub fn store(&self) -> &ModelStore<F> {
        &self.store
    }

    /// The pacer's counters (glitches, synthetic steps, backlog).
    pub fn pacer_counters(&self) -> PacerCounters {
        self.pacer.counters()
    }

    /// Ends the loop (the fault campaign's runs): its sensors, output and model store.
    pub fn destroy(self) -> (T, R, W, ModelStore<F>) {
        let (thermometers, front_ends, output) = self.compensation.destroy();
        (thermometers, front_ends, output, self.store)
    }
}

/// Sends the health report: `boot`, then the counters of the loop
/// `compensation`, the model store `store`, the pacer `pacer` and the
/// platform's (the interrupt handlers', the bus recovery's, the stack's).
#[inline(never)]
fn send_health<F, T, R, W, MH, P, const K: usize, const N: usize>(
    boot: &BootState,
    compensation: &mut CompensationLoop<T, R, W, MH, K, N>,
    store: &ModelStore<F>,
    pacer: &Pacer,
    platform: &P,
) where
    F: MappedFlash + FlashHealth,
    T: AxisThermometers,
    R: BoardFrontEnds,
    W: Write,
    MH: ModelHolder<K, N>,
    P: LoopPlatform,
{
    let report = HealthReport {
        reset_cause: boot.cause,
        reset_flags: boot.flags,
        fault_pc: boot.fault.map_or(0, |r| r.pc),
        fault_lr: boot.fault.map_or(0, |r| r.lr),
        counters: health_counters(
            &compensation.stats(),
            &pacer.counters(),
            compensation.sensors().1.inits(),
            store.flash().errors(),
            platform,
        ),
        model: store.identity(),
        board_flags: if boot.tree.on_crystal { 0 } else { BOARD_ON_HSI } | brown_out_flag(boot.option_bytes),
        firmware_version: FirmwareVersion::CURRENT,
        stack_peak_bytes: platform.stack_peak_bytes(),
    };
    let mut frame = [0u8; HEALTH_FRAME_LEN];
    if let Some(n) = report.encode(&mut frame) {
        write_frame(compensation.output_mut(), frame.get(..n).unwrap_or(&[]));
    }
}

/// The counters of the health report, gathered from their owners.
pub fn health_counters<P: LoopPlatform>(
    stats: &LoopStats,
    pacer: &PacerCounters,
    front_end_inits: u32,
    flash_errors: u32,
    platform: &P,
) -> HealthCounters {
    let recoveries = platform.i2c_recoveries();
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
        overruns: platform.rx_overruns().wrapping_add(platform.stamp_overruns()),
        output_dropped: stats.output_errors,
        flash_errors,
    }
}
