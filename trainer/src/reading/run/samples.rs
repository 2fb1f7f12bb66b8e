//! A run's rows as samples, above the reader: held in memory ([`Run`]) or streamed
//! once from a [`RunReader`] ([`StreamedRun`]), with the reference rate
//! ([`Reference`]) and each row's thermometer readings.

use std::path::{Path, PathBuf};

use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::record::Row;
use rbf_core::thermometer::ThermometerSet;
use rbf_core::{CompensatorConfig, GyroSample};

use super::{RawRow, RunError, RunReader};
use crate::reading::chunked::Batch;

/// A whole run in memory, column-wise.
#[derive(Clone, Debug)]
pub struct Run {
    /// File it came from.
    pub path: PathBuf,
    /// Sample times, s.
    pub time_s: Vec<f64>,
    /// Gyro output, °/h.
    pub rate_dph: Vec<f64>,
    /// Loop temperature, °C (`None` where `temp_fault` = 1).
    pub temp_c: Vec<Option<f64>>,
    /// All thermometers `temp_a` … `temp_h` per row, °C (`None` where absent
    /// or `temp_fault` = 1); empty unless the run has thermometers besides `temp_c`.
    pub temps_c: Vec<[Option<f64>; THERMOMETERS]>,
    /// The thermometer columns the run has.
    pub thermometers: ThermometerSet,
    /// Known true rate, °/h, if the run has the column.
    pub ref_dph: Option<Vec<f64>>,
    /// Nominal sample period, s (see [`rbf_core::record::nominal_period_s`]).
    pub nominal_period_s: f64,
}

impl Run {
    /// Reads a whole run that has a `temp_c` column or other thermometers.
    pub fn load(path: &Path) -> Result<Run, RunError> {
        Self::read(RunReader::open(path)?)
    }

    /// Reads the rest of a run from an open reader (the run needs a `temp_c`
    /// column or other thermometers).
    pub fn read(mut reader: RunReader) -> Result<Run, RunError> {
        let path = reader.path().to_owned();
        let thermometers = reader.columns().thermometers();
        if thermometers.is_empty() {
            reader.require_temp()?;
        }
        let has_ref = reader.columns().ref_dph.is_some();
        let multi_point = !thermometers.is_subset(ThermometerSet::LOOP);
        let (mut time_s, mut rate_dph, mut temp_c, mut temps_c, mut ref_dph) = (vec![], vec![], vec![], vec![], vec![]);
        while let Some((_, row)) = reader.next_parsed()? {
            time_s.push(row.time_s);
            rate_dph.push(row.rate_dph);
            let readings = row.readings_c();
            temp_c.push(readings[LOOP_THERMOMETER]);
            if multi_point {
                temps_c.push(readings);
            }
            if has_ref {
                ref_dph.push(row.ref_dph.unwrap_or(0.0));
            }
        }
        if time_s.len() < 2 {
            return Err(RunError::Format {
                path: path.to_owned(),
                line: reader.line_number(),
                message: format!("run has {} data rows; at least 2 are needed", time_s.len()),
            });
        }
        Ok(Run {
            path,
            time_s,
            rate_dph,
            temp_c,
            temps_c,
            thermometers,
            ref_dph: has_ref.then_some(ref_dph),
            nominal_period_s: reader.nominal_period_s(),
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when the run has no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The reference rate of sample `i`: `ref_dph`, or else the run's mean rate, °/h.
    pub fn reference_dph(&self) -> Reference<'_> {
        match &self.ref_dph {
            Some(r) => Reference::Known(r),
            None => Reference::Mean(self.rate_dph.iter().sum::<f64>() / self.len() as f64),
        }
    }

    /// The compensator settings for this run's sample rate.
    pub fn compensator_config(&self) -> CompensatorConfig {
        CompensatorConfig::for_nominal_period_s(self.nominal_period_s)
    }

    /// Samples in rbf-core form, as the firmware receives them.
    pub fn samples(&self) -> impl Iterator<Item = GyroSample> + '_ {
        (0..self.len()).map(|i| {
            let prev = i.checked_sub(1).map(|p| self.time_s[p]);
            let readings = match self.temps_c.get(i) {
                Some(all) => *all,
                None => loop_only(self.temp_c[i]),
            };
            GyroSample::from_recorded(prev, self.time_s[i], self.rate_dph[i], &readings)
        })
    }
}

/// What a run's rate is compared against.
#[derive(Clone, Copy, Debug)]
pub enum Reference<'a> {
    /// Per-sample known true rate (`ref_dph`).
    Known(&'a [f64]),
    /// No reference column: the run's mean rate (IFOG paper, step 2).
    Mean(f64),
}

impl Reference<'_> {
    /// Reference rate of sample `i`, °/h.
    pub fn at(&self, i: usize) -> f64 {
        match self {
            Reference::Known(r) => r[i],
            Reference::Mean(m) => *m,
        }
    }
}

/// Thermometer readings with only the loop temperature.
pub(super) fn loop_only(temp_c: Option<f64>) -> [Option<f64>; THERMOMETERS] {
    let mut readings = [None; THERMOMETERS];
    readings[LOOP_THERMOMETER] = temp_c;
    readings
}

impl RawRow {
    /// The gyro sample of this row (see [`GyroSample::from_recorded`]).
    pub fn sample(&self, prev_time_s: Option<f64>) -> GyroSample {
        GyroSample::from_recorded(prev_time_s, self.row.time_s, self.row.rate_dph, &self.row.readings_c())
    }
}

/// Nominal period of a run file read in a first pass (for streaming commands).
/// A run read in one streaming pass: its nominal period and reference are
/// known up front, its samples are handed out one by one, parsed on a second
/// thread (so parsing and computation overlap); nothing holds the whole run.
pub struct StreamedRun {
    /// Nominal sample period, s (see [`RunReader::nominal_period_s`]).
    pub nominal_period_s: f64,
    /// The run has a `ref_dph` column.
    pub has_ref: bool,
    reader: RunReader,
}

impl StreamedRun {
    /// Opens a run that has the columns of `thermometers` (single-point
    /// models read `temp_c`, see [`rbf_core::FeatureSet::thermometers`]).
    pub fn open(path: &Path, thermometers: ThermometerSet) -> Result<Self, RunError> {
        Self::from_reader(RunReader::open(path)?, thermometers)
    }

    /// [`StreamedRun::open`] on an open reader.
    pub fn from_reader(reader: RunReader, thermometers: ThermometerSet) -> Result<Self, RunError> {
        reader.require_thermometers(thermometers)?;
        Ok(StreamedRun {
            nominal_period_s: reader.nominal_period_s(),
            has_ref: reader.columns().ref_dph.is_some(),
            reader,
        })
    }

    /// Feeds every data row and its gyro sample (as the firmware sees it) to
    /// `each`, in order; returns the number of rows.
    pub fn for_each(self, mut each: impl FnMut(&Row, &GyroSample)) -> anyhow::Result<usize> {
        self.for_each_line(|_, row, sample| each(row, sample))
    }

    /// Hands the rows to `consume` in batches, in order (see
    /// [`RunReader::for_each_batch`]); returns the number of rows.
    pub fn for_each_batch(self, consume: impl FnMut(Batch)) -> anyhow::Result<usize> {
        Ok(self.reader.for_each_batch(consume)?)
    }

    /// [`StreamedRun::for_each`] with each row's line number.
    pub fn for_each_line(self, mut each: impl FnMut(usize, &Row, &GyroSample)) -> anyhow::Result<usize> {
        let rows = self.reader.for_each_batch(|batch| {
            for i in 0..batch.len() {
                each(batch.line(i), &batch.row(i), &batch.sample(i));
            }
        })?;
        Ok(rows)
    }
}
