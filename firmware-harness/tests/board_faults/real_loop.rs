//! The board's own run loop on simulated peripherals: `firmware::board::run_loop`'s
//! [`BoardLoop`], the code `Board::run` runs on the MCU (its start, then
//! `serve_once` pass by pass, sleeping when `idle`), with the bodies of the
//! USART1 and EXTI0 handlers (`firmware::interrupts`) run as their
//! interrupts arrive between passes: every data-ready edge stamped into
//! the board's stamp queue, every received byte through USART1's receive
//! logic into the command queue, and the transmit queue drained through
//! its transmit logic. Nothing of the loop is re-implemented here.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;
use std::sync::atomic::{AtomicU32, Ordering};

use firmware::board::run_loop::{BoardLoop, BootState, LoopHooks, LoopParts, LoopPlatform};
use firmware::board::timing;
use firmware::compensation::LoopStats;
use firmware::flash_ctl::ControllerFlash;
use firmware::frontend::FrontEnd;
use firmware::health::reset_cause_at_boot;
use firmware::i2c_master::BoundedI2c;
use firmware::interrupts::{self, Transmit};
use firmware::tmp117::Tmp117;
use firmware::uart::FrameQueue;
use firmware::update::{CommandReceiver, UpdateStatus};
use firmware::watchdog::LSI_FASTEST_HZ;
use gyro_wire::cobs::cobs_decode_in_place;
use gyro_wire::frame::OutputFrame;
use gyro_wire::health::{HealthReport, ResetCause};
use heapless::spsc::{Consumer, Producer, Queue};
use rbf_core::Model;

use crate::sim::{FakeI2c, FakeSpi, FlashSim, FrontEndSim, I2cSim, SimClock, SimWatchdog, UartRxSim, UartTxSim};

/// The board's queue sizes (`firmware::board`'s `TX_QUEUE`, `RX_QUEUE`, `STAMP_QUEUE`).
const TX_QUEUE: usize = 512;
const RX_QUEUE: usize = 256;
const STAMP_QUEUE: usize = 16;

/// The counters the interrupt handlers keep (statics on the MCU).
#[derive(Debug, Default)]
pub struct HandlerCounters {
    /// USART1's: command bytes lost.
    pub rx_overruns: AtomicU32,
    /// EXTI0's: stamps lost to a full queue.
    pub stamp_overruns: AtomicU32,
}

/// TIM2 (1 tick per simulated µs), a cycle counter, the handlers' counters
/// and the I2C bus's recoveries (each ends in a peripheral reset).
pub struct SimPlatform {
    clock: SimClock,
    i2c: Rc<RefCell<I2cSim>>,
    counters: &'static HandlerCounters,
}

impl LoopPlatform for SimPlatform {
    fn now_ticks(&mut self) -> u32 {
        self.clock.now_us() as u32
    }
    fn cycles(&mut self) -> u32 {
        self.clock.now_us() as u32
    }
    fn stack_peak_bytes(&self) -> u32 {
        4096
    }
    fn i2c_recoveries(&self) -> u32 {
        self.i2c.borrow().resets
    }
    fn rx_overruns(&self) -> u32 {
        self.counters.rx_overruns.load(Ordering::Relaxed)
    }
    fn stamp_overruns(&self) -> u32 {
        self.counters.stamp_overruns.load(Ordering::Relaxed)
    }
}

/// What the loop told its hooks.
#[derive(Debug, Default)]
pub struct Heard {
    /// Steps, by sequence number.
    pub steps: u32,
    /// Replies: status and whether a model ran after it.
    pub replies: Vec<(UpdateStatus, bool)>,
    /// The `bench` command's statistics, each time it ended.
    pub benched: Vec<firmware::bench::CycleStats>,
    /// Passes of the loop.
    pub passes: u32,
    /// The loop's counters after the last pass.
    pub last_stats: Option<LoopStats>,
}

impl LoopHooks for Heard {
    fn stepped(&mut self, _seq: u32) {
        self.steps += 1;
    }
    fn benched(&mut self, stats: &firmware::bench::CycleStats) {
        self.benched.push(*stats);
    }
    fn replied(&mut self, status: UpdateStatus, model_loaded: bool) {
        self.replies.push((status, model_loaded));
    }
    fn served(&mut self, stats: &LoopStats) {
        self.passes += 1;
        self.last_stats = Some(*stats);
    }
}

type Thermometer = Tmp117<BoundedI2c<FakeI2c, SimClock>>;
type Flash = ControllerFlash<FlashSim, SimClock, SimWatchdog>;
/// The single-axis image's loop, as `Board::run::<Model, …>` instantiates it.
type Loop = BoardLoop<
    'static,
    Model,
    Thermometer,
    FrontEnd<FakeSpi>,
    FrameQueue<'static, fn()>,
    Flash,
    SimWatchdog,
    SimPlatform,
    Heard,
    { rbf_core::MAX_CENTERS },
    1,
>;

/// The single-axis board: its loop, its handlers' state, its peripherals.
pub struct SimBoard {
    pub clock: SimClock,
    pub i2c: Rc<RefCell<I2cSim>>,
    pub fe: Rc<RefCell<FrontEndSim>>,
    pub board: Loop,
    pub watchdog: SimWatchdog,
    pub counters: &'static HandlerCounters,
    /// EXTI0's end of the stamp queue.
    stamps: Producer<'static, u32>,
    /// USART1's ends of the queues.
    outgoing: Consumer<'static, u8>,
    incoming: Producer<'static, u8>,
    pub rx: UartRxSim,
    pub tx: UartTxSim,
    /// Bytes still to arrive on RX: (when, µs; byte).
    pub rx_line: VecDeque<(u64, u8)>,
    /// Longest pass of the loop, µs.
    pub longest_pass_us: u64,
    /// Stalls of the loop (the interrupts still served): (from, length), µs.
    pub stalls: Vec<(u64, u64)>,
    /// When the loop's start was done, µs.
    pub boot_us: u64,
}

/// How the board boots.
pub struct BootWith {
    /// Sector erases take this long, µs.
    pub erase_us: u64,
    /// The clock tree setup ended in.
    pub tree: timing::ClockTree,
    /// A fault record from before the reset.
    pub fault: Option<firmware::fault::FaultRecord>,
    /// A data-ready line high at boot is taken as an edge (`Board::run` pends EXTI0).
    pub pend_high_data_ready: bool,
}

impl Default for BootWith {
    fn default() -> Self {
        BootWith {
            erase_us: 1_000_000,
            tree: timing::pll_tree(true),
            fault: None,
            pend_high_data_ready: true,
        }
    }
}

/// The flash slots' layout of the simulated flash (sectors 10 and 11).
pub const SLOTS: firmware::model_store::SlotLayout = firmware::model_store::SlotLayout {
    offsets: [crate::sim::SLOTS_START, crate::sim::SLOTS_START + 0x2_0000],
    len: 0x2_0000,
};

impl SimBoard {
    /// Boots the board's loop ([`BoardLoop::start`]) on fresh simulated
    /// peripherals: the TMP117 at 25 °C, the front end sampling from boot.
    pub fn boot(with: BootWith) -> SimBoard {
        let (clock, i2c, fe) = crate::setup(0);
        SimBoard::boot_on(&clock, &i2c, &fe, with)
    }

    /// Boots the board's loop ([`BoardLoop::start`]) on the TMP117 `i2c`
    /// and the front end `fe`, on `clock`. A data-ready line high at boot
    /// is taken as an edge, as `Board::run` pends EXTI0 for it.
    pub fn boot_on(
        clock: &SimClock,
        i2c: &Rc<RefCell<I2cSim>>,
        fe: &Rc<RefCell<FrontEndSim>>,
        with: BootWith,
    ) -> SimBoard {
        let (clock, i2c, fe) = (clock.clone(), i2c.clone(), fe.clone());
        let watchdog = SimWatchdog::new(&clock, LSI_FASTEST_HZ);
        let counters: &'static HandlerCounters = Box::leak(Box::default());
        let (frames_in, outgoing) = Box::leak(Box::new(Queue::<u8, TX_QUEUE>::new())).split();
        let (incoming, commands) = Box::leak(Box::new(Queue::<u8, RX_QUEUE>::new())).split();
        let (stamps, stamp_consumer) = Box::leak(Box::new(Queue::<u32, STAMP_QUEUE>::new())).split();
        let flash = ControllerFlash::new(FlashSim::new(&clock, with.erase_us), clock.clone(), watchdog.clone());
        // The board's setup recovers the bus before the thermometer's init.
        let bus = BoundedI2c::new(FakeI2c(i2c.clone()), clock.clone());
        let boot_cause = firmware::fault::boot_cause(with.fault, false);
        let board = BoardLoop::start(LoopParts {
            boot: BootState {
                cause: reset_cause_at_boot(with.fault, 0),
                flags: 0,
                fault: with.fault,
                tree: with.tree,
                option_bytes: 0,
            },
            boot_cause,
            model: Box::leak(Box::new(Model::EMPTY)),
            receiver: Box::leak(Box::new(CommandReceiver::new())),
            flash,
            slots: SLOTS,
            thermometers: Tmp117::new(bus, 0x48),
            front_ends: FrontEnd::new(FakeSpi(fe.clone())),
            output: FrameQueue::new(frames_in, (|| {}) as fn()),
            stamps: stamp_consumer,
            commands,
            watchdog: watchdog.clone(),
            platform: SimPlatform {
                clock: clock.clone(),
                i2c: i2c.clone(),
                counters,
            },
            timer_hz: 1_000_000,
            hooks: Heard::default(),
        });
        let data_ready_high = fe.borrow().level_high && with.pend_high_data_ready;
        let mut stamps = stamps;
        if data_ready_high {
            interrupts::stamp_data_ready(clock.now_us() as u32, &mut stamps, &counters.stamp_overruns);
        }
        SimBoard {
            boot_us: clock.now_us(),
            clock,
            i2c,
            fe,
            board,
            watchdog,
            counters,
            stamps,
            outgoing,
            incoming,
            rx: UartRxSim::default(),
            tx: UartTxSim::default(),
            rx_line: VecDeque::new(),
            longest_pass_us: 0,
            stalls: Vec::new(),
        }
    }

    /// `bytes` arrive on RX from `at_us` on, one every 11 µs (921,600 Bd).
    pub fn send_at(&mut self, at_us: u64, bytes: &[u8]) {
        for (i, &b) in bytes.iter().enumerate() {
            self.rx_line.push_back((at_us + 11 * i as u64, b));
        }
        self.rx_line.make_contiguous().sort_by_key(|&(t, _)| t);
    }

    /// The interrupts due by now, as the NVIC would run them before the
    /// loop resumes: EXTI0 for each data-ready edge, USART1 for each
    /// received byte, then USART1 while the transmitter has bytes to send.
    fn interrupts(&mut self) {
        self.fe.borrow_mut().advance();
        let edges: Vec<u32> = self.fe.borrow_mut().stamps.drain(..).collect();
        for stamp in edges {
            interrupts::stamp_data_ready(stamp, &mut self.stamps, &self.counters.stamp_overruns);
        }
        let now = self.clock.now_us();
        while self.rx_line.front().is_some_and(|&(t, _)| t <= now) {
            if let Some((_, byte)) = self.rx_line.pop_front() {
                self.rx.line.push_back(byte);
            }
            self.serve_uart();
        }
        while self.serve_uart() == Transmit::Sending {}
    }

    fn serve_uart(&mut self) -> Transmit {
        interrupts::serve_uart(
            &mut self.rx,
            &mut self.tx,
            &mut self.outgoing,
            &mut self.incoming,
            &self.counters.rx_overruns,
        )
    }

    /// Runs the loop until `end_us`: the interrupts due, a pass
    /// ([`BoardLoop::serve_once`]), the interrupts again, and a sleep
    /// while the loop is [`BoardLoop::idle`] until the next edge, byte or
    /// SysTick (every millisecond).
    pub fn run_until(&mut self, end_us: u64) {
        while self.clock.now_us() < end_us {
            if let Some(&(at, len)) = self.stalls.first()
                && self.clock.now_us() >= at
            {
                // The loop is held up; the interrupts are not.
                self.stalls.remove(0);
                let until = self.clock.now_us() + len;
                while self.clock.now_us() < until {
                    self.clock.set_us((self.clock.now_us() + 100).min(until));
                    self.interrupts();
                }
                continue;
            }
            self.interrupts();
            let started = self.clock.now_us();
            self.board.serve_once();
            self.longest_pass_us = self.longest_pass_us.max(self.clock.now_us() - started);
            self.interrupts();
            if self.board.idle() {
                let next_byte = self.rx_line.front().map_or(u64::MAX, |&(t, _)| t);
                let systick = (self.clock.now_us() / 1000 + 1) * 1000;
                let wake = self.fe.borrow().next_event_us().min(systick).min(next_byte);
                self.clock.set_us(wake);
            }
        }
    }

    /// The payloads of every frame sent on TX, in order.
    pub fn sent_payloads(&self) -> Vec<Vec<u8>> {
        let mut sent = self.tx.sent.clone();
        sent.split_mut(|&b| b == 0)
            .filter_map(|f| {
                let n = cobs_decode_in_place(f)?;
                Some(f.get(..n)?.to_vec())
            })
            .filter(|p| !p.is_empty())
            .collect()
    }

    /// The output frames sent on TX.
    pub fn frames(&self) -> Vec<OutputFrame> {
        crate::decode_frames(&self.tx.sent)
    }

    /// The health reports sent on TX.
    pub fn health_reports(&self) -> Vec<HealthReport> {
        self.sent_payloads()
            .iter()
            .filter_map(|p| HealthReport::from_bytes(p))
            .collect()
    }

    /// The replies sent on TX: (command, status byte).
    pub fn replies(&self) -> Vec<(u8, u8)> {
        self.sent_payloads()
            .iter()
            .filter_map(|p| match p.as_slice() {
                &[command, status] => Some((command, status)),
                _ => None,
            })
            .collect()
    }

    /// The loop's counters.
    pub fn stats(&mut self) -> LoopStats {
        self.board.compensation().stats()
    }

    /// The pacer's counters.
    pub fn pacer_counters(&self) -> firmware::pacing::PacerCounters {
        self.board.pacer_counters()
    }

    /// Data-ready stamps lost: to a full stamp queue (EXTI0's count) or
    /// while the loop stalled the front end's own (the simulation's).
    pub fn stamp_overruns(&self) -> u32 {
        self.counters.stamp_overruns.load(Ordering::Relaxed) + self.fe.borrow().stamp_overruns
    }

    /// Ends the run: the I2C master's counters, the front end's inits, the watchdog.
    pub fn finish(self) -> (firmware::i2c_master::I2cCounters, u32, SimWatchdog) {
        let (thermometer, front_end, _, _) = self.board.destroy();
        (thermometer.destroy().counters(), front_end.inits(), self.watchdog)
    }
}

/// A COBS-framed command with `payload`, as the host sends it.
pub fn command_frame(payload: &[u8]) -> Vec<u8> {
    let mut wire = vec![0u8; payload.len() + payload.len() / 254 + 2];
    let n = gyro_wire::cobs::cobs_encode(payload, &mut wire).unwrap_or(0);
    wire.truncate(n);
    wire
}

/// Noise bytes (a frame end now and then) from a xorshift seeded with `state`.
pub fn noise(state: &mut u32, n: usize) -> Vec<u8> {
    (0..n)
        .map(|_| {
            *state ^= *state << 13;
            *state ^= *state >> 17;
            *state ^= *state << 5;
            if state.is_multiple_of(23) {
                0
            } else {
                (*state >> 8) as u8
            }
        })
        .collect()
}

/// The last health report sent, after a `health` command at `at_us`.
fn health_at(board: &mut SimBoard, at_us: u64) -> Result<HealthReport, String> {
    // A frame end first: whatever the receiver holds of an unfinished frame is dropped.
    let mut wire = vec![0u8];
    wire.extend(command_frame(&[gyro_wire::command::CMD_HEALTH]));
    board.send_at(at_us, &wire);
    board.run_until(at_us + 5_000);
    board
        .health_reports()
        .last()
        .copied()
        .ok_or_else(|| "no health report".to_string())
}

/// Boot after a HardFault on the HSI: the boot report, the health report,
/// then frames flagged.
pub fn boot_after_a_fault() -> crate::Verdict {
    let fault = firmware::fault::FaultRecord {
        reason: firmware::fault::FaultReason::HardFault,
        pc: 0x0800_1234,
        lr: 0x0800_0F01,
    };
    let mut board = SimBoard::boot(BootWith {
        tree: timing::HSI_TREE,
        fault: Some(fault),
        ..BootWith::default()
    });
    board.run_until(1_000_000);
    let payloads = board.sent_payloads();
    let frames = board.frames();
    let stats = board.stats();
    crate::check_sequence(&frames, &stats)?;
    ensure!(
        payloads.first().and_then(|p| p.first()) == Some(&gyro_wire::boot::BOOT_REPORT_TAG),
        "the first frame is not the boot report"
    );
    let health = payloads
        .get(1)
        .and_then(|p| HealthReport::from_bytes(p))
        .ok_or("the second frame is not the health report")?;
    ensure!(
        health.reset_cause == ResetCause::HardFault && health.fault_pc == fault.pc,
        "health report: cause {:?}, PC {:#x}",
        health.reset_cause,
        health.fault_pc
    );
    ensure!(
        health.board_flags & gyro_wire::health::BOARD_ON_HSI != 0,
        "the HSI is not flagged in the health report"
    );
    ensure!(health.model.blob_crc32 == 0, "a model reported in empty slots");
    let first = frames.first().ok_or("no frames")?;
    ensure!(
        crate::flagged(first, rbf_core::Flags::FAULT_RESET),
        "the first frame is not flagged 128 (fault reset)"
    );
    ensure!(
        frames
            .iter()
            .all(|f| crate::flagged(f, rbf_core::Flags::NO_VALID_MODEL)),
        "a frame without flag 4 while no model runs"
    );
    ensure!(frames.len() >= 995, "{} frames in 1 s", frames.len());
    ensure!(
        board.watchdog.check().expired_at_us.is_none(),
        "the watchdog reset the chip"
    );
    Ok(format!(
        "BoardLoop::start after a HardFault, on the HSI, slots empty: boot report, health report (HardFault at {:#x}, HSI flagged, {} bus recovery), then {} frames in 1 s, the first flagged 128, all flagged 4",
        health.fault_pc,
        health.counters.bus_recoveries,
        frames.len()
    ))
}

/// A storm of noise bytes on RX while sampling, through USART1's handler
/// body and the loop's command path; then `health`.
pub fn uart_storm_while_sampling() -> crate::Verdict {
    let mut board = SimBoard::boot(BootWith::default());
    board.rx = UartRxSim::with_errors_every(97);
    let mut state = 0x2545_F491u32;
    // A byte every 11 µs (the line's full rate) from 0.2 s to 1.2 s.
    let storm = noise(&mut state, 90_000);
    board.send_at(200_000, &storm);
    board.run_until(1_500_000);
    let frames = board.frames();
    let stats = board.stats();
    crate::check_sequence(&frames, &stats)?;
    let counted = board.counters.rx_overruns.load(Ordering::Relaxed);
    let health = health_at(&mut board, 1_500_000)?;
    let heard = &board.board.hooks_mut().replies;
    let installs = heard.iter().filter(|(s, _)| *s == UpdateStatus::Installed).count();
    ensure!(stats.samples_missed == 0, "{} samples missed", stats.samples_missed);
    ensure!(frames.len() >= 1495, "{} frames in 1.5 s", frames.len());
    ensure!(installs == 0, "noise installed a model");
    ensure!(heard.len() >= 100, "only {} noise frames answered", heard.len());
    ensure!(
        counted >= 900,
        "{counted} receive errors counted of 90,000 bytes, one in 97 bad"
    );
    ensure!(
        health.counters.overruns == counted,
        "health report: {} overruns, the handler counted {counted}",
        health.counters.overruns
    );
    ensure!(
        board.longest_pass_us < 1000,
        "a loop pass took {} µs",
        board.longest_pass_us
    );
    Ok(format!(
        "90,000 noise bytes at the line's rate during 1 s of sampling, through USART1's handler body and BoardLoop::serve_once: {} frames, 0 missed, {} noise frames answered, {counted} receive errors counted and reported in `health` ({} overruns), no install",
        frames.len(),
        heard.len(),
        health.counters.overruns
    ))
}

/// The thermometer NACKs for a second, then its bus hangs (BUSY stuck),
/// mid-run: frames still one per sample, flagged 2 while it fails; the
/// health report counts the faults, the timeout and the recoveries.
pub fn thermometer_fails_mid_run() -> crate::Verdict {
    let mut board = SimBoard::boot(BootWith::default());
    board.i2c.borrow_mut().nack_window_us = (500_000, 1_500_000);
    board.run_until(2_000_000);
    board.i2c.borrow_mut().busy_stuck = true;
    board.run_until(3_000_000);
    let frames = board.frames();
    let stats = board.stats();
    crate::check_sequence(&frames, &stats)?;
    let health = health_at(&mut board, 3_000_000)?;
    let samples_after = board.stats().samples;
    let during = frames.iter().filter(|f| (630..1500).contains(&f.seq));
    ensure!(
        during
            .clone()
            .all(|f| crate::flagged(f, rbf_core::Flags::TEMP_SENSOR_FAULT)),
        "a frame without flag 2 while the TMP117 NACKed"
    );
    ensure!(
        frames
            .iter()
            .filter(|f| f.seq >= 2130)
            .all(|f| !crate::flagged(f, rbf_core::Flags::TEMP_SENSOR_FAULT)),
        "flag 2 after the bus was recovered"
    );
    ensure!(stats.samples_missed <= 2, "{} samples missed", stats.samples_missed);
    ensure!(
        health.counters.temp_read_faults == stats.temp_read_faults && stats.temp_read_faults >= 7,
        "health report: {} thermometer faults, the loop counted {}",
        health.counters.temp_read_faults,
        stats.temp_read_faults
    );
    ensure!(
        health.counters.sensor_timeouts == 1 && health.counters.bus_recoveries == 2,
        "health report: {} timeouts, {} recoveries (expected 1, 2: boot and the stuck BUSY)",
        health.counters.sensor_timeouts,
        health.counters.bus_recoveries
    );
    ensure!(
        (stats.samples..=samples_after).contains(&health.counters.samples),
        "health report: {} samples, the loop {} … {samples_after}",
        health.counters.samples,
        stats.samples
    );
    ensure!(
        board.watchdog.check().expired_at_us.is_none(),
        "the watchdog reset the chip"
    );
    Ok(format!(
        "TMP117 NACKs 0.5–1.5 s, then BUSY stuck at 2 s, through BoardLoop: {} frames, {} missed, flag 2 while failing and clear after; `health`: {} thermometer faults, {} timeout, {} recoveries, longest pass {} µs",
        frames.len(),
        stats.samples_missed,
        health.counters.temp_read_faults,
        health.counters.sensor_timeouts,
        health.counters.bus_recoveries,
        board.longest_pass_us
    ))
}

/// A model installed over RX through the loop while it samples: a 1-s
/// sector erase, the reply, the model running after it, its identity in `health`.
pub fn install_through_the_loop() -> crate::Verdict {
    let mut board = SimBoard::boot(BootWith::default());
    let model = firmware_harness::fault_injection::cubic_model().ok_or("no cubic model")?;
    let mut blob = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
    let n = rbf_core::blob::encode(&model, &mut blob).map_err(|e| format!("{e:?}"))?;
    // The blob's CRC-32 trailer, which the health report names the running model by.
    let crc = blob[..n].last_chunk::<4>().map_or(0, |t| u32::from_le_bytes(*t));
    board.send_at(500_000, &command_frame(&crate::install_payload(&model)));
    board.run_until(3_000_000);
    let frames = board.frames();
    let stats = board.stats();
    crate::check_sequence(&frames, &stats)?;
    let health = health_at(&mut board, 3_000_000)?;
    // The install's reply (the `health` request's leading frame end adds an empty frame's).
    let replies: Vec<_> = board
        .replies()
        .into_iter()
        .filter(|&(command, _)| command == gyro_wire::command::CMD_INSTALL_MODEL)
        .collect();
    let heard = board.board.hooks_mut().replies.clone();
    ensure!(
        replies == [(gyro_wire::command::CMD_INSTALL_MODEL, UpdateStatus::Installed as u8)],
        "replies {replies:?}"
    );
    ensure!(
        heard.first() == Some(&(UpdateStatus::Installed, true)),
        "hooks heard {heard:?}"
    );
    let last_unmodelled = frames
        .iter()
        .rev()
        .find(|f| crate::flagged(f, rbf_core::Flags::NO_VALID_MODEL))
        .map(|f| f.seq);
    ensure!(
        last_unmodelled.is_some_and(|s| s < 2000),
        "flag 4 until sample {last_unmodelled:?}"
    );
    ensure!(
        (900..=1100).contains(&stats.samples_missed),
        "{} samples missed over a 1-s erase",
        stats.samples_missed
    );
    ensure!(
        health.model.blob_crc32 == crc && health.model.sequence == 1,
        "health report: model CRC {:#010x} sequence {}, installed {crc:#010x}",
        health.model.blob_crc32,
        health.model.sequence
    );
    ensure!(health.counters.flash_errors == 0, "flash errors reported");
    ensure!(
        board.watchdog.check().expired_at_us.is_none(),
        "the watchdog reset the chip"
    );
    Ok(format!(
        "install over RX at 0.5 s through USART1's handler body and BoardLoop: reply Installed, model runs from sample {}, {} samples missed over the 1-s erase (flag 32 once), `health`: CRC {crc:#010x} sequence 1",
        last_unmodelled.map_or(0, |s| s + 1),
        stats.samples_missed
    ))
}
