//! Replay of a recorded run through the real drivers and loop.
//!
//! [`EmulatedTmp117`] and [`EmulatedFrontEnd`] implement the embedded-hal 1.0
//! I2C and SPI traits and answer as the devices would for the current row:
//! two emulated I2C buses carry the eight TMP117s `temp_a` … `temp_h` of a
//! multi-point board (`temp_c`, the loop sensor, among them); a thermometer
//! without a value in the row (no such column, or `temp_fault` = 1) NACKs;
//! the rate goes out as the front end's binary32 word. [`Replayer`] feeds a
//! run line by line through [`Tmp117Array`], [`FrontEnd`] and
//! [`CompensationLoop`], per axis (one for a single gyro's run), and writes
//! the compensated run exactly as `trainer compensate` does (same row
//! parser, period rule, time step and row formatter from rbf-core), so the
//! two are byte-identical.
//! The QEMU board reads and writes the files over semihosting; host tests use
//! the same code.

use core::cell::Cell;

use embedded_hal::i2c::{self, I2c, NoAcknowledgeSource};
use embedded_hal::spi::{self, SpiDevice};
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::record::{self, Columns, HeaderError, RowError};
use rbf_core::sensor::tmp117_raw;
use rbf_core::{CompensatorConfig, MAX_CENTERS};

use firmware::compensation::{CompensationLoop, LoopConfig, LoopStats, ModelHolder};
use firmware::frontend::{self, FrontEnd};
use firmware::tmp117::{self, Tmp117Array};

/// What the buses present for the current row.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReplaySample {
    /// Thermometers `temp_a` … `temp_h`, °C; `None` makes that TMP117 NACK.
    pub temps_c: [Option<f64>; THERMOMETERS],
    /// Rate word the front end sends, °/h.
    pub rate_dph: f32,
}

impl ReplaySample {
    /// A sample with the loop sensor (`temp_c`) alone.
    pub fn with_loop(temp_c: Option<f64>, rate_dph: f32) -> Self {
        let mut temps_c = [None; THERMOMETERS];
        temps_c[LOOP_THERMOMETER] = temp_c;
        ReplaySample { temps_c, rate_dph }
    }

    /// The loop sensor's value.
    pub fn loop_temp_c_mut(&mut self) -> &mut Option<f64> {
        &mut self.temps_c[LOOP_THERMOMETER]
    }
}

/// One I2C bus with four TMP117s (at [`tmp117::ADDRESSES`]) answering from
/// the current replay row: thermometers `first` … `first + 3`.
#[derive(Debug)]
pub struct EmulatedTmp117<'c> {
    current: &'c Cell<ReplaySample>,
    first: usize,
}

impl<'c> EmulatedTmp117<'c> {
    /// The bus carrying thermometers `first` … `first + 3` of `current`.
    pub fn new(current: &'c Cell<ReplaySample>, first: usize) -> Self {
        EmulatedTmp117 { current, first }
    }
}

impl i2c::ErrorType for EmulatedTmp117<'_> {
    type Error = i2c::ErrorKind;
}

impl I2c for EmulatedTmp117<'_> {
    fn transaction(&mut self, address: u8, operations: &mut [i2c::Operation<'_>]) -> Result<(), Self::Error> {
        let nack = i2c::ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);
        let Some(k) = tmp117::ADDRESSES.iter().position(|&a| a == address) else {
            return Err(nack);
        };
        let thermometer = self.first + k;
        match operations {
            [i2c::Operation::Write([register]), i2c::Operation::Read(buf)] if buf.len() == 2 => {
                let value = match *register {
                    tmp117::REG_DEVICE_ID => tmp117::DEVICE_ID,
                    tmp117::REG_CONFIGURATION => tmp117::CONFIG_CONTINUOUS_AVG8,
                    tmp117::REG_TEMP_RESULT => match self.current.get().temps_c.get(thermometer) {
                        Some(Some(t)) => tmp117_raw(*t) as u16,
                        _ => return Err(nack),
                    },
                    _ => return Err(i2c::ErrorKind::Other),
                };
                buf.copy_from_slice(&value.to_be_bytes());
                Ok(())
            }
            [i2c::Operation::Write([tmp117::REG_CONFIGURATION, _, _])] => Ok(()),
            _ => Err(i2c::ErrorKind::Other),
        }
    }
}

/// The IFOG front end answering from the current replay row (scale factor
/// 1); each SAMPLE read is a new sample (its counter advances).
#[derive(Debug)]
pub struct EmulatedFrontEnd<'c> {
    current: &'c Cell<ReplaySample>,
    counter: u8,
}

impl<'c> EmulatedFrontEnd<'c> {
    /// A front end reading `current`.
    pub fn new(current: &'c Cell<ReplaySample>) -> Self {
        EmulatedFrontEnd { current, counter: 0 }
    }
}

impl spi::ErrorType for EmulatedFrontEnd<'_> {
    type Error = spi::ErrorKind;
}

impl SpiDevice for EmulatedFrontEnd<'_> {
    fn transaction(&mut self, operations: &mut [spi::Operation<'_, u8>]) -> Result<(), Self::Error> {
        let [spi::Operation::Write([command]), spi::Operation::Read(buf)] = operations else {
            return Err(spi::ErrorKind::Other);
        };
        let command = *command;
        let mut reply = [0u8; frontend::SAMPLE_LEN];
        let len = match command & !frontend::READ {
            frontend::REG_WHO_AM_I => {
                reply[..2].copy_from_slice(&frontend::WHO_AM_I.to_be_bytes());
                2
            }
            frontend::REG_SCALE_FACTOR => {
                reply[..4].copy_from_slice(&1.0f32.to_bits().to_be_bytes());
                4
            }
            frontend::REG_SAMPLE => {
                self.counter = self.counter.wrapping_add(1);
                reply =
                    frontend::encode_counted_sample(frontend::STATUS_VALID, self.counter, self.current.get().rate_dph);
                frontend::SAMPLE_LEN
            }
            _ => return Err(spi::ErrorKind::Other),
        };
        let out = buf
            .get_mut(..)
            .filter(|b| b.len() == len)
            .ok_or(spi::ErrorKind::Other)?;
        out.copy_from_slice(&reply[..len]);
        Ok(())
    }
}

/// Why a replay stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplayError {
    /// The header line is unusable.
    Header(HeaderError),
    /// A data row (1-based line number) is malformed.
    Row(u32, RowError),
    /// The emulated devices did not initialise (a bug, not an input problem).
    DeviceInit,
    /// The CSV output refused a write.
    Output,
}

impl From<core::fmt::Error> for ReplayError {
    fn from(_: core::fmt::Error) -> Self {
        ReplayError::Output
    }
}

/// First pass over a run: the nominal period by the shared rule
/// ([`record::PeriodEstimator`]), fed line by line.
#[derive(Debug, Default)]
pub struct PeriodProbe {
    estimator: record::PeriodEstimator,
    columns: Option<Columns>,
    line: u32,
}

impl PeriodProbe {
    /// Consumes one line; `Ok(true)` once enough is known (the rest need not be read).
    pub fn feed_line(&mut self, line: &str) -> Result<bool, ReplayError> {
        self.line += 1;
        let text = clean(line, self.line);
        let Some(columns) = &self.columns else {
            if record::is_comment_or_blank(text) {
                self.estimator.note_preamble_line(text);
            } else {
                self.columns = Some(Columns::from_header(text).map_err(ReplayError::Header)?);
            }
            return Ok(false);
        };
        if self.estimator.is_complete() {
            return Ok(true);
        }
        if record::is_comment_or_blank(text) {
            return Ok(false);
        }
        let row = columns.parse_row(text).map_err(|e| ReplayError::Row(self.line, e))?;
        Ok(self.estimator.push_time(row.time_s))
    }

    /// True once the header is read and names per-axis rates (`rate_x_dph` …).
    pub fn is_multi_axis(&self) -> bool {
        self.columns.as_ref().is_some_and(Columns::is_multi_axis)
    }

    /// The nominal period, s.
    pub fn period_s(&mut self) -> f64 {
        self.estimator.period_s()
    }
}

/// First pass over all `lines`: the nominal period, s.
pub fn probe_period<'a>(lines: impl IntoIterator<Item = &'a str>) -> Result<f64, ReplayError> {
    let mut probe = PeriodProbe::default();
    for line in lines {
        if probe.feed_line(line)? {
            break;
        }
    }
    Ok(probe.period_s())
}

fn clean(line: &str, line_no: u32) -> &str {
    let line = if line_no == 1 {
        line.strip_prefix('\u{feff}').unwrap_or(line)
    } else {
        line
    };
    line.strip_suffix('\n').unwrap_or(line).trim_end_matches('\r')
}

/// The replay's thermometers: eight TMP117s on two emulated buses.
pub type ReplayThermometers<'c> = Tmp117Array<EmulatedTmp117<'c>, EmulatedTmp117<'c>>;

/// The replay loop: per axis, eight TMP117s on two emulated buses and a
/// front end, all answering from that axis's cell; `M` holds the models
/// ([`ModelHolder`]: a single gyro's, a model per axis, or a shared basis).
pub type ReplayLoop<'c, W, M, const K: usize = MAX_CENTERS, const N: usize = 1> =
    CompensationLoop<[ReplayThermometers<'c>; N], [FrontEnd<EmulatedFrontEnd<'c>>; N], W, M, K, N>;

/// Second pass: feeds every row through the drivers and the loop and
/// writes the compensated run as `trainer compensate` writes it, one frame
/// per row. `N` is the loop's axis count: 1 for a single gyro's run
/// (`rate_dph`; `bias_dph`, `rate_comp_dph`, `flags` appended, single-axis
/// frames), [`rbf_core::axis::MAX_AXES`] for a multi-axis run (`rate_x_dph` …; per axis
/// present `bias_<axis>_dph`, `rate_comp_<axis>_dph`, `flags_<axis>`,
/// [`gyro_wire::frame::AxesFrame`]s).
///
/// Each axis's devices answer from the row as that axis reads it
/// ([`Columns::for_axis`]): its rate, `temp_<axis>_c` (else `temp_c`) as
/// its loop thermometer, the shared `temp_a` … `temp_h` as the others.
/// `M` is `Option<&Model>` (a single gyro), `Option<&AxisModels<K>>` (a
/// model per axis) or `Option<&SharedAxisModels<K>>` (one basis for every
/// axis, stepped by [`rbf_core::Compensator::process_shared`] on the first
/// axis's thermometers, as `trainer compensate` steps it).
///
/// [`AxisModels<K>`]: rbf_core::blob::axes::AxisModels
/// [`SharedAxisModels<K>`]: rbf_core::shared_basis::SharedAxisModels
pub struct Replayer<'c, W, M, const K: usize = MAX_CENTERS, const N: usize = 1> {
    current: &'c [Cell<ReplaySample>; N],
    compensation: ReplayLoop<'c, W, M, K, N>,
    /// Per axis present, its columns.
    axes: [Option<Columns>; N],
    header_read: bool,
    prev_time_s: Option<f64>,
    line: u32,
}

impl<'c, W: embedded_io::Write, M: ModelHolder<K, N>, const K: usize, const N: usize> Replayer<'c, W, M, K, N> {
    /// A replayer over `models` for a run of nominal period `period_s`,
    /// each axis's devices answering from its cell of `current`; frames go
    /// to `frames`. Which axes run comes from the run's header.
    pub fn new(models: M, period_s: f64, current: &'c [Cell<ReplaySample>; N], frames: W) -> Result<Self, ReplayError> {
        let mut thermometers = current.each_ref().map(|c| {
            Tmp117Array::new(
                EmulatedTmp117::new(c, 0),
                EmulatedTmp117::new(c, tmp117::PER_BUS),
                u8::MAX,
            )
        });
        let mut front_ends = current.each_ref().map(|c| FrontEnd::new(EmulatedFrontEnd::new(c)));
        for (thermometer, front_end) in thermometers.iter_mut().zip(&mut front_ends) {
            if thermometer.init() != 0 {
                return Err(ReplayError::DeviceInit);
            }
            front_end.init().map_err(|_| ReplayError::DeviceInit)?;
        }
        let config = LoopConfig {
            compensator: CompensatorConfig::for_nominal_period_s(period_s),
            temp_read_every: 1,
        };
        Ok(Replayer {
            current,
            compensation: CompensationLoop::new(models, config, thermometers, front_ends, frames),
            axes: [None; N],
            header_read: false,
            prev_time_s: None,
            line: 0,
        })
    }

    /// Consumes one input line and writes what `trainer compensate` writes for it.
    pub fn feed_line(&mut self, line: &str, out: &mut impl core::fmt::Write) -> Result<(), ReplayError> {
        self.line += 1;
        let text = clean(line, self.line);
        if !self.header_read {
            if record::is_comment_or_blank(text) {
                writeln!(out, "{text}")?;
                return Ok(());
            }
            let columns = Columns::from_header(text).map_err(ReplayError::Header)?;
            let mut mask = 0u8;
            if N > 1 {
                for axis in columns.axes_present() {
                    if let Some(slot) = self.axes.get_mut(axis.index()) {
                        *slot = columns.for_axis(axis);
                        mask |= 1 << axis.index();
                    }
                }
            }
            if mask == 0 {
                // A single gyro's run (or a single gyro's replay): `rate_dph` serves as axis x.
                if let Some(slot) = self.axes.first_mut() {
                    *slot = Some(columns);
                }
                mask = 1;
            }
            self.header_read = true;
            self.compensation.set_axis_mask(mask);
            if N == 1 {
                writeln!(out, "{text}{}", record::COMPENSATED_COLUMNS)?;
            } else {
                record::write_compensated_header(out, text, &columns)?;
            }
            return Ok(());
        }
        if record::is_comment_or_blank(text) {
            return Ok(());
        }
        let mut time_s = None;
        for (columns, cell) in self.axes.iter().zip(self.current) {
            let Some(columns) = columns else {
                continue;
            };
            let row = columns.parse_row(text).map_err(|e| ReplayError::Row(self.line, e))?;
            time_s.get_or_insert(row.time_s);
            cell.set(ReplaySample {
                temps_c: row.readings_c(),
                rate_dph: row.rate_dph as f32,
            });
        }
        let time_s = time_s.ok_or(ReplayError::DeviceInit)?;
        let dt_s = rbf_core::compensator::time_step_s(self.prev_time_s, time_s);
        self.prev_time_s = Some(time_s);
        let samples = self.compensation.step(dt_s);
        let mut present = samples;
        let mut n = 0;
        for (columns, sample) in self.axes.iter().zip(samples) {
            if columns.is_some()
                && let Some(slot) = present.get_mut(n)
            {
                *slot = sample;
                n += 1;
            }
        }
        record::write_compensated_row(out, text, present.get(..n).unwrap_or(&[]))?;
        Ok(())
    }

    /// Health counters of the loop.
    pub fn stats(&self) -> LoopStats {
        self.compensation.stats()
    }

    /// Thermometer reads that failed, per axis (x first).
    pub fn temp_read_faults_per_axis(&self) -> [u32; N] {
        self.compensation.temp_read_faults_per_axis()
    }
}
