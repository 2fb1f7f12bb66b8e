//! Compensation of whole runs into CSV: every sample through rbf-core's compensator
//! (one model, a model per axis, or one shared basis: [`RunModels`]), streamed, the
//! compensated columns appended to each input line byte for byte as the firmware
//! replay writes them ([`push_compensated_row`]).

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use rbf_core::record::{self, Columns};
use rbf_core::{CompensatedSample, CompensatorConfig, Flags, Model};

use super::decimal;
use super::diagnose::RunDiagnosis;
use super::evaluate::*;
use crate::output::{Existing, Output};
use crate::reading::chunked::Batch;
use crate::reading::run::RunReader;
use crate::text;

/// How compensating a run went.
#[derive(Clone, Debug)]
pub struct Compensation {
    /// Rows written, one per input row.
    pub rows: usize,
    /// Samples per flag.
    pub flagged: FlagCounts,
    /// Rows whose output is compensated (no flag 4).
    pub compensated: usize,
    /// What the rows showed, to explain an output with nothing compensated.
    pub diagnosis: RunDiagnosis,
}

/// Streams the rows of `reader` through the compensator of each axis of `models` into `out`
/// (recorded-run format, input lines passed through as read, one output row per input row):
/// per axis `bias_dph`, `rate_comp_dph`, `flags` appended, named for the axis on a
/// multi-axis run, in `models`' order ([`record::write_compensated_header`]). Returns what
/// each axis's compensation did, in that order.
pub fn compensate_reader(
    models: &RunModels<'_>,
    reader: RunReader,
    out: &mut (impl Write + Send),
) -> anyhow::Result<Vec<Compensation>> {
    models.require_thermometers(&reader)?;
    refuse_columns_compensate_writes(&reader)?;
    compensate_stepped(models.stepper(), &models.columns(), reader, out)
}

/// Refuses a run that already has a column compensate appends (a
/// compensated output, or a recording of an older `trainer device record`,
/// which named the unit's outputs so): the output would name it twice.
fn refuse_columns_compensate_writes(reader: &RunReader) -> anyhow::Result<()> {
    let mut appended = String::new();
    record::write_compensated_header(&mut appended, "", reader.columns())?;
    let appended: Vec<&str> = appended.trim_end().split(',').filter(|n| !n.is_empty()).collect();
    for (i, name) in reader.header().line().split(',').enumerate() {
        let name = record::trim_field(name);
        anyhow::ensure!(
            !appended.contains(&name),
            "{}: column {name} (field {}) is one compensate adds (the run is a compensated output, or was recorded \
             before `trainer device record` named the unit's columns unit_{name}); the output would hold it twice: \
             rename the column first, e.g. to unit_{name}",
            text::path(reader.path()),
            i + 1
        );
    }
    Ok(())
}

/// The compensation loop of [`compensate_reader`].
pub(super) fn compensate_stepped(
    mut stepper: Stepper<'_>,
    columns: &[Columns],
    reader: RunReader,
    out: &mut (impl Write + Send),
) -> anyhow::Result<Vec<Compensation>> {
    let n = columns.len();
    let config = CompensatorConfig::for_nominal_period_s(reader.nominal_period_s());
    let mut c: Vec<Compensation> = columns
        .iter()
        .map(|columns| Compensation {
            rows: 0,
            flagged: FlagCounts::default(),
            compensated: 0,
            diagnosis: RunDiagnosis::new(reader.path(), reader.nominal_period_s())
                .named_by(reader.header().line(), columns),
        })
        .collect();
    let io = |e: std::io::Error| anyhow::Error::new(e).context("write failed");
    for line in reader.header().preamble() {
        writeln!(out, "{line}").map_err(io)?;
    }
    let mut header = String::new();
    record::write_compensated_header(&mut header, reader.header().line(), reader.columns())?;
    out.write_all(header.as_bytes()).map_err(io)?;
    let parser = reader.header().row_parser();
    let mut rows = Vec::with_capacity(n);
    let mut step = Vec::with_capacity(n);
    let mut refused: Option<crate::reading::run::rows::RunError> = None;
    // The rows are parsed on every core, compensated in order here, and
    // formatted and written on a thread of their own, a batch at a time.
    let (tx, rx) = std::sync::mpsc::sync_channel::<(Batch, Vec<CompensatedSample>)>(4);
    std::thread::scope(|scope| {
        let writer = scope.spawn(move || -> std::io::Result<()> {
            let mut text = Vec::new();
            for (batch, outputs) in rx {
                text.clear();
                for (i, row) in outputs.chunks_exact(n).enumerate() {
                    push_compensated_row(&mut text, batch.line_text(i), row);
                }
                out.write_all(&text)?;
            }
            Ok(())
        });
        let mut writing = true;
        let read = reader.for_each_batch(|batch| {
            if refused.is_some() {
                return;
            }
            let mut outputs = Vec::with_capacity(batch.len() * n);
            for i in 0..batch.len() {
                if let Err(e) = rows_of_axes(&parser, columns, &batch, i, &mut rows) {
                    refused = Some(e);
                    break;
                }
                stepper.step(&config, &rows, &mut step);
                for ((axis, (row, _)), &o) in c.iter_mut().zip(&rows).zip(&step) {
                    axis.flagged.add(o.flags, 1);
                    axis.compensated += usize::from(!o.flags.contains(Flags::NO_VALID_MODEL));
                    axis.diagnosis.push(batch.line(i), row);
                    axis.rows += 1;
                    outputs.push(o);
                }
            }
            // A failed write stops the writer; its error is reported below.
            writing = writing && tx.send((batch, outputs)).is_ok();
        });
        drop(tx);
        let written = writer
            .join()
            .map_err(|_| anyhow::anyhow!("the output writer thread panicked"))?;
        read?;
        if let Some(e) = refused.take() {
            return Err(e.into());
        }
        written.map_err(io)
    })?;
    Ok(c)
}

/// Appends one compensated output row of one or more axes: the input line as read, then
/// `bias`, `rate_comp` and `flags` of each sample in axis order and a `\n`, byte for byte
/// what [`record::write_compensated_row`] (the firmware replay's writer) writes, without
/// its formatter (a long run's compensation is mostly this).
pub fn push_compensated_row(out: &mut Vec<u8>, input_line: &[u8], samples: &[CompensatedSample]) {
    out.extend_from_slice(input_line);
    for sample in samples {
        out.push(b',');
        decimal::push_f32(out, sample.bias_dph);
        out.push(b',');
        decimal::push_f32(out, sample.rate_comp_dph);
        out.push(b',');
        decimal::push_u8(out, sample.flags.bits());
    }
    out.push(b'\n');
}

/// Streams `input` through the compensator into `output` (replacing it;
/// see [`compensate_reader`]); returns the row and flag counts.
pub fn compensate_file(model: Option<&Model>, input: &Path, output: &Path) -> anyhow::Result<(usize, FlagCounts)> {
    let mut out = Output::create(output, &[input], Existing::Replace)?;
    let reader = RunReader::open(input)?;
    let c = compensate_reader(&RunModels::one(model, &reader), reader, &mut out)
        .and_then(only_axis)
        .with_context(|| format!("{}: compensating {}", text::path(output), text::path(input)))?;
    out.commit()?;
    Ok((c.rows, c.flagged))
}
