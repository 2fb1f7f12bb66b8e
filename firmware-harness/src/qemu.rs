//! What the QEMU board images emulate around the board's own code
//! (`firmware::board`, built with its feature `board-qemu`): the model
//! slots in emulated NOR flash, the TMP117s and front ends on a built-in
//! ramp or a recorded run (`run.csv`, the serving images), TIM3 as the
//! data-ready line, and the run's end with the stack's high-water mark
//! (`cargo xtask bench-fw`, board_stack_peak_bytes; `cargo xtask
//! qemu-board`; docs/firmware.md).
#![allow(unsafe_code)]
use core::cell::Cell;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_semihosting::{debug, hprintln};
use embedded_hal_bus::util::AtomicCell;
use firmware::board::{Board, BoardFlash, BoardModel, FlashHealth, Hooks, LoopHooks, Wiring, hw::Tim2Clock};
use firmware::compensation::{InPlaceModel, LoopStats, ModelHolder};
use firmware::model_store::SlotLayout;
use firmware::tmp117::Tmp117;
use firmware::update::UpdateStatus;
use stm32f4xx_hal::pac::{self, interrupt};

use crate::fault_injection::{EMULATED_LAYOUT, EMULATED_SLOT_LEN, ModelFlash};
use crate::replay::{EmulatedTmp117, ReplaySample};

/// Samples the run lasts at least, and at least this many after the update.
const SAMPLES: u32 = 10_000;
const SAMPLES_AFTER_UPDATE: u32 = 2_000;
/// Samples after which a run that never received an update gives up.
const SAMPLES_WITHOUT_UPDATE: u32 = 200_000;

/// The rate QEMU 7.2's STM32F2xx timers count at (their `clock-frequency`), Hz.
pub const TIMER_HZ: u32 = 1_000_000_000;

/// The model slots: QEMU maps flash as ROM and has no flash
/// controller, so they live in emulated NOR flash in RAM (the
/// board's [`firmware::model_store::ModelStore`] code runs on it).
/// Slot A starts as the blob QEMU's loader placed in flash slot A.
static mut FLASH: ModelFlash = ModelFlash::new();
/// Whether [`emulated_model_flash`] handed [`FLASH`] out: the one `&mut` to it.
static FLASH_OPENED: AtomicBool = AtomicBool::new(false);

/// The model slots' flash of the QEMU images: emulated NOR flash in RAM
/// ([`emulated_model_flash`]).
pub type SlotFlash = &'static mut ModelFlash;

impl BoardFlash for SlotFlash {
    const SLOTS: SlotLayout = EMULATED_LAYOUT;

    /// The emulated model flash, slot A seeded from the real slot A.
    #[inline(always)]
    fn open(_tim2: Tim2Clock) -> Self {
        emulated_model_flash()
    }
}

impl FlashHealth for SlotFlash {
    /// Its slots are emulated: no flash operation fails.
    #[inline(always)]
    fn errors(&self) -> u32 {
        0
    }
}

/// Sets the board up ([`Board::setup_with_slots`]) with its model slots
/// in the emulated flash.
#[inline(always)]
pub fn setup() -> (Board<SlotFlash>, Wiring) {
    Board::setup_with_slots()
}

/// The serving images' board, run source and first readings: TIM2 taken
/// at QEMU's timer clock (samples at 1 kHz of real time, no -icount), the
/// sensors answering from `run.csv` or the built-in ramp ([`RunSource`]).
/// SPI1 stays set up and unused: QEMU has no front end on it.
#[inline(always)]
pub fn serving<const AXES: usize>() -> (Board<SlotFlash>, RunSource<AXES>, Readings<AXES>) {
    let (mut board, _wiring) = setup();
    board.timer_hz = TIMER_HZ;
    let mut source = RunSource::<AXES>::open();
    let readings = source.next(0).map(Cell::new);
    (board, source, readings)
}

/// Runs the three-axis board image holding models `M` on the built-in ramp
/// (`stm32f405-axes-qemu`, `stm32f405-axes-shared-qemu`): three coils, each
/// half a degree warmer than the last, the board's own front ends on SPI1.
#[inline(always)]
pub fn run_axes_on_ramp<M, const K: usize>() -> !
where
    M: BoardModel,
    for<'m> InPlaceModel<'m, M>: ModelHolder<K, 3>,
{
    let (board, wiring) = setup();
    let readings = ramp::<3>();
    let thermometers = coil_thermometers(&readings);
    let spi = AtomicCell::new(wiring.spi);
    let front_ends = firmware::board::axis_front_ends(&spi, wiring.cs, wiring.delay);
    board.run::<M, _, _, _, K, 3>(thermometers, front_ends, Emulation::new(&readings, Ramp))
}

/// The emulated model flash, slot A seeded from the real slot A.
///
/// # Panics
/// Opened a second time: the image would hold two `&mut` to one flash
/// (a defect of the image, found on its first run under QEMU).
pub fn emulated_model_flash() -> &'static mut ModelFlash {
    assert!(
        !FLASH_OPENED.swap(true, Ordering::AcqRel),
        "the emulated model flash is opened once"
    );
    let flash = &raw mut FLASH;
    // SAFETY: FLASH_OPENED lets this line run once: the only reference.
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
/// (`stm32f405-qemu-serve`) sends with it.
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
pub struct RunSource<const AXES: usize> {
    lines: Option<crate::host_file::HostLines>,
    columns: Option<[Option<rbf_core::record::Columns>; AXES]>,
}

impl<const AXES: usize> RunSource<AXES> {
    /// The run in `run.csv`, if QEMU's directory holds one.
    pub fn open() -> Self {
        RunSource {
            lines: crate::host_file::HostLines::open(RUN_FILE),
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
            *lines = crate::host_file::HostLines::open(RUN_FILE);
            *columns = None;
        }
        samples
    }
}

/// The run file of [`RunSource`], NUL-terminated for semihosting.
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
    /// The serving image: never exits by itself.
    serve: bool,
}

impl Run {
    /// A run; the serving image's (`serve`) lasts until QEMU is stopped.
    pub fn new(serve: bool) -> Run {
        Run {
            updated: None,
            samples: 0,
            serve,
        }
    }

    /// Starts the data-ready source: TIM3 (which QEMU emulates) at
    /// one period of `period_ticks` TIM2 ticks pends EXTI0, whose
    /// handler (the board's) stamps the edge as on the board, where
    /// the front end's data-ready line raises it (QEMU has no GPIO).
    pub fn start(&mut self, nvic: &mut cortex_m::peripheral::NVIC, period_ticks: u32) {
        // SAFETY: TIM3 is the QEMU images' own: nothing else uses it.
        let tim3 = unsafe { &*pac::TIM3::ptr() };
        tim3.psc().write(|w| w.psc().set(0));
        tim3.arr().write(|w| unsafe { w.bits(period_ticks.saturating_sub(1)) });
        tim3.dier().write(|w| w.uie().set_bit());
        tim3.cr1().modify(|_, w| w.cen().set_bit());
        // SAFETY: the handler only pends EXTI0, whose state is in place.
        unsafe {
            nvic.set_priority(pac::Interrupt::TIM3, 0x40);
            cortex_m::peripheral::NVIC::unmask(pac::Interrupt::TIM3);
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
        if self.serve {
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

/// What the emulated sensors of a QEMU image answer: one cell per coil
/// (the TMP117 on [`thermometer_bus`], and the serving image's front end,
/// [`crate::replay::EmulatedFrontEnd`], read it).
pub type Readings<const AXES: usize> = [Cell<ReplaySample>; AXES];

/// The built-in ramp's first sample for each of `AXES` coils.
pub fn ramp<const AXES: usize>() -> Readings<AXES> {
    core::array::from_fn(|axis| Cell::new(axis_sample(0, axis)))
}

/// Where a QEMU image's readings come from, sample by sample.
pub trait Source<const AXES: usize> {
    /// The serving image's sources: it runs until QEMU is stopped.
    const SERVES: bool;
    /// What the sensors present for sample `seq`.
    fn next(&mut self, seq: u32) -> [ReplaySample; AXES];
}

/// The built-in ramp ([`axis_sample`]): the measuring images' source.
#[derive(Clone, Copy, Debug, Default)]
pub struct Ramp;

impl<const AXES: usize> Source<AXES> for Ramp {
    const SERVES: bool = false;
    fn next(&mut self, seq: u32) -> [ReplaySample; AXES] {
        core::array::from_fn(|axis| axis_sample(seq, axis))
    }
}

impl<const AXES: usize> Source<AXES> for RunSource<AXES> {
    const SERVES: bool = true;
    fn next(&mut self, seq: u32) -> [ReplaySample; AXES] {
        RunSource::next(self, seq)
    }
}

/// The QEMU images' additions to the board's loop: TIM3 as the data-ready
/// source, the next readings from `S` after each step ([`Ramp`], or the
/// serving image's [`RunSource`]) and the run's end (the serving image
/// runs until QEMU is stopped).
pub struct Emulation<'a, S, const AXES: usize> {
    readings: &'a Readings<AXES>,
    source: S,
    run: Run,
}

impl<'a, S: Source<AXES>, const AXES: usize> Emulation<'a, S, AXES> {
    /// The loop's additions, the sensors answering `readings`, refreshed from `source`.
    pub fn new(readings: &'a Readings<AXES>, source: S) -> Self {
        Emulation {
            readings,
            source,
            run: Run::new(S::SERVES),
        }
    }
}

impl<S: Source<AXES>, const AXES: usize> Hooks for Emulation<'_, S, AXES> {
    fn start(&mut self, nvic: &mut cortex_m::peripheral::NVIC, period_ticks: u32) {
        self.run.start(nvic, period_ticks);
    }
}

impl<S: Source<AXES>, const AXES: usize> LoopHooks for Emulation<'_, S, AXES> {
    fn stepped(&mut self, seq: u32) {
        for (cell, sample) in self.readings.iter().zip(self.source.next(seq)) {
            cell.set(sample);
        }
    }

    fn replied(&mut self, status: UpdateStatus, _model_loaded: bool) {
        self.run.replied(status);
    }

    fn served(&mut self, stats: &LoopStats) {
        self.run.check(stats);
    }
}

/// The loop TMP117 on an emulated bus, answering `reading`.
pub fn thermometer(reading: &Cell<ReplaySample>) -> Tmp117<EmulatedTmp117<'_>> {
    Tmp117::new(thermometer_bus(reading), firmware::tmp117::DEFAULT_ADDRESS)
}

/// A TMP117 per coil, each on its own emulated bus answering its coil's reading.
pub fn coil_thermometers<const AXES: usize>(readings: &Readings<AXES>) -> [Tmp117<EmulatedTmp117<'_>>; AXES] {
    core::array::from_fn(|axis| thermometer(&readings[axis]))
}
