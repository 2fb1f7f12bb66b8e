//! The board's fault campaign, a test target (`cargo test -p
//! firmware-harness --test board_faults`; `cargo xtask board-faults`): the
//! stm32f405 board's own driver and loop
//! code (the bounded I2C master with bus recovery, the TMP117 and front-end
//! drivers, the data-ready pacer, the compensation loop, the flash
//! controller driver, the model store and command path) run on the host
//! against simulated peripherals that misbehave on purpose, on a simulated
//! clock. One line per scenario with what happened, then
//! `board faults: N scenarios, M failed`; the exit code is non-zero when any
//! failed. docs/firmware.md, "Faults the board survives".

mod sim;

use std::cell::{Cell, RefCell};
use std::process::ExitCode;
use std::rc::Rc;
use std::sync::atomic::{AtomicU32, Ordering};

use firmware::bench::Bench;
use firmware::commands::{self, Report};
use firmware::compensation::{CompensationLoop, InPlaceModel, LoopConfig, LoopStats};
use firmware::flash_ctl::{self, ControllerFlash};
use firmware::frontend::FrontEnd;
use firmware::i2c_master::{BoundedI2c, I2cCounters};
use firmware::interrupts::{self, Transmit};
use firmware::model_store::{ModelStore, SlotLayout};
use firmware::pacing::Pacer;
use firmware::samples::serve_samples_timed;
use firmware::sensors::{RateFrontEnd, RateSample, SensorFault, Thermometer};
use firmware::tmp117::Tmp117;
use firmware::uart::{self, FrameQueue};
use firmware::update::{self, CommandReceiver, UpdateStatus};
use firmware::watchdog::{LSI_FASTEST_HZ, SECTOR_ERASE_WORST_MS, Watchdog, running_setting};
use heapless::spsc::{Consumer, Producer, Queue};
use rbf_core::axis::Axis;
use rbf_core::frame::cobs_decode_in_place;
use rbf_core::frame::{self, OutputFrame};
use rbf_core::{CompensatorConfig, Flags, Model};
use sim::{FakeI2c, FakeSpi, FlashSim, FrontEndSim, I2cSim, SimClock, SimWatchdog, UartRxSim, UartTxSim};

/// A scenario's verdict: what happened, or why it failed.
type Verdict = Result<String, String>;

/// A named scenario.
type Scenario = (&'static str, fn() -> Verdict);

macro_rules! ensure {
    ($cond:expr, $($msg:tt)*) => {
        let holds: bool = $cond;
        if !holds {
            return Err(format!($($msg)*));
        }
    };
}

// After `ensure!`, which it uses: the board's own loop (`BoardLoop`) on the simulations.
mod real_loop;

/// 25 °C as the TMP117 codes it.
const TEMP_25C_RAW: i16 = 3200;

type Bus = BoundedI2c<FakeI2c, SimClock>;
type BoardLoop = CompensationLoop<Tmp117<Bus>, FrontEnd<FakeSpi>, Vec<u8>, Option<Model>>;

/// The single-axis board's sample path, wired as `src/bin/stm32f405.rs` and `firmware::board` wire it.
struct Board {
    clock: SimClock,
    fe: Rc<RefCell<FrontEndSim>>,
    lp: BoardLoop,
    pacer: Pacer,
    watchdog: SimWatchdog,
    /// The `bench` command's timing (never started here).
    bench: Bench,
    /// Stalls of the loop: (from, length), µs.
    stalls: Vec<(u64, u64)>,
    /// Longest pass of the loop, µs.
    longest_pass_us: u64,
    boot_us: u64,
}

impl Board {
    /// Boots as the board does: watchdog, bus recovery, sensor inits (failures not fatal), pacer.
    fn boot(clock: &SimClock, i2c: &Rc<RefCell<I2cSim>>, fe: &Rc<RefCell<FrontEndSim>>) -> Board {
        let watchdog = SimWatchdog::new(clock, LSI_FASTEST_HZ);
        let bus = BoundedI2c::new(FakeI2c(i2c.clone()), clock.clone());
        let mut thermometer = Tmp117::new(bus, 0x48);
        let _ = thermometer.init();
        let mut front_end = FrontEnd::new(FakeSpi(fe.clone()));
        let _ = front_end.init();
        let config = LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(1000.0),
            temp_read_every: 125,
        };
        let lp = CompensationLoop::new(None::<Model>, config, thermometer, front_end, Vec::new());
        Board {
            clock: clock.clone(),
            fe: fe.clone(),
            lp,
            pacer: Pacer::new(1_000_000, 1000, clock.now_us() as u32),
            watchdog,
            bench: Bench::default(),
            stalls: Vec::new(),
            longest_pass_us: 0,
            boot_us: clock.now_us(),
        }
    }

    /// Runs the board's main loop until `end_us`: a pass per wake-up (a
    /// data-ready edge or the 1 kHz SysTick), sleeping in between.
    fn run_until(&mut self, end_us: u64) {
        while self.clock.now_us() < end_us {
            if let Some(&(at, len)) = self.stalls.first()
                && self.clock.now_us() >= at
            {
                self.stalls.remove(0);
                self.clock.advance_us(len);
                self.fe.borrow_mut().advance();
                continue;
            }
            self.fe.borrow_mut().advance();
            let started = self.clock.now_us();
            let fe = &self.fe;
            let clock = &self.clock;
            // The sample half of Board::run's pass, as the board runs it
            // (the simulated µs stand in for the DWT cycle counter).
            let stepped = serve_samples_timed(
                &mut self.pacer,
                || fe.borrow_mut().stamps.pop_front(),
                started as u32,
                &mut self.watchdog,
                &mut self.lp,
                &mut self.bench,
                || clock.now_us() as u32,
                |_, _| {},
            );
            self.longest_pass_us = self.longest_pass_us.max(self.clock.now_us() - started);
            if !stepped {
                let wake = self
                    .fe
                    .borrow()
                    .next_event_us()
                    .min((self.clock.now_us() / 1000 + 1) * 1000);
                self.clock.set_us(wake);
            }
        }
    }

    fn frames(&mut self) -> Vec<OutputFrame> {
        decode_frames(self.lp.output_mut())
    }

    fn stats(&self) -> LoopStats {
        self.lp.stats()
    }

    /// Ends the run: the I2C master's counters and the front end's inits.
    fn finish(self) -> (I2cCounters, u32, SimWatchdog) {
        let (t, f, _) = self.lp.destroy();
        (t.destroy().counters(), f.inits(), self.watchdog)
    }
}

fn decode_frames(bytes: &[u8]) -> Vec<OutputFrame> {
    let mut bytes = bytes.to_vec();
    bytes
        .split_mut(|&b| b == 0)
        .filter(|c| !c.is_empty())
        .filter_map(|c| frame::decode(c).ok())
        .collect()
}

/// Every frame's sequence number follows the last; a jump is counted as
/// missed samples and flagged 32.
fn check_sequence(frames: &[OutputFrame], stats: &LoopStats) -> Result<(), String> {
    let mut missed = 0u32;
    for pair in frames.windows(2) {
        let gap = pair[1].seq.wrapping_sub(pair[0].seq);
        ensure!(
            (1..1 << 20).contains(&gap),
            "seq {} follows {}",
            pair[1].seq,
            pair[0].seq
        );
        if gap > 1 {
            ensure!(
                pair[1].flags & Flags::SAMPLES_MISSED.bits() != 0,
                "seq {} jumps {gap} without flag 32",
                pair[1].seq
            );
            missed += gap - 1;
        }
    }
    ensure!(
        missed == stats.samples_missed,
        "frames skip {missed} samples, the loop counted {}",
        stats.samples_missed
    );
    ensure!(
        frames.len() as u32 == stats.samples,
        "{} frames for {} samples",
        frames.len(),
        stats.samples
    );
    Ok(())
}

fn flagged(f: &OutputFrame, flag: Flags) -> bool {
    f.flags & flag.bits() != 0
}

fn setup(boot_at_us: u64) -> (SimClock, Rc<RefCell<I2cSim>>, Rc<RefCell<FrontEndSim>>) {
    let clock = SimClock::default();
    let i2c = Rc::new(RefCell::new(I2cSim::new(&clock, TEMP_25C_RAW)));
    let fe = Rc::new(RefCell::new(FrontEndSim::new(&clock, boot_at_us)));
    (clock, i2c, fe)
}

fn stuck_sda_at_boot() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    i2c.borrow_mut().sda_stuck_clocks = 7;
    let mut board = Board::boot(&clock, &i2c, &fe);
    let boot_us = board.boot_us;
    board.run_until(1_000_000);
    let frames = board.frames();
    check_sequence(&frames, &board.stats())?;
    let (i2c_counters, _, _) = board.finish();
    ensure!(i2c.borrow().sda_stuck_clocks == 0, "SDA still held after boot");
    ensure!(
        i2c_counters.timeouts == 0,
        "the bus was recovered only after a timeout, not before init"
    );
    ensure!(boot_us < 5000, "boot took {boot_us} µs");
    ensure!(frames.len() >= 995, "{} frames in 1 s", frames.len());
    let late = frames.iter().filter(|f| f.seq >= 130);
    ensure!(
        late.clone()
            .all(|f| !flagged(f, Flags::TEMP_SENSOR_FAULT) && (f.temp_c - 25.0).abs() < 1e-3),
        "the thermometer does not read 25 °C after the recovery"
    );
    Ok(format!(
        "a TMP117 holding SDA through 7 clocks at boot: released by the recovery before init ({} recovery, boot {boot_us} µs); {} frames in 1 s, 25 °C from the second read on",
        i2c_counters.recoveries,
        frames.len()
    ))
}

fn stuck_bus_at_run_time() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(500_000);
    i2c.borrow_mut().sda_stuck_clocks = 8;
    board.run_until(1_500_000);
    i2c.borrow_mut().busy_stuck = true;
    board.run_until(3_000_000);
    let frames = board.frames();
    let stats = board.stats();
    check_sequence(&frames, &stats)?;
    let longest = board.longest_pass_us;
    let (c, _, dog) = board.finish();
    ensure!(
        c.timeouts == 2,
        "{} timeouts, expected 2 (stuck SDA, stuck BUSY)",
        c.timeouts
    );
    ensure!(c.recoveries == 3, "{} recoveries, expected 3 (boot + 2)", c.recoveries);
    ensure!(longest < 2500, "a loop pass took {longest} µs");
    ensure!(dog.check().expired_at_us.is_none(), "the watchdog reset the chip");
    let last = frames.last().ok_or("no frames")?;
    ensure!(
        !flagged(last, Flags::TEMP_SENSOR_FAULT),
        "the thermometer did not come back"
    );
    ensure!(stats.samples_missed <= 4, "{} samples missed", stats.samples_missed);
    Ok(format!(
        "SDA stuck at 0.5 s, BUSY stuck (erratum) at 1.5 s: {} timeouts, {} recoveries, longest loop pass {longest} µs, {} frames, {} samples missed, thermometer back",
        c.timeouts,
        c.recoveries,
        frames.len(),
        stats.samples_missed
    ))
}

fn nack_storm() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    let mut board = Board::boot(&clock, &i2c, &fe);
    i2c.borrow_mut().nack_window_us = (1_000_000, 2_000_000);
    board.run_until(3_000_000);
    let frames = board.frames();
    let stats = board.stats();
    check_sequence(&frames, &stats)?;
    let (c, _, _) = board.finish();
    ensure!(c.nacks >= 7, "{} NACKs counted", c.nacks);
    ensure!(c.timeouts == 0, "a NACK is no timeout ({})", c.timeouts);
    ensure!(stats.samples_missed == 0, "{} samples missed", stats.samples_missed);
    let during = frames.iter().filter(|f| (1130..2000).contains(&f.seq));
    ensure!(
        during.clone().all(|f| flagged(f, Flags::TEMP_SENSOR_FAULT)),
        "storm frames not flagged 2"
    );
    let after = frames.iter().filter(|f| f.seq >= 2130);
    ensure!(
        after.clone().all(|f| !flagged(f, Flags::TEMP_SENSOR_FAULT)),
        "flag 2 after the storm"
    );
    Ok(format!(
        "TMP117 NACKs every transaction for 1 s: {} NACKs, 0 timeouts, {} frames (flag 2 during the storm, clear after), 0 samples missed",
        c.nacks,
        frames.len()
    ))
}

fn late_thermometer() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    i2c.borrow_mut().nack_window_us = (0, 300_000);
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(1_000_000);
    let frames = board.frames();
    check_sequence(&frames, &board.stats())?;
    let first_temp = frames
        .iter()
        .find(|f| !flagged(f, Flags::TEMP_SENSOR_FAULT))
        .map(|f| f.seq);
    let (_, _, _) = board.finish();
    ensure!(
        first_temp.is_some_and(|s| (300..=500).contains(&s)),
        "first reading at sample {first_temp:?}"
    );
    ensure!(
        frames
            .iter()
            .all(|f| f.temp_c.is_nan() || (f.temp_c - 25.0).abs() < 1e-3),
        "a reading other than 25 °C went out (−256 °C before the first conversion?)"
    );
    ensure!(
        frames
            .iter()
            .filter(|f| f.seq < 300)
            .all(|f| flagged(f, Flags::TEMP_SENSOR_FAULT)),
        "unflagged frame before the TMP117 answered"
    );
    Ok(format!(
        "TMP117 answers 300 ms after boot: init retried on each read, flag 2 until sample {}, then 25 °C (never −256 °C), {} frames",
        first_temp.unwrap_or(0),
        frames.len()
    ))
}

fn data_ready_stuck_high_at_boot() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    {
        let mut f = fe.borrow_mut();
        f.level_high = true;
        f.counter = 42;
    }
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(1_000_000);
    let frames = board.frames();
    check_sequence(&frames, &board.stats())?;
    let synthetic = board.pacer.counters().synthetic;
    let (_, _, dog) = board.finish();
    ensure!(dog.check().expired_at_us.is_none(), "the watchdog reset the chip");
    ensure!((1..=3).contains(&synthetic), "{synthetic} synthetic steps");
    ensure!(frames.len() >= 990, "{} frames in 1 s", frames.len());
    let invalid = frames.iter().filter(|f| flagged(f, Flags::RATE_INVALID)).count();
    ensure!(invalid <= 3, "{invalid} frames flagged 16");
    Ok(format!(
        "data-ready high from before the reset, no edge: {synthetic} step(s) on the silence read SAMPLE (acknowledging it), edges resume; {} frames in 1 s, {invalid} flagged 16",
        frames.len()
    ))
}

fn front_end_boots_late() -> Verdict {
    let (clock, i2c, fe) = setup(2_000_000);
    // Its samples come 100 ms before its scale factor is valid.
    fe.borrow_mut().scale_from_us = 2_100_000;
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(3_000_000);
    let frames = board.frames();
    check_sequence(&frames, &board.stats())?;
    let (_, inits, dog) = board.finish();
    ensure!(dog.check().expired_at_us.is_none(), "the watchdog reset the chip");
    let before: Vec<_> = frames.iter().filter(|f| f.seq < 2090).collect();
    ensure!(before.len() >= 2080, "{} frames in the first 2.1 s", before.len());
    ensure!(
        before
            .iter()
            .all(|f| flagged(f, Flags::RATE_INVALID) && f.rate_dph.is_nan()),
        "a rate went out before the front end answered (scale 1.0?)"
    );
    ensure!(inits == 1, "front end initialised {inits} times");
    let after: Vec<_> = frames.iter().filter(|f| f.seq >= 2110).collect();
    ensure!(
        after.iter().all(|f| !flagged(f, Flags::RATE_INVALID)),
        "flag 16 after the front end answered"
    );
    for pair in after.windows(2) {
        let step = (pair[1].rate_dph - pair[0].rate_dph).rem_euclid(512.0);
        ensure!(
            (step - 2.0).abs() < 1e-3,
            "rates {} then {}: not its scale factor 2",
            pair[0].rate_dph,
            pair[1].rate_dph
        );
    }
    Ok(format!(
        "front end silent for 2 s, then 0.1 s of samples without a valid scale factor: {} frames flagged 16 with no rate (never scale 1), then initialised once, its scale 2 on {} frames",
        before.len(),
        after.len()
    ))
}

fn front_end_resets() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(1_000_000);
    {
        // Its supply dips: 50 ms unpowered (MISO floats high), then it
        // boots again with another scale factor and its counter from 0.
        let mut f = fe.borrow_mut();
        f.boot_at_us = 1_050_000;
        f.scale_dph = 4.0;
        f.counter = 0;
    }
    board.run_until(2_000_000);
    let frames = board.frames();
    check_sequence(&frames, &board.stats())?;
    let (_, inits, dog) = board.finish();
    ensure!(dog.check().expired_at_us.is_none(), "the watchdog reset the chip");
    ensure!(inits == 2, "front end initialised {inits} times, expected 2");
    let dark: Vec<_> = frames.iter().filter(|f| (1001..1045).contains(&f.seq)).collect();
    let unflagged = dark.iter().find(|f| !flagged(f, Flags::RATE_INVALID));
    ensure!(
        unflagged.is_none(),
        "a frame without a front end went out unflagged: {unflagged:?}"
    );
    let after: Vec<_> = frames.iter().filter(|f| f.seq >= 1100).collect();
    ensure!(!after.is_empty(), "no frames after the reset");
    for pair in after.windows(2) {
        let step = (pair[1].rate_dph - pair[0].rate_dph).rem_euclid(1024.0);
        ensure!(
            (step - 4.0).abs() < 1e-3,
            "rates {} then {}: not the new scale factor 4",
            pair[0].rate_dph,
            pair[1].rate_dph
        );
    }
    Ok(format!(
        "front end unpowered for 50 ms at 1 s: {} frames flagged 16 meanwhile, re-initialised after {} failed reads (2 inits), its new scale 4 on {} frames",
        dark.len(),
        firmware::frontend::REINIT_AFTER_FAULTS,
        after.len()
    ))
}

fn loop_stall() -> Verdict {
    let mut lines = Vec::new();
    // Both kinds of data-ready line: held high until SAMPLE is read, and pulsed.
    for pulsed in [false, true] {
        let (clock, i2c, fe) = setup(0);
        fe.borrow_mut().pulsed = pulsed;
        let mut board = Board::boot(&clock, &i2c, &fe);
        board.stalls.push((500_000, 200_000));
        board.run_until(1_000_000);
        let frames = board.frames();
        let stats = board.stats();
        check_sequence(&frames, &stats)?;
        let backlog = board.pacer.counters().backlog;
        let overruns = fe.borrow().stamp_overruns;
        let (_, _, dog) = board.finish();
        let dog = dog.check();
        ensure!(dog.expired_at_us.is_none(), "the watchdog reset the chip");
        ensure!(
            (198..=201).contains(&stats.samples_missed),
            "{} samples missed",
            stats.samples_missed
        );
        ensure!((198..=201).contains(&backlog), "{backlog} edges passed over");
        ensure!(!pulsed || overruns >= 180, "{overruns} stamps lost to the full queue");
        let bridges: Vec<_> = frames.iter().filter(|f| flagged(f, Flags::SAMPLES_MISSED)).collect();
        ensure!(bridges.len() == 1, "{} frames flagged 32", bridges.len());
        ensure!(
            frames.iter().all(|f| !flagged(f, Flags::RATE_INVALID)),
            "a stale sample went out"
        );
        // The frame after the stall carries the sample its sequence number names.
        let (first, bridge) = (&frames[0], bridges[0]);
        let sample_of = |f: &OutputFrame| f.rate_dph / 2.0;
        let expected = (sample_of(first) + (bridge.seq - first.seq) as f32).rem_euclid(256.0);
        ensure!(
            (sample_of(bridge) - expected).abs() < 1e-3,
            "frame {} holds sample {} of 256, expected {expected}",
            bridge.seq,
            sample_of(bridge)
        );
        lines.push(format!(
            "{} line: one frame for the stall, {} missed and flagged 32, {overruns} stamps lost to the full queue, watchdog gap {} ms",
            if pulsed { "pulsed" } else { "level" },
            stats.samples_missed,
            dog.longest_gap_us / 1000
        ));
    }
    Ok(format!("loop stalled 200 ms: {}", lines.join("; ")))
}

fn data_ready_glitch() -> Verdict {
    let (clock, i2c, fe) = setup(0);
    fe.borrow_mut().glitch_after_us = 150;
    let mut board = Board::boot(&clock, &i2c, &fe);
    board.run_until(1_000_000);
    let frames = board.frames();
    let stats = board.stats();
    check_sequence(&frames, &stats)?;
    let glitches = board.pacer.counters().glitches;
    let samples = fe.borrow().samples;
    board.finish();
    ensure!(glitches >= 990, "{glitches} glitches rejected");
    ensure!(
        frames.len() as u64 >= samples - 1,
        "{} frames for {samples} samples",
        frames.len()
    );
    ensure!(stats.samples_missed == 0, "{} samples missed", stats.samples_missed);
    ensure!(
        frames.iter().all(|f| !flagged(f, Flags::RATE_INVALID)),
        "a glitch gave a stale frame"
    );
    Ok(format!(
        "an extra edge 150 µs after every edge: {glitches} rejected by the timer, {} frames for {samples} samples, none stale",
        frames.len()
    ))
}

/// The flash, model store and loop of the command path.
struct Installer {
    clock: SimClock,
    watchdog: SimWatchdog,
    store: ModelStore<ControllerFlash<FlashSim, SimClock, SimWatchdog>>,
}

/// A thermometer and front end that always answer (the command scenarios).
struct Steady;

impl Thermometer for Steady {
    fn read_temp_c(&mut self) -> Result<f32, SensorFault> {
        Ok(25.0)
    }
}

impl RateFrontEnd for Steady {
    fn read_rate(&mut self) -> Result<RateSample, SensorFault> {
        Ok(RateSample {
            rate_dph: 1.0,
            valid: true,
        })
    }
}

const SLOTS: SlotLayout = SlotLayout {
    offsets: [sim::SLOTS_START, sim::SLOTS_START + 0x2_0000],
    len: 0x2_0000,
};

impl Installer {
    /// Erases take `erase_us`; the first `failing_programs` word programs fail.
    fn new(erase_us: u64, failing_programs: u32) -> Installer {
        let clock = SimClock::default();
        let watchdog = SimWatchdog::new(&clock, LSI_FASTEST_HZ);
        let mut sim = FlashSim::new(&clock, erase_us);
        sim.failing_programs = failing_programs;
        let flash = ControllerFlash::new(sim, clock.clone(), watchdog.clone());
        Installer {
            store: ModelStore::open(flash, SLOTS),
            clock,
            watchdog,
        }
    }

    fn sim(&self) -> &FlashSim {
        self.store.flash().registers()
    }
}

fn install_payload(model: &Model) -> Vec<u8> {
    let mut blob = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
    let n = rbf_core::blob::encode(model, &mut blob).unwrap_or(0);
    let mut payload = vec![update::CMD_INSTALL_MODEL];
    payload.extend_from_slice(&blob[..n]);
    payload
}

fn slow_erase_at_fast_lsi() -> Verdict {
    let mut inst = Installer::new(u64::from(SECTOR_ERASE_WORST_MS) * 1000, 0);
    let payload = install_payload(&firmware_harness::fault_injection::cubic_model().expect("valid cubic model"));
    let mut model: Model = Model::EMPTY;
    inst.watchdog.feed();
    let status = update::execute_into(&mut inst.store, &payload, &mut model);
    let dog = inst.watchdog.check();
    ensure!(status == UpdateStatus::Installed, "install: {status:?}");
    ensure!(
        dog.expired_at_us.is_none(),
        "the watchdog reset the chip at {:?} µs",
        dog.expired_at_us
    );
    ensure!(
        dog.longest_gap_us >= 4_000_000,
        "the erase stalled only {} µs",
        dog.longest_gap_us
    );
    ensure!(dog.setting == running_setting(), "the running period was not restored");
    let running_ms = running_setting().period_us_at(LSI_FASTEST_HZ) / 1000;
    ensure!(
        running_ms < 4000,
        "the scenario proves nothing: the running period is {running_ms} ms"
    );
    let sim = inst.sim();
    ensure!(
        sim.erases.iter().all(|&p| p == flash_ctl::CR_PSIZE_X32),
        "an erase not at x32"
    );
    ensure!(sim.flushes_since_erase >= 1, "caches not flushed after the erase");
    ensure!(sim.locked(), "controller left unlocked");
    ensure!(sim.status() & flash_ctl::SR_ERRORS == 0, "error flags left set");
    Ok(format!(
        "4-s sector erase with the LSI at 47 kHz: installed, the CPU stalled {} ms under the install period {} ms (the running period, {running_ms} ms, would have reset), x32, caches flushed, controller locked, {} s simulated",
        dog.longest_gap_us / 1000,
        firmware::watchdog::install_setting().period_us_at(LSI_FASTEST_HZ) / 1000,
        inst.clock.now_us() / 1_000_000
    ))
}

fn flash_error() -> Verdict {
    // The first word program fails (PGSERR).
    let mut inst = Installer::new(1_000_000, 1);
    let payload = install_payload(&firmware_harness::fault_injection::cubic_model().expect("valid cubic model"));
    let mut storage: Model = Model::EMPTY;
    let mut lp = CompensationLoop::new(
        InPlaceModel::new(&mut storage, false),
        LoopConfig {
            compensator: CompensatorConfig::for_sample_rate(1000.0),
            temp_read_every: 125,
        },
        Steady,
        Steady,
        Vec::new(),
    );
    let mut statuses = Vec::new();
    let mut after_first = None;
    for _ in 0..2 {
        let mut status = UpdateStatus::UnknownCommand;
        lp.update_model_if(|m| {
            status = update::run_in_place(&mut inst.store, &payload, m);
            status == UpdateStatus::Installed
        });
        statuses.push(status);
        after_first.get_or_insert((
            inst.store.flash().errors(),
            inst.sim().status() & flash_ctl::SR_ERRORS,
            inst.sim().locked(),
            lp.model(Axis::X).is_some(),
        ));
    }
    let (errors, flags, locked, model_after_failure) = after_first.unwrap_or_default();
    let restarts = lp.stats().filter_restarts;
    ensure!(
        statuses == [UpdateStatus::FlashFailed, UpdateStatus::Installed],
        "statuses {statuses:?}"
    );
    ensure!(errors == 1, "{errors} flash errors counted");
    ensure!(flags == 0, "error flags {flags:#x} left set after the failure");
    ensure!(locked, "controller left unlocked after the failure");
    ensure!(
        !model_after_failure,
        "a model runs after a failed install into empty slots"
    );
    ensure!(
        restarts == 1,
        "filters restarted {restarts} times for one installed model"
    );
    ensure!(lp.model(Axis::X).is_some(), "the installed model does not run");
    ensure!(
        inst.store.identity().sequence == 1,
        "identity {:?}",
        inst.store.identity()
    );
    Ok(format!(
        "a word program fails (PGSERR): reply FlashFailed, 1 flash error counted, flags cleared, controller locked, no restart; the retry installs (filters restarted once), model sequence {}",
        inst.store.identity().sequence
    ))
}

/// The board's receive and transmit queues' sizes (`firmware::board`'s `RX_QUEUE`, `TX_QUEUE`).
const RX_QUEUE: usize = 256;
const TX_QUEUE: usize = 512;

/// The single-axis loop writing its frames into the board's transmit queue.
type QueuedLoop<'m> = CompensationLoop<Steady, Steady, FrameQueue<'static, fn()>, InPlaceModel<'m, Model>>;

/// The board's UART side: its queues, USART1's interrupt logic on a
/// simulated UART, and the loop's command path, as `Board::run` and the
/// USART1 handler wire them; a model installed at the start.
struct UartBoard {
    inst: Installer,
    outgoing: Consumer<'static, u8>,
    incoming: Producer<'static, u8>,
    in_consumer: Consumer<'static, u8>,
    rx: UartRxSim,
    tx: UartTxSim,
    rx_overruns: AtomicU32,
    receiver: CommandReceiver,
    bench: Bench,
    pacer: Pacer,
    /// A cycle counter for the `bench` command: 1,000 per read.
    cycles: Cell<u32>,
}

impl UartBoard {
    /// The board with a framing error on every `error_every`-th received
    /// byte, and its loop running the cubic model (installed over the
    /// command path's install, filters restarted once).
    fn new(error_every: u32, storage: &mut Model) -> (UartBoard, QueuedLoop<'_>) {
        let mut inst = Installer::new(1_000_000, 0);
        let good = install_payload(&firmware_harness::fault_injection::cubic_model().expect("valid cubic model"));
        let (frames_in, outgoing) = Box::leak(Box::new(Queue::<u8, TX_QUEUE>::new())).split();
        let (incoming, in_consumer) = Box::leak(Box::new(Queue::<u8, RX_QUEUE>::new())).split();
        let mut lp = CompensationLoop::new(
            InPlaceModel::new(storage, false),
            LoopConfig {
                compensator: CompensatorConfig::for_sample_rate(1000.0),
                temp_read_every: 125,
            },
            Steady,
            Steady,
            FrameQueue::new(frames_in, (|| {}) as fn()),
        );
        lp.update_model_if(|m| update::run_in_place(&mut inst.store, &good, m) == UpdateStatus::Installed);
        let board = UartBoard {
            inst,
            outgoing,
            incoming,
            in_consumer,
            rx: UartRxSim::with_errors_every(error_every),
            tx: UartTxSim::default(),
            rx_overruns: AtomicU32::new(0),
            receiver: CommandReceiver::new(),
            bench: Bench::default(),
            pacer: Pacer::new(1_000_000, 1000, 0),
            cycles: Cell::new(0),
        };
        (board, lp)
    }

    /// `byte` arrives on RX: USART1's interrupt takes it (and sends a
    /// queued byte, as the same interrupt does).
    fn receive(&mut self, byte: u8) {
        self.rx.line.push_back(byte);
        interrupts::serve_uart(
            &mut self.rx,
            &mut self.tx,
            &mut self.outgoing,
            &mut self.incoming,
            &self.rx_overruns,
        );
    }

    /// One pass of the loop for the data-ready edge of sample `seq`: the
    /// sample half, then the command half (`report` hears `bench` and
    /// `health` after the board's own handling of `bench`; `replied` each
    /// reply's status), then USART1's interrupt until the transmit queue is empty.
    fn pass(
        &mut self,
        lp: &mut QueuedLoop<'_>,
        seq: u32,
        mut report: impl FnMut(Report),
        mut replied: impl FnMut(UpdateStatus),
    ) {
        let stamp = seq * 1000;
        let mut stamps = Some(stamp);
        let cycles = &self.cycles;
        serve_samples_timed(
            &mut self.pacer,
            || stamps.take(),
            stamp,
            &mut self.inst.watchdog,
            lp,
            &mut self.bench,
            || {
                cycles.set(cycles.get().wrapping_add(1000));
                cycles.get()
            },
            |_, _| {},
        );
        let bench = &mut self.bench;
        let in_consumer = &mut self.in_consumer;
        commands::serve_commands(
            || uart::dequeue(in_consumer),
            &mut self.receiver,
            lp,
            &mut self.inst.store,
            &mut self.inst.watchdog,
            |r, _, _| {
                if r == Report::Bench {
                    bench.start();
                }
                report(r);
            },
            |status, _| replied(status),
        );
        while interrupts::serve_uart(
            &mut self.rx,
            &mut self.tx,
            &mut self.outgoing,
            &mut self.incoming,
            &self.rx_overruns,
        ) == Transmit::Sending
        {}
    }
}

fn rx_noise() -> Verdict {
    let mut storage: Model = Model::EMPTY;
    let (mut board, mut lp) = UartBoard::new(97, &mut storage);
    let identity = board.inst.store.identity();
    let mut state = 0x2545_F491u32;
    let (mut replies, mut installs, mut reports) = (0u32, 0u32, 0u32);
    for seq in 0..2000u32 {
        // 20 noise bytes a sample: mostly non-zero, a frame end now and then.
        for _ in 0..20 {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let byte = if state.is_multiple_of(23) {
                0
            } else {
                (state >> 8) as u8
            };
            board.receive(byte);
        }
        board.pass(
            &mut lp,
            seq,
            |_| reports += 1,
            |status| {
                replies += 1;
                installs += u32::from(status == UpdateStatus::Installed);
            },
        );
    }
    let frames = decode_frames(&board.tx.sent);
    let stats = lp.stats();
    let errors = board.rx_overruns.load(Ordering::Relaxed);
    ensure!(replies >= 100, "only {replies} noise frames");
    ensure!(installs == 0, "noise installed a model");
    ensure!(
        errors >= 400,
        "{errors} receive errors counted of 40,000 bytes, one in 97 in error"
    );
    ensure!(
        stats.filter_restarts == 1,
        "{} filter restarts (1 from the real install)",
        stats.filter_restarts
    );
    ensure!(
        frames.len() as u32 == stats.samples,
        "{} output frames through USART1 for {} samples",
        frames.len(),
        stats.samples
    );
    ensure!(board.inst.store.identity() == identity, "the running model changed");
    ensure!(
        frames.iter().all(|f| f.flags & Flags::NO_VALID_MODEL.bits() == 0),
        "the model stopped running"
    );
    Ok(format!(
        "40,000 noise bytes on RX during 2,000 samples, through USART1's interrupt logic and the loop's command path: {replies} frames refused or unknown, {reports} bench/health reports, {errors} receive errors counted, no filter restart from the noise, {} frames sent, model CRC {:#010x} kept",
        frames.len(),
        identity.blob_crc32
    ))
}

fn bench_over_the_uart() -> Verdict {
    let mut storage: Model = Model::EMPTY;
    let (mut board, mut lp) = UartBoard::new(0, &mut storage);
    let (mut benches, mut healths, mut replies) = (0u32, 0u32, 0u32);
    for seq in 0..1500u32 {
        // `bench` at sample 10, `health` at sample 1,200: COBS with its 0x00.
        let command = match seq {
            10 => Some(firmware::bench::CMD_BENCH),
            1200 => Some(firmware::health::CMD_HEALTH),
            _ => None,
        };
        if let Some(c) = command {
            let mut wire = [0u8; 4];
            let n = rbf_core::frame::cobs_encode(&[c], &mut wire).unwrap_or(0);
            for &b in &wire[..n] {
                board.receive(b);
            }
        }
        board.pass(
            &mut lp,
            seq,
            |r| match r {
                Report::Bench => benches += 1,
                Report::Health => healths += 1,
            },
            |_| replies += 1,
        );
    }
    // The bench report among the output frames: COBS([CMD_BENCH, steps, min, mean, max]).
    let mut sent = board.tx.sent.clone();
    let reports: Vec<[u32; 4]> = sent
        .split_mut(|&b| b == 0)
        .filter_map(|f| {
            let n = cobs_decode_in_place(f)?;
            let payload = f.get(..n)?;
            let (&cmd, fields) = payload.split_first()?;
            (cmd == firmware::bench::CMD_BENCH && fields.len() == 16).then(|| {
                let word = |i: usize| u32::from_le_bytes(fields[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]));
                [word(0), word(1), word(2), word(3)]
            })
        })
        .collect();
    let frames = decode_frames(&board.tx.sent);
    ensure!(
        (benches, healths, replies) == (1, 1, 0),
        "{benches} bench, {healths} health requests, {replies} replies (expected 1, 1, none: both answer with reports)"
    );
    ensure!(reports.len() == 1, "{} bench reports", reports.len());
    let [steps, min, mean, max] = reports[0];
    ensure!(
        steps == firmware::bench::BENCH_STEPS && (min, mean, max) == (1000, 1000, 1000),
        "bench report {:?}: expected 1000 steps of 1000 cycles",
        reports[0]
    );
    ensure!(frames.len() == 1500, "{} output frames for 1,500 samples", frames.len());
    Ok(format!(
        "`bench` and `health` over RX through USART1's logic and the command path: one bench report after {steps} timed steps (min/mean/max {min}/{mean}/{max} cycles), the health request handed to the board, no reply frame, {} output frames",
        frames.len()
    ))
}

fn main() -> ExitCode {
    let scenarios: [Scenario; 17] = [
        ("stuck SDA at boot", stuck_sda_at_boot),
        ("stuck bus at run time", stuck_bus_at_run_time),
        ("NACK storm", nack_storm),
        ("TMP117 answers late", late_thermometer),
        ("data-ready stuck high at boot", data_ready_stuck_high_at_boot),
        ("front end boots 2 s late", front_end_boots_late),
        ("front end resets", front_end_resets),
        ("200-ms loop stall", loop_stall),
        ("glitch on data-ready", data_ready_glitch),
        ("4-s erase at 47 kHz LSI", slow_erase_at_fast_lsi),
        ("flash error", flash_error),
        ("noise on RX", rx_noise),
        ("bench and health over RX", bench_over_the_uart),
        ("board loop: boot after a HardFault", real_loop::boot_after_a_fault),
        (
            "board loop: UART storm while sampling",
            real_loop::uart_storm_while_sampling,
        ),
        (
            "board loop: thermometer fails mid-run",
            real_loop::thermometer_fails_mid_run,
        ),
        ("board loop: install over RX", real_loop::install_through_the_loop),
    ];
    let mut failed = 0;
    for (name, scenario) in scenarios {
        match scenario() {
            Ok(what) => println!("{name}: ok: {what}"),
            Err(why) => {
                failed += 1;
                println!("{name}: FAILED: {why}");
            }
        }
    }
    println!("board faults: {} scenarios, {failed} failed", scenarios.len());
    if failed == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
