//! The calibration records `trainer fit --records STORE` writes, after its blob is committed.

use trainer::calibration::{Outcome, rows};
use trainer::records::{Record, Store};

/// Records the calibration of `serial` whose fit JSON is `json` and blob `blob`: one
/// record per summary row (per axis), each in its own transaction, with this command's arguments.
pub(super) fn write_records(
    store: Option<Store>,
    serial: Option<&str>,
    json: &serde_json::Value,
    blob: &[u8],
) -> anyhow::Result<()> {
    let Some(mut store) = store else { return Ok(()) };
    // `--records` requires `--serial` (clap); a record without one could not be found again.
    let serial = serial.unwrap_or_default();
    let outcome = Outcome::fitted(serial, json.clone(), false);
    let options: Vec<String> = std::env::args_os()
        .skip(1)
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    for row in rows(&outcome) {
        store.insert(&Record::fitted(&row, blob, &options)?)?;
    }
    eprintln!("recorded in {}", store.name());
    Ok(())
}
