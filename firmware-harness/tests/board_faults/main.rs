//! The board's fault campaign, a test target (`cargo test` runs it: `cargo
//! test -p firmware-harness --test board_faults`; `cargo xtask
//! board-faults`): the stm32f405 board's own code on the host against
//! simulated peripherals that misbehave on purpose, on a simulated clock.
//! The sample and command scenarios run the board's run loop itself
//! (`firmware::board::run_loop::BoardLoop`, what `Board::run` calls: its
//! start, then a pass per wake-up) with the USART1 and EXTI0 handlers'
//! bodies (`firmware::interrupts`) run as their interrupts arrive between
//! passes (`real_loop`); under it the bounded I2C master with bus recovery,
//! the TMP117 and front-end drivers, the pacer, the flash controller
//! driver and the model store. The flash scenarios drive the install path
//! directly. One line per scenario with what happened, then `board faults:
//! N scenarios, M failed`; the exit code is non-zero when any failed.
//! docs/firmware.md, "Faults the board survives".

mod sim;

use std::cell::RefCell;
use std::process::ExitCode;
use std::rc::Rc;
use std::sync::atomic::Ordering;

use firmware::compensation::{CompensationLoop, InPlaceModel, LoopConfig, LoopStats};
use firmware::flash_ctl::{self, ControllerFlash};
use firmware::model_store::{ModelStore, SlotLayout};
use firmware::sensors::{RateFrontEnd, RateSample, SensorFault, Thermometer};
use firmware::update::{self, UpdateStatus};
use firmware::watchdog::{LSI_FASTEST_HZ, SECTOR_ERASE_WORST_MS, Watchdog, running_setting};
use gyro_wire::frame::{self, OutputFrame};
use rbf_core::axis::Axis;
use rbf_core::{CompensatorConfig, Flags, Model};
use sim::{FlashSim, FrontEndSim, I2cSim, SimClock, SimWatchdog};

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

/// The single-axis board: its own loop (`BoardLoop`) and the handlers' bodies on the simulations.
use real_loop::{BootWith, SimBoard as Board};

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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
    let mut lines = Vec::new();
    // As `Board::run` starts (EXTI0 pended for the high line), and with
    // that edge lost: the steps on the silence must still acknowledge it.
    for pended in [true, false] {
        let (clock, i2c, fe) = setup(0);
        {
            let mut f = fe.borrow_mut();
            f.level_high = true;
            f.counter = 42;
        }
        let with = BootWith {
            pend_high_data_ready: pended,
            ..BootWith::default()
        };
        let mut board = Board::boot_on(&clock, &i2c, &fe, with);
        board.run_until(1_000_000);
        let frames = board.frames();
        check_sequence(&frames, &board.stats())?;
        let synthetic = board.pacer_counters().synthetic;
        let (_, _, dog) = board.finish();
        ensure!(dog.check().expired_at_us.is_none(), "the watchdog reset the chip");
        if pended {
            ensure!(synthetic == 0, "{synthetic} synthetic steps though EXTI0 was pended");
        } else {
            ensure!((1..=3).contains(&synthetic), "{synthetic} synthetic steps");
        }
        ensure!(frames.len() >= 990, "{} frames in 1 s", frames.len());
        let invalid = frames.iter().filter(|f| flagged(f, Flags::RATE_INVALID)).count();
        ensure!(invalid <= 3, "{invalid} frames flagged 16");
        lines.push(format!(
            "{}: {synthetic} step(s) on the silence, {} frames in 1 s, {invalid} flagged 16",
            if pended {
                "EXTI0 pended at start"
            } else {
                "that edge lost"
            },
            frames.len()
        ));
    }
    Ok(format!(
        "data-ready high from before the reset, no edge (the first step reads SAMPLE, acknowledging it; edges resume): {}",
        lines.join("; ")
    ))
}

fn front_end_boots_late() -> Verdict {
    let (clock, i2c, fe) = setup(2_000_000);
    // Its samples come 100 ms before its scale factor is valid.
    fe.borrow_mut().scale_from_us = 2_100_000;
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
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
        let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
        board.stalls.push((500_000, 200_000));
        board.run_until(1_000_000);
        let frames = board.frames();
        let stats = board.stats();
        check_sequence(&frames, &stats)?;
        let backlog = board.pacer_counters().backlog;
        let overruns = board.stamp_overruns();
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
    let mut board = Board::boot_on(&clock, &i2c, &fe, BootWith::default());
    board.run_until(1_000_000);
    let frames = board.frames();
    let stats = board.stats();
    check_sequence(&frames, &stats)?;
    let glitches = board.pacer_counters().glitches;
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
    let mut payload = vec![gyro_wire::command::CMD_INSTALL_MODEL];
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

/// A model installed over RX through the board's loop at its start (filters restarted once).
fn board_with_model() -> Result<Board, String> {
    let mut board = Board::boot(BootWith::default());
    let model = firmware_harness::fault_injection::cubic_model().ok_or("no cubic model")?;
    board.send_at(1_000, &real_loop::command_frame(&install_payload(&model)));
    board.run_until(100_000);
    let installed = board.board.hooks_mut().replies.first().copied();
    ensure!(
        installed == Some((UpdateStatus::Installed, true)),
        "the model's install: {installed:?}"
    );
    board.board.hooks_mut().replies.clear();
    Ok(board)
}

fn rx_noise() -> Verdict {
    let mut board = board_with_model()?;
    let identity = board.board.store().identity();
    board.rx.error_every = 97;
    let mut state = 0x2545_F491u32;
    // 20 noise bytes a sample for 2 s from the end of the install's erase:
    // mostly non-zero, a frame end now and then.
    let from_us = board.clock.now_us();
    for ms in 0..2000u64 {
        let bytes = real_loop::noise(&mut state, 20);
        board.send_at(from_us + ms * 1000, &bytes);
    }
    board.run_until(from_us + 2_000_000);
    let frames = board.frames();
    let stats = board.stats();
    check_sequence(&frames, &stats)?;
    let replies = board.board.hooks_mut().replies.clone();
    let installs = replies.iter().filter(|(s, _)| *s == UpdateStatus::Installed).count();
    let errors = board.counters.rx_overruns.load(Ordering::Relaxed);
    ensure!(replies.len() >= 100, "only {} noise frames", replies.len());
    ensure!(installs == 0, "noise installed a model");
    ensure!(
        (400..=420).contains(&errors),
        "{errors} receive errors counted of 40,000 bytes, one in 97 in error"
    );
    ensure!(
        stats.filter_restarts == 1,
        "{} filter restarts (1 from the real install)",
        stats.filter_restarts
    );
    ensure!(board.board.store().identity() == identity, "the running model changed");
    ensure!(
        frames
            .iter()
            .filter(|f| u64::from(f.seq) * 1000 >= from_us)
            .all(|f| f.flags & Flags::NO_VALID_MODEL.bits() == 0),
        "the model stopped running"
    );
    Ok(format!(
        "40,000 noise bytes on RX during 2,000 samples, through USART1's handler body and the board's loop: {} frames refused or unknown, {errors} receive errors counted, no filter restart from the noise, {} frames sent, model CRC {:#010x} kept",
        replies.len(),
        frames.len(),
        identity.blob_crc32
    ))
}

fn bench_over_the_uart() -> Verdict {
    let mut board = Board::boot(BootWith::default());
    // `bench` at 10 ms, `health` at 1.2 s: COBS with its 0x00.
    board.send_at(10_000, &real_loop::command_frame(&[gyro_wire::command::CMD_BENCH]));
    board.send_at(1_200_000, &real_loop::command_frame(&[gyro_wire::command::CMD_HEALTH]));
    board.run_until(1_500_000);
    // The bench report among the output frames: [CMD_BENCH, steps, min, mean, max].
    let reports: Vec<[u32; 4]> = board
        .sent_payloads()
        .iter()
        .filter_map(|payload| {
            let (&cmd, fields) = payload.split_first()?;
            (cmd == gyro_wire::command::CMD_BENCH && fields.len() == 16).then(|| {
                let word = |i: usize| u32::from_le_bytes(fields[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]));
                [word(0), word(1), word(2), word(3)]
            })
        })
        .collect();
    let frames = board.frames();
    let healths = board.health_reports().len();
    let heard = &board.board.hooks_mut().benched;
    let benched = heard.len();
    let replies = board.board.hooks_mut().replies.len();
    ensure!(
        (benched, healths, replies) == (1, 2, 0),
        "{benched} bench reports heard, {healths} health reports (boot and request), {replies} replies (expected 1, 2, none)"
    );
    ensure!(reports.len() == 1, "{} bench reports sent", reports.len());
    let [steps, min, mean, max] = reports[0];
    ensure!(
        steps == firmware::bench::BENCH_STEPS && 0 < min && min <= mean && mean <= max,
        "bench report {:?}: expected {} steps, 0 < min ≤ mean ≤ max",
        reports[0],
        firmware::bench::BENCH_STEPS
    );
    ensure!(frames.len() >= 1495, "{} output frames in 1.5 s", frames.len());
    Ok(format!(
        "`bench` and `health` over RX through USART1's handler body and the board's loop: one bench report after {steps} timed steps (min/mean/max {min}/{mean}/{max} simulated µs), a health report, no reply frame, {} output frames",
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
