//! Replay of a recorded run through the real drivers and loop.
//!
//! [`EmulatedTmp117`] and [`EmulatedFrontEnd`] implement the embedded-hal 1.0
//! I2C and SPI traits and answer as the devices would for the current row:
//! two emulated I2C buses carry the eight TMP117s `temp_a` … `temp_h` of a
//! multi-point board (`temp_c`, the loop sensor, among them); a thermometer
//! without a value in the row (no such column, or `temp_fault` = 1) NACKs;
//! the rate goes out as the front end's binary32 word. [`Replayer`] feeds a
//! run line by line through [`Tmp117Array`], [`FrontEnd`] and
//! [`CompensationLoop`] and writes the compensated
//! run exactly as `trainer compensate` does (same row parser, period rule,
//! time step and row formatter from rbf-core), so the two are byte-identical.
//! The QEMU board reads and writes the files over semihosting; host tests use
//! the same code.

use core::cell::Cell;

use embedded_hal::i2c::{self, I2c, NoAcknowledgeSource};
use embedded_hal::spi::{self, SpiDevice};
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::record::{self, Columns, HeaderError, RowError};
use rbf_core::sensor::tmp117_raw;
use rbf_core::{CompensatorConfig, Model};

use crate::compensation::{CompensationLoop, LoopConfig, LoopStats};
use crate::frontend::{self, FrontEnd};
use crate::tmp117::{self, Tmp117Array};

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

/// The IFOG front end answering from the current replay row (scale factor 1).
#[derive(Debug)]
pub struct EmulatedFrontEnd<'c> {
    current: &'c Cell<ReplaySample>,
}

impl<'c> EmulatedFrontEnd<'c> {
    /// A front end reading `current`.
    pub fn new(current: &'c Cell<ReplaySample>) -> Self {
        EmulatedFrontEnd { current }
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
                reply = frontend::encode_sample(frontend::STATUS_VALID, self.current.get().rate_dph);
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

/// The replay loop type: real drivers over emulated buses.
pub type ReplayLoop<'c, W> = CompensationLoop<ReplayThermometers<'c>, FrontEnd<EmulatedFrontEnd<'c>>, W>;

/// Second pass: feeds rows through the loop and writes the compensated run.
pub struct Replayer<'c, W> {
    current: &'c Cell<ReplaySample>,
    compensation: ReplayLoop<'c, W>,
    columns: Option<Columns>,
    prev_time_s: Option<f64>,
    line: u32,
}

impl<'c, W: embedded_io::Write> Replayer<'c, W> {
    /// A replayer over `model` for a run of nominal period `period_s`; frames go to `frames`.
    pub fn new(
        model: Option<&Model>,
        period_s: f64,
        current: &'c Cell<ReplaySample>,
        frames: W,
    ) -> Result<Self, ReplayError> {
        let mut thermometer = Tmp117Array::new(
            EmulatedTmp117::new(current, 0),
            EmulatedTmp117::new(current, tmp117::PER_BUS),
            u8::MAX,
        );
        if thermometer.init() != 0 {
            return Err(ReplayError::DeviceInit);
        }
        let mut front_end = FrontEnd::new(EmulatedFrontEnd::new(current));
        front_end.init().map_err(|_| ReplayError::DeviceInit)?;
        let config = LoopConfig {
            compensator: CompensatorConfig::for_nominal_period_s(period_s),
            temp_read_every: 1,
        };
        Ok(Replayer {
            current,
            compensation: CompensationLoop::new(model.cloned(), config, thermometer, front_end, frames),
            columns: None,
            prev_time_s: None,
            line: 0,
        })
    }

    /// Consumes one input line and writes what `trainer compensate` writes for it.
    pub fn feed_line(&mut self, line: &str, out: &mut impl core::fmt::Write) -> Result<(), ReplayError> {
        self.line += 1;
        let text = clean(line, self.line);
        let Some(columns) = &self.columns else {
            if record::is_comment_or_blank(text) {
                writeln!(out, "{text}")?;
            } else {
                self.columns = Some(Columns::from_header(text).map_err(ReplayError::Header)?);
                writeln!(out, "{text}{}", record::COMPENSATED_COLUMNS)?;
            }
            return Ok(());
        };
        if record::is_comment_or_blank(text) {
            return Ok(());
        }
        let row = columns.parse_row(text).map_err(|e| ReplayError::Row(self.line, e))?;
        self.current.set(ReplaySample {
            temps_c: row.readings_c(),
            rate_dph: row.rate_dph as f32,
        });
        let dt_s = record::time_step_s(self.prev_time_s, row.time_s);
        self.prev_time_s = Some(row.time_s);
        let sample = self.compensation.step(dt_s);
        record::write_compensated_row(out, text, &sample)?;
        Ok(())
    }

    /// Health counters of the loop.
    pub fn stats(&self) -> LoopStats {
        self.compensation.stats()
    }
}
