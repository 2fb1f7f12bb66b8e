//! The column mapping a run's header gives: its axes, each axis's columns,
//! and the thermometers a model needs, refused at the header's line.

use rbf_core::axis::Axis;
use rbf_core::record::{self, Columns};
use rbf_core::thermometer::ThermometerSet;

use super::header::RunHeader;
use super::rows::{RunError, short};

impl RunHeader {
    /// The axes of a multi-axis run, in x, y, z order; empty for a single-axis run.
    pub fn axes(&self) -> Vec<Axis> {
        self.columns.axes_present().collect()
    }

    /// The header's columns: every axis's (a reader's `columns()` are the selected axis's).
    pub fn columns(&self) -> &Columns {
        &self.columns
    }

    /// The columns that read `axis` ([`Columns::for_axis`]), or an error at
    /// the header naming the missing rate column.
    pub fn axis_columns(&self, axis: Axis) -> Result<Columns, RunError> {
        self.columns.for_axis(axis).ok_or_else(|| {
            self.error_at(
                self.line_no,
                format!(
                    "header has no column {} (header: {})",
                    axis.rate_column(),
                    short(&self.line)
                ),
            )
        })
    }

    /// Fails on a multi-axis run, for commands that read one axis
    /// (`rate_dph`): the message names the axes and the commands that read them.
    pub fn require_single_axis(&self) -> Result<(), RunError> {
        let axes = self.axes();
        if axes.is_empty() {
            return Ok(());
        }
        let names: Vec<&str> = axes.iter().map(|a| a.name()).collect();
        Err(self.error_at(
            self.line_no,
            format!(
                "a multi-axis run (axes {}): this reads single-axis runs (rate_dph); fit, compensate, \
                 eval and inspect read each axis",
                names.join(", ")
            ),
        ))
    }

    /// Fails unless `columns` (this run's, of one axis) have the columns of
    /// `thermometers`, naming the missing ones.
    pub fn require_thermometers(&self, columns: &Columns, thermometers: ThermometerSet) -> Result<(), RunError> {
        let absent = thermometers.difference(columns.thermometers());
        let missing: Vec<&str> = record::column::THERMOMETERS
            .iter()
            .enumerate()
            .filter(|(i, _)| absent.contains(*i))
            .map(|(_, name)| *name)
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        let what = if thermometers == ThermometerSet::LOOP {
            "which single-point models need"
        } else {
            "which the model's inputs need"
        };
        Err(self.error_at(
            self.line_no,
            format!(
                "header has no column {}, {what} (header: {})",
                missing.join(", "),
                short(&self.line)
            ),
        ))
    }
}
