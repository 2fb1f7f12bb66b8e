//! The board image over its wiring: setup ([`Board::setup`]: watchdog,
//! reset cause, clock tree, TIM2, SPI1, USART1 and its queues, the
//! data-ready line, the boot report) and the run loop ([`Board::run`]:
//! model store, sensors' init, pacing, commands, health); the interrupt
//! and exception handlers it starts are in `isr`. An image's
//! binary (`src/bin/`) only wires its sensors to the pieces `setup` hands
//! it and picks its model kind by type ([`BoardModel`]).
//!
//! - TMP117 on I2C1 (PB6 SCL, PB7 SDA, 400 kHz);
//! - IFOG front ends on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, chip selects
//!   PA4, PA3, PA2, mode 3, at most 10 MHz: 84 MHz / 16) with data-ready on
//!   PB0 (EXTI0, rising edge), 1 kHz;
//! - output frames on USART1 TX (PA9, 921 600 Bd, 8N1); model-update,
//!   bench and health commands on USART1 RX (PA10, pulled up), replies on
//!   TX (crate::update, crate::health);
//! - the model in flash slot MODEL_A (0x080C_0000) or MODEL_B (0x080E_0000),
//!   whichever holds the newest committed blob (crate::model_store).
//!
//! Timing (docs/firmware.md): the EXTI0 interrupt timestamps every
//! data-ready edge with TIM2 (32 bits at the 84 MHz timer clock) and queues
//! the stamp; the main loop takes stamps from the queue, derives dt and the
//! edge number from them (edges lost while the CPU stalled, as during a
//! flash erase, count and are flagged) and runs one compensation step per
//! stamp (crate::pacing: glitches rejected, a backlog counted as missed,
//! steps synthesised when data-ready falls silent; SysTick wakes the loop
//! every millisecond to notice). USART1's interrupt moves bytes between the
//! UART and two queues: frames out (crate::uart::FrameQueue, whole or
//! dropped and flagged) and command bytes in (overruns counted). The
//! independent watchdog starts before the clock tree (crate::watchdog:
//! ≥ 2 s at the fastest LSI, ≥ 4.5 s around a model install) and is fed
//! once per step. Every wait on I2C, the flash controller and the clock
//! setup is bounded (crate::i2c_master, crate::flash_ctl, `hw`). A
//! panic or HardFault records its cause in RAM that survives the reset
//! (crate::fault) and resets; the next boot reports it, and every boot
//! sends the health report (crate::health).
#![allow(unsafe_code)]

use core::sync::atomic::Ordering;

use cortex_m::peripheral::DWT;
#[cfg(feature = "board-debug")]
use defmt_rtt as _;
use embedded_hal::i2c::I2c;
use embedded_hal_bus::spi::{AtomicDevice, ExclusiveDevice};
use embedded_hal_bus::util::AtomicCell;
use heapless::spsc::{Consumer, Producer, Queue};
use rbf_core::Model;
use rbf_core::blob::axes::AxisModels;
use rbf_core::shared_basis::SharedAxisModels;
use stm32f4xx_hal::gpio::{Edge, ErasedPin, ExtiPin, Output, PA2, PA3, PA4, PinState, Speed};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::{Enable, Reset};
use stm32f4xx_hal::serial::RxListen;
use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};

#[cfg(not(feature = "board-qemu"))]
use super::chip as platform;
use super::hw;
use super::isr::{DataReadyIsr, RX_OVERRUNS, STAMP_OVERRUNS, UartIsr, hand_over, start_tx};
#[cfg(feature = "board-qemu")]
use super::qemu as platform;
pub use super::run_loop::{BoardFrontEnds, BoardThermometers, FlashHealth, GYRO_RATE_HZ, LoopHooks};
use super::run_loop::{BoardLoop, BootState, LoopParts, LoopPlatform};
use super::timing;
#[cfg(feature = "board-debug")]
use crate::compensation::LoopStats;
use crate::compensation::{InPlaceModel, ModelHolder};
use crate::fault::{self, FaultRecord};
use crate::frontend::{self, FrontEnd};
use crate::health::reset_cause_at_boot;
use crate::model_store::{MappedFlash, SlotLayout, StoredModel};
use crate::tmp117::Tmp117;
use crate::uart::FrameQueue;
use crate::update::CommandReceiver;
#[cfg(feature = "board-debug")]
use crate::update::UpdateStatus;
use crate::watchdog;

pub use platform::I2c1;

/// The flash an image keeps its two model slots in: the chip's flash
/// through its controller ([`super::chip::SlotFlash`]), or what a test
/// image emulates (the QEMU images' NOR flash in RAM, `firmware-harness`).
/// Its failed operations count in the health report ([`FlashHealth`]).
pub trait BoardFlash: MappedFlash + FlashHealth + Sized {
    /// Where the two slots lie in it.
    const SLOTS: SlotLayout;
    /// The flash, ready for the model store; `tim2` bounds its waits.
    fn open(tim2: hw::Tim2Clock) -> Self;
}

/// Logs over RTT in the debug image (`board-debug`); nothing otherwise.
macro_rules! log {
    ($($arg:tt)*) => {
        #[cfg(feature = "board-debug")]
        defmt::info!($($arg)*);
    };
}

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

/// The model kinds a board image runs, each decoded in place into a
/// `static` of its own (`singleton!`, all bits zero: .bss, no flash): a
/// single gyro's [`Model`], an IMU's [`AxisModels`] of
/// [`crate::AXIS_CENTERS`] centres per axis, or one [`SharedAxisModels`]
/// basis of [`crate::SHARED_AXIS_CENTERS`] centres.
pub trait BoardModel: StoredModel + 'static {
    /// The image's model storage: the first call's; `None` on any later one.
    fn storage() -> Option<&'static mut Self>;
}

impl BoardModel for Model {
    #[inline(always)]
    fn storage() -> Option<&'static mut Self> {
        cortex_m::singleton!(: Model = Model::EMPTY)
    }
}

impl BoardModel for AxisModels<{ crate::AXIS_CENTERS }> {
    #[inline(always)]
    fn storage() -> Option<&'static mut Self> {
        cortex_m::singleton!(: AxisModels<{ crate::AXIS_CENTERS }> = AxisModels::EMPTY)
    }
}

impl BoardModel for SharedAxisModels<{ crate::SHARED_AXIS_CENTERS }> {
    #[inline(always)]
    fn storage() -> Option<&'static mut Self> {
        cortex_m::singleton!(: SharedAxisModels<{ crate::SHARED_AXIS_CENTERS }> = SharedAxisModels::EMPTY)
    }
}

/// What an image adds to the board's loop (none on the chip: `()`; the
/// QEMU images' sensors and data-ready source, `firmware_harness::qemu`):
/// its start, and what it adds pass by pass ([`LoopHooks`]).
pub trait Hooks: LoopHooks {
    /// The interrupts are enabled, the loop is about to start; samples
    /// come every `period_ticks` TIM2 ticks.
    #[inline(always)]
    fn start(&mut self, nvic: &mut cortex_m::peripheral::NVIC, period_ticks: u32) {
        let _ = (nvic, period_ticks);
    }
}

/// The gyro board's own image: nothing added.
impl Hooks for () {}

/// The debug image's hooks: the image's, and the bench statistics and
/// command statuses logged over RTT.
#[cfg(feature = "board-debug")]
struct Logged<H>(H);

#[cfg(feature = "board-debug")]
impl<H: LoopHooks> LoopHooks for Logged<H> {
    fn stepped(&mut self, seq: u32) {
        self.0.stepped(seq);
    }
    fn benched(&mut self, stats: &crate::bench::CycleStats) {
        log!(
            "bench: {=u32} steps, cycles min {=u32} mean {=u32} max {=u32}",
            stats.steps,
            stats.min,
            stats.mean(),
            stats.max
        );
        self.0.benched(stats);
    }
    fn replied(&mut self, status: UpdateStatus, model_loaded: bool) {
        log!(
            "command: status {=u8}, model loaded {=bool}",
            status as u8,
            model_loaded
        );
        self.0.replied(status, model_loaded);
    }
    fn served(&mut self, stats: &LoopStats) {
        self.0.served(stats);
    }
}

/// The chip under the loop: TIM2, the DWT cycle counter, the stack's
/// painted peak, and the counters of the interrupt handlers and of I2C1's
/// bus recovery.
struct Chip;

impl LoopPlatform for Chip {
    #[inline(always)]
    fn now_ticks(&mut self) -> u32 {
        hw::Tim2Clock::now()
    }
    #[inline(always)]
    fn cycles(&mut self) -> u32 {
        DWT::cycle_count()
    }
    #[inline(always)]
    fn stack_peak_bytes(&self) -> u32 {
        super::stack_peak_bytes() as u32
    }
    #[inline(always)]
    fn i2c_recoveries(&self) -> u32 {
        hw::I2C_RECOVERIES.load(Ordering::Relaxed)
    }
    #[inline(always)]
    fn rx_overruns(&self) -> u32 {
        RX_OVERRUNS.load(Ordering::Relaxed)
    }
    #[inline(always)]
    fn stamp_overruns(&self) -> u32 {
        STAMP_OVERRUNS.load(Ordering::Relaxed)
    }
}

/// Busy-waits on the core clock: the SPI devices' delay (embedded-hal-bus's
/// `NoDelay` would link a panic for a delay operation).
#[derive(Clone, Copy, Debug)]
pub struct CycleDelay {
    core_hz: u32,
}

impl embedded_hal::delay::DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        cortex_m::asm::delay(timing::delay_cycles(ns, self.core_hz));
    }
}

/// Everything the board does after init: `serve` once per wake-up,
/// forever. Its own function (never inlined), so that `cargo xtask
/// check-board-panics` can prove from the image that no panic is
/// reachable from here or from the interrupt handlers.
/// The loop's state stays where `run` built it (`serve` borrows it: no
/// second copy of it on the stack).
#[inline(never)]
fn run_forever(serve: &mut impl FnMut()) -> ! {
    loop {
        serve();
    }
}

/// Sleeps until an interrupt is pending (called with interrupts masked).
/// The debug image does not sleep: a probe keeps DBG_SLEEP set for RTT,
/// and with it a WFI from flash can fetch wrongly on wake-up (setup clears
/// the bit in every other image).
#[inline(always)]
fn sleep_until_interrupt() {
    #[cfg(not(feature = "board-debug"))]
    cortex_m::asm::wfi();
}

/// Stops for good (a setup step that cannot fail failed): the watchdog resets.
pub fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// The front ends' chip selects on SPI1 (x, y, z of a three-axis IMU;
/// a single gyro's is PA4): push-pull outputs, high (deselected) from the
/// moment setup makes them outputs.
pub struct ChipSelects {
    /// Axis x's (or the single front end's).
    pub pa4: PA4<Output>,
    /// Axis y's.
    pub pa3: PA3<Output>,
    /// Axis z's.
    pub pa2: PA2<Output>,
}

/// What [`Board::setup`] hands an image to wire its sensors to.
pub struct Wiring {
    /// I2C1 (PB6 SCL, PB7 SDA) through the bounded master, the bus
    /// recovered (QEMU: none, `qemu::NoI2c`).
    pub i2c: I2c1,
    /// SPI1, mode 3, at most 10 MHz.
    pub spi: Spi<pac::SPI1>,
    /// The front ends' chip select pins.
    pub cs: ChipSelects,
    /// A delay on the core clock for the SPI devices.
    pub delay: CycleDelay,
}

/// The board after [`Board::setup`], which [`Board::run`] runs; its
/// model slots in the flash `F` (the chip's own unless an image picks
/// another, [`Board::setup_with_slots`]).
pub struct Board<F = super::chip::SlotFlash> {
    /// TIM2's rate, Hz: the pacer's and the data-ready stamps' time base
    /// (the clock tree's; an image may set another, as QEMU's serving image does).
    pub timer_hz: u32,
    core_hz: u32,
    core: cortex_m::Peripherals,
    watchdog: hw::Iwdg,
    boot: BootState,
    boot_cause: Option<FaultRecord>,
    out_producer: Producer<'static, u8>,
    in_consumer: Consumer<'static, u8>,
    stamp_consumer: Consumer<'static, u32>,
    /// The data-ready line was high when setup armed its interrupt.
    data_ready_high: bool,
    flash: F,
}

/// The single gyro's front end: SPI1 with chip select PA4.
pub type SingleFrontEnd = FrontEnd<ExclusiveDevice<Spi<pac::SPI1>, PA4<Output>, CycleDelay>>;

/// A front end of a three-axis IMU: SPI1 shared, its own chip select.
pub type AxisFrontEnd<'a> = FrontEnd<AtomicDevice<'a, Spi<pac::SPI1>, ErasedPin<Output>, CycleDelay>>;

/// The single gyro's front end on SPI1, chip select PA4.
#[inline(always)]
pub fn single_front_end(spi: Spi<pac::SPI1>, cs: PA4<Output>, delay: CycleDelay) -> SingleFrontEnd {
    let Ok(device) = ExclusiveDevice::new(spi, cs, delay);
    FrontEnd::new(device)
}

/// A three-axis IMU's front ends on one SPI1 `bus` (chip selects PA4 x,
/// PA3 y, PA2 z): a busy bus is an error the loop flags, never a wait or a panic.
#[inline(always)]
pub fn axis_front_ends<'a>(
    bus: &'a AtomicCell<Spi<pac::SPI1>>,
    cs: ChipSelects,
    delay: CycleDelay,
) -> [AxisFrontEnd<'a>; 3] {
    let (Ok(x), Ok(y), Ok(z)) = (
        AtomicDevice::new(bus, cs.pa4.erase(), delay),
        AtomicDevice::new(bus, cs.pa3.erase(), delay),
        AtomicDevice::new(bus, cs.pa2.erase(), delay),
    );
    [FrontEnd::new(x), FrontEnd::new(y), FrontEnd::new(z)]
}

/// A three-axis IMU's coil TMP117s on one I2C `bus`, each at its own
/// address (0x48 x, 0x49 y, 0x4A z).
#[inline(always)]
pub fn coil_thermometers<B: I2c>(bus: &AtomicCell<B>) -> [Tmp117<embedded_hal_bus::i2c::AtomicDevice<'_, B>>; 3] {
    let [bx, by, bz] = [0, 1, 2].map(|_| embedded_hal_bus::i2c::AtomicDevice::new(bus));
    [Tmp117::new(bx, 0x48), Tmp117::new(by, 0x49), Tmp117::new(bz, 0x4A)]
}

impl Board {
    /// Sets the board up with its model slots in the chip's flash
    /// ([`Board::setup_with_slots`]).
    #[inline(always)]
    pub fn setup() -> (Board, Wiring) {
        Board::setup_with_slots()
    }
}

impl<F: BoardFlash> Board<F> {
    /// Sets the board up, every wait bounded: the watchdog first, the
    /// reset cause, the clock tree, TIM2 free-running, I2C1 (its bus
    /// recovered), SPI1, USART1 with its interrupt's queues, the
    /// data-ready line's interrupt, the model slots' flash `F`. The
    /// interrupts are still masked.
    #[inline(always)]
    pub fn setup_with_slots() -> (Self, Wiring) {
        // Every image paints its stack first: the health report carries its peak.
        super::paint_stack();
        let Some(mut dp) = pac::Peripherals::take() else { halt() };
        let Some(mut core) = cortex_m::Peripherals::take() else {
            halt()
        };
        // The watchdog first: a dead crystal or a stuck setup wait must not hang the board.
        let _ = hw::Iwdg::start(watchdog::running_setting());
        let watchdog = hw::Iwdg;
        // No debug clocks kept running in sleep: with DBG_SLEEP set (by a
        // probe that was attached), a WFI from flash right after masking
        // interrupts can fetch a wrong instruction on wake-up (the STM32
        // WFI erratum; docs/firmware.md, "Sleep and the debug probe"). The
        // debug image keeps them for RTT and never sleeps instead.
        #[cfg(not(feature = "board-debug"))]
        dp.DBGMCU.cr().modify(|_, w| {
            w.dbg_sleep()
                .clear_bit()
                .dbg_stop()
                .clear_bit()
                .dbg_standby()
                .clear_bit()
        });
        let rcc_csr = dp.RCC.csr().read().bits();
        let reset_flags = (rcc_csr >> 24) as u8;
        let watchdog_reset = dp.RCC.csr().read().wdgrstf().bit_is_set();
        dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
        let fault_record = super::take_fault();
        let reset_cause = reset_cause_at_boot(fault_record, rcc_csr);
        let boot_cause = fault::boot_cause(fault_record, watchdog_reset);

        // The board's own clock setup, every wait bounded (a dead crystal:
        // the HSI); QEMU has no clock controller: the reset clocks.
        let clocks = platform::clocks();
        // The HAL's RCC only enables and resets peripherals here: it
        // believes in the reset clocks, so the SPI divider and the UART's
        // baud rate are set again below from `clocks`.
        let mut rcc = dp.RCC.constrain();
        // The cycle counter the `bench` command reads (crate::bench).
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let mut syscfg = dp.SYSCFG.constrain(&mut rcc);

        // TIM2 free-running over 32 bits at the timer clock: the data-ready
        // timestamps and the clock of every bounded wait.
        let timer_hz = clocks.timclk1_hz;
        pac::TIM2::enable(&mut rcc);
        pac::TIM2::reset(&mut rcc);
        dp.TIM2.arr().write(|w| unsafe { w.bits(u32::MAX) });
        dp.TIM2.cr1().modify(|_, w| w.cen().set_bit());
        let tim2 = hw::Tim2Clock {
            ticks_per_us: timing::ticks_per_us(timer_hz),
        };

        let i2c = platform::i2c1(gpiob.pb6, gpiob.pb7, &mut rcc, &clocks, tim2);
        let mode = Mode {
            polarity: Polarity::IdleHigh,
            phase: Phase::CaptureOnSecondTransition,
        };
        // The chip selects high (no front end selected) before SPI1 exists.
        let cs = ChipSelects {
            pa4: gpioa.pa4.into_push_pull_output_in_state(PinState::High),
            pa3: gpioa.pa3.into_push_pull_output_in_state(PinState::High),
            pa2: gpioa.pa2.into_push_pull_output_in_state(PinState::High),
        };
        // SCK and MOSI at High speed: at the reset's Low speed their edges
        // are too slow for 5.25 MHz (the HAL's note on `Spi::new`: a wrong
        // last bit in received bytes).
        let sck = gpioa.pa5.into_alternate::<5>().speed(Speed::High);
        let mosi = gpioa.pa7.into_alternate::<5>().speed(Speed::High);
        let spi = Spi::new(
            dp.SPI1,
            (Some(sck), Some(gpioa.pa6), Some(mosi)),
            mode,
            frontend::spi_clock_hz(rcc.clocks.pclk2().raw(), SPI_MAX_HZ).Hz(),
            &mut rcc,
        );
        hw::set_spi1_divider(&clocks, SPI_MAX_HZ);
        // RX pulled up: an unconnected or floating line reads idle, not noise.
        let rx_pin = gpioa.pa10.internal_pull_up(true);
        let Ok(serial) = dp.USART1.serial::<u8>((gpioa.pa9, rx_pin), 921_600.bps(), &mut rcc) else {
            halt()
        };
        hw::set_usart1_baud(&clocks, 921_600);
        let (tx, mut rx) = serial.split();
        rx.listen();
        let flash = F::open(tim2);

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
        let (incoming, in_consumer) = in_queue.split();
        let (stamps, stamp_consumer) = stamp_queue.split();

        let mut data_ready = gpiob.pb0.into_pull_down_input();
        data_ready.make_interrupt_source(&mut syscfg);
        data_ready.trigger_on_edge(&mut dp.EXTI, Edge::Rising);
        data_ready.enable_interrupt(&mut dp.EXTI);
        // A data-ready line already high (the front end kept its sample
        // over an MCU-only reset) gives no rising edge: `run` takes it as one.
        let data_ready_high = data_ready.is_high();
        let Some(uart_isr) = cortex_m::singleton!(: UartIsr = UartIsr {
            tx,
            rx,
            outgoing,
            incoming,
        }) else {
            halt()
        };
        let Some(data_ready_isr) = cortex_m::singleton!(: DataReadyIsr = DataReadyIsr {
            pin: data_ready,
            stamps,
        }) else {
            halt()
        };
        hand_over(uart_isr, data_ready_isr);
        let core_hz = clocks.sysclk_hz;
        let wiring = Wiring {
            i2c,
            spi,
            cs,
            delay: CycleDelay { core_hz },
        };
        let board = Board {
            core_hz,
            timer_hz,
            core,
            watchdog,
            boot: BootState {
                cause: reset_cause,
                flags: reset_flags,
                fault: fault_record,
                tree: clocks,
                option_bytes: dp.FLASH.optcr().read().bits(),
            },
            boot_cause,
            out_producer,
            in_consumer,
            stamp_consumer,
            data_ready_high,
            flash,
        };
        (board, wiring)
    }

    /// Runs the board for good: the boot report, the model of kind `M`
    /// from its flash slots, the sensors' init, the health report, the
    /// interrupts, then one compensation step per data-ready edge and the
    /// commands between them (see the module docs), each pass
    /// [`BoardLoop::serve_once`], the host-tested loop. `hooks` adds what
    /// an image needs around that (none on the chip).
    #[inline(always)]
    pub fn run<M, T, R, H, const K: usize, const N: usize>(self, thermometers: T, front_ends: R, hooks: H) -> !
    where
        M: BoardModel,
        for<'m> InPlaceModel<'m, M>: ModelHolder<K, N>,
        T: BoardThermometers,
        R: BoardFrontEnds,
        H: Hooks,
    {
        let Board {
            timer_hz,
            core_hz,
            mut core,
            watchdog,
            boot,
            boot_cause,
            out_producer,
            in_consumer,
            stamp_consumer,
            data_ready_high,
            flash,
        } = self;
        // Command bytes collect in a static of their own (4 KiB: off the stack).
        let (Some(model), Some(receiver)) = (
            M::storage(),
            cortex_m::singleton!(: CommandReceiver = CommandReceiver::new()),
        ) else {
            halt()
        };
        #[cfg(feature = "board-debug")]
        let hooks = Logged(hooks);
        let mut board_loop: BoardLoop<'static, M, T, R, _, F, _, _, _, K, N> = BoardLoop::start(LoopParts {
            boot,
            boot_cause,
            model,
            receiver,
            flash,
            slots: F::SLOTS,
            thermometers,
            front_ends,
            output: FrameQueue::new(out_producer, start_tx),
            stamps: stamp_consumer,
            commands: in_consumer,
            watchdog,
            platform: Chip,
            timer_hz,
            hooks,
        });
        log!(
            "boot: reset flags {=u8:#x}, fault or watchdog reset {=bool}, model loaded {=bool}",
            boot.flags,
            boot_cause.is_some(),
            board_loop.store().model_loaded()
        );
        // SysTick wakes the loop every millisecond (a silent data-ready line is noticed).
        core.SYST
            .set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        core.SYST.set_reload(timing::systick_reload_1ms(core_hz));
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
        if data_ready_high {
            cortex_m::peripheral::NVIC::pend(pac::Interrupt::EXTI0);
        }
        let period_ticks = board_loop.period_ticks();
        #[cfg(feature = "board-debug")]
        board_loop.hooks_mut().0.start(&mut core.NVIC, period_ticks);
        #[cfg(not(feature = "board-debug"))]
        board_loop.hooks_mut().start(&mut core.NVIC, period_ticks);
        run_forever(&mut || {
            board_loop.serve_once();
            // Sleep only if no interrupt queued work since the checks above:
            // with interrupts masked, an edge or byte that arrives now stays
            // pending and ends the WFI at once (unmasked, its handler could
            // run between the check and the WFI, and the stamp would wait a
            // whole sample period for the next wake-up). SysTick ends it
            // within a millisecond in any case.
            cortex_m::interrupt::free(|_| {
                if board_loop.idle() {
                    sleep_until_interrupt();
                }
            });
        })
    }
}
