//! `trainer history`: a unit's or a batch's calibration records, newest first.

use std::io::Write;

use trainer::records::{Access, Record, Store};
use trainer::text;

/// A unit's calibrations (or a batch's), newest first, from a records store.
///
/// Reads the records `trainer batch --records STORE` and `trainer fit --records STORE`
/// wrote: one per calibration of a unit's axis, with when it was fitted, on which runs
/// (SHA-256), with which trainer and options, against which spec, with what result and
/// which model (CRC-32 and model id, as `trainer device status` names the unit's running
/// model; the blob itself is in the record). The store is only read, never created or
/// migrated. STORE is a SQLite file or a PostgreSQL URL (docs/production.md).
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  trainer history FOG-0001 --records calibrations.sqlite\n  \
                        trainer history --batch B-2026-48 --records postgres://cal@db.plant/records --json"
)]
#[command(group(clap::ArgGroup::new("which").required(true).args(["serial", "batch"])))]
pub struct Args {
    /// The unit's serial number.
    #[arg(value_name = "SERIAL")]
    serial: Option<String>,
    /// List a batch's calibrations instead of a unit's.
    #[arg(long, value_name = "ID")]
    batch: Option<String>,
    /// The records store: a SQLite file, or postgres://user@host/database.
    #[arg(long, value_name = "STORE")]
    records: String,
    /// Print the records as a JSON array on standard output.
    ///
    /// Each record: serial, axis, batch, fitted_utc, recorded_utc, trainer_version,
    /// trainer_commit, training_runs [{file, sha256}], options, spec_sha256, model_crc32
    /// ("0x…", as `inspect --format json` prints it), model_id, blob_bytes, blob_check
    /// ("ok", or why the stored blob is not the model named), status, reasons, figures
    /// (the batch summary row).
    #[arg(long)]
    json: bool,
}

/// The table `trainer history` prints: a line per record, newest first.
fn table(records: &[Record]) -> String {
    let mut out = format!(
        "{:<20}  {:<12}  {:<6}  {:<12}  {:<6}  {:<10}  {:<8}  {:<8}  {}\n",
        "fitted (UTC)", "serial", "axis", "batch", "status", "crc32", "model id", "trainer", "reasons"
    );
    for r in records {
        let reasons = match r.blob_problem() {
            Some(why) => format!("STORED BLOB DAMAGED: {why}"),
            None => r.reasons.join("; "),
        };
        out += &format!(
            "{:<20}  {:<12}  {:<6}  {:<12}  {:<6}  {:<10}  {:<8}  {:<8}  {}\n",
            r.fitted_utc,
            r.serial,
            r.axis,
            r.batch.as_deref().unwrap_or("-"),
            r.status.as_str(),
            r.model_crc32.map_or("-".to_owned(), trainer::provenance::crc32_text),
            r.model_id.map_or("-".to_owned(), trainer::provenance::model_id_text),
            r.trainer_version,
            reasons
        );
    }
    out
}

/// Runs `trainer history`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let mut store = Store::open(&a.records, Access::Read)?;
    let (records, what) = match (&a.serial, &a.batch) {
        (_, Some(batch)) => (store.for_batch(batch)?, format!("batch {batch}")),
        (Some(serial), None) => (store.for_serial(serial)?, format!("unit {serial}")),
        (None, None) => anyhow::bail!("name a SERIAL or --batch ID"),
    };
    let mut stdout = std::io::stdout().lock();
    if a.json {
        let array: Vec<serde_json::Value> = records.iter().map(Record::to_json).collect();
        writeln!(stdout, "{}", serde_json::to_string_pretty(&array)?)?;
    } else if records.is_empty() {
        writeln!(stdout, "no calibration of {what} in {}", store.name())?;
    } else {
        stdout.write_all(text::terminal_safe(&table(&records)).as_bytes())?;
    }
    stdout.flush()?;
    Ok(())
}
