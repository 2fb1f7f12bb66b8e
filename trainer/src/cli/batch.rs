//! `trainer batch`: every unit of a production batch fitted and judged, in parallel.
//!
//! Each unit runs `trainer fit` itself (this very binary, the one fit entry point) as
//! a child process with the unit's runs, serial, spec and batch id: a unit that fails or
//! even crashes costs the others nothing, and memory is bounded by the number of
//! workers (one per core) times one streaming fit. Then one summary of every unit:
//! `summary.json`, `summary.csv`, `index.html` (failing units first).

use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde::Deserialize;
use toml::Spanned;
use trainer::acceptance::{Rejected, Spec};
use trainer::calibration::{Outcome, Status, rows};
use trainer::provenance::sha256_file;
use trainer::records::{Access, Record, Store};
use trainer::text::{self, line_col};

/// Fit and judge every unit of a production batch.
///
/// MANIFEST.toml names the batch, an optional acceptance spec and each unit's serial,
/// training and holdout runs (paths relative to the manifest; docs/production.md).
/// Every unit is fitted by `trainer fit` on its own, one per core, then judged (a
/// three-axis unit axis by axis); OUTDIR gets `<serial>/model.bin`, `<serial>/fit.json`
/// and `summary.json`, `summary.csv`, `index.html` (a row per unit and axis, failing first).
/// Memory: at most --jobs streaming fits at once, each flat in the run's length (about
/// 48 MB for a 17-h run at 10 Hz; docs/benchmarks.md). Exit 0: every unit passed; 3: a
/// unit failed or could not be calibrated (the others are written); 1: the batch could
/// not run (nothing written).
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer batch batch.toml -o out/B-2026-48")]
pub struct Args {
    /// The batch manifest (TOML).
    #[arg(value_name = "MANIFEST.toml")]
    manifest: PathBuf,
    /// Output directory.
    #[arg(short = 'o', long = "output", value_name = "OUTDIR")]
    output: PathBuf,
    /// Write into an existing OUTDIR (its units' files are replaced).
    #[arg(long, conflicts_with = "resume")]
    force: bool,
    /// Into an existing OUTDIR: redo only units whose inputs, options or spec changed,
    /// or whose outputs are missing or damaged.
    #[arg(long)]
    resume: bool,
    /// Also record each calibration in STORE (a SQLite file, or postgres://…).
    ///
    /// One record per unit and axis (serial, batch, time, trainer version, run digests, fit
    /// options, spec digest, model CRC-32 and id, the blob, every figure of its summary row,
    /// status and reasons), each written in one transaction after the unit's blob. A SQLite
    /// file is created when missing; a store that cannot be written, is damaged or has a
    /// newer schema fails the batch before any fit. `trainer history` reads it back
    /// (docs/production.md, "Calibration records").
    #[arg(long, value_name = "STORE")]
    records: Option<String>,
    /// Parallel fits (default: the number of cores).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
}

/// One unit as the manifest gives it.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct UnitEntry {
    serial: Spanned<String>,
    #[serde(default)]
    train: Vec<Spanned<String>>,
    #[serde(default)]
    holdout: Vec<Spanned<String>>,
    /// `--features` of `trainer fit`.
    features: Option<String>,
    /// `--method` of `trainer fit`.
    method: Option<String>,
    /// `--use-range-c` of `trainer fit`, °C.
    use_range_c: Option<[f64; 2]>,
}

/// The manifest.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    batch: String,
    spec: Option<Spanned<String>>,
    /// Allow one run to be the training run of several units (a run shared on purpose).
    #[serde(default)]
    allow_shared_runs: bool,
    #[serde(default)]
    unit: Vec<UnitEntry>,
}

/// A unit ready to fit.
#[derive(Debug, Clone)]
struct Unit {
    serial: String,
    train: Vec<PathBuf>,
    holdout: Vec<PathBuf>,
    options: Vec<String>,
}

/// Reads and checks the manifest: the batch's units, its spec.
fn read_manifest(path: &Path) -> anyhow::Result<(String, Option<PathBuf>, Vec<Unit>)> {
    let name = text::path(path);
    let source =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{name}: cannot read the batch manifest: {e}"))?;
    let at = |offset: usize, why: String| {
        let (line, col) = line_col(&source, offset);
        anyhow::anyhow!("{name}:{line}:{col}: {why}")
    };
    let m: Manifest =
        toml::from_str(&source).map_err(|e| at(e.span().map_or(0, |s| s.start), e.message().to_owned()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let resolve = |p: &Spanned<String>, what: &str| -> anyhow::Result<PathBuf> {
        let full = base.join(p.get_ref());
        anyhow::ensure!(
            full.is_file(),
            at(p.span().start, format!("{what} {}: no such file", p.get_ref()))
        );
        Ok(full)
    };
    let spec = m.spec.as_ref().map(|s| resolve(s, "spec")).transpose()?;
    if let Some(s) = &spec {
        Spec::read(s)?;
    }
    anyhow::ensure!(!m.unit.is_empty(), "{name}: the manifest names no [[unit]]");
    let mut serials = HashSet::new();
    let mut trained_by: BTreeMap<PathBuf, String> = BTreeMap::new();
    let mut units = Vec::new();
    for u in &m.unit {
        let serial = u.serial.get_ref().clone();
        let span = u.serial.span().start;
        anyhow::ensure!(
            !serial.is_empty()
                && serial.len() <= rbf_core::model::SERIAL_CAPACITY
                && serial.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)),
            at(
                span,
                format!(
                    "serial {serial:?}: 1 to {} letters, digits, '-', '_' or '.' (a blob holds at most {} bytes; it names a directory)",
                    rbf_core::model::SERIAL_CAPACITY,
                    rbf_core::model::SERIAL_CAPACITY
                )
            )
        );
        anyhow::ensure!(
            serials.insert(serial.clone()),
            at(span, format!("serial {serial} is listed twice"))
        );
        anyhow::ensure!(
            !u.train.is_empty(),
            at(span, format!("unit {serial} has no training run (train = [...])"))
        );
        let train = u
            .train
            .iter()
            .map(|p| resolve(p, "training run"))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let holdout = u
            .holdout
            .iter()
            .map(|p| resolve(p, "holdout run"))
            .collect::<anyhow::Result<Vec<_>>>()?;
        for (h, spanned) in holdout.iter().zip(&u.holdout) {
            let canon = std::fs::canonicalize(h).unwrap_or_else(|_| h.clone());
            anyhow::ensure!(
                !train
                    .iter()
                    .any(|t| std::fs::canonicalize(t).unwrap_or_else(|_| t.clone()) == canon),
                at(
                    spanned.span().start,
                    format!(
                        "unit {serial}: holdout run {} is also its training run; a holdout must be unseen",
                        spanned.get_ref()
                    )
                )
            );
        }
        for (t, spanned) in train.iter().zip(&u.train) {
            let canon = std::fs::canonicalize(t).unwrap_or_else(|_| t.clone());
            if let Some(other) = trained_by.insert(canon, serial.clone())
                && other != serial
                && !m.allow_shared_runs
            {
                return Err(at(
                    spanned.span().start,
                    format!(
                        "training run {} of unit {serial} is also the training run of unit {other}: each unit is \
                         calibrated on its own gyro's runs (allow_shared_runs = true accepts it)",
                        spanned.get_ref()
                    ),
                ));
            }
        }
        let mut options = Vec::new();
        if let Some(f) = &u.features {
            options.extend(["--features".to_owned(), f.clone()]);
        }
        if let Some(me) = &u.method {
            options.extend(["--method".to_owned(), me.clone()]);
        }
        if let Some([lo, hi]) = u.use_range_c {
            options.extend(["--use-range-c".to_owned(), format!("{lo},{hi}")]);
        }
        units.push(Unit {
            serial,
            train,
            holdout,
            options,
        });
    }
    Ok((m.batch, spec, units))
}

/// The digest of everything a unit's result depends on: its runs, options, spec, batch
/// and this trainer's version (`--resume` redoes a unit whose digest changed).
fn inputs_digest(unit: &Unit, spec: Option<&Path>, batch: &str) -> anyhow::Result<String> {
    let mut s = format!("{}\n{batch}\n{}\n", env!("CARGO_PKG_VERSION"), unit.serial);
    for p in unit.train.iter().chain(&unit.holdout) {
        let _ = writeln!(s, "{}", sha256_file(p)?);
    }
    let _ = writeln!(s, "{}|{}", unit.holdout.len(), unit.options.join(" "));
    if let Some(spec) = spec {
        let _ = writeln!(s, "spec {}", sha256_file(spec)?);
    }
    Ok(trainer::provenance::sha256_bytes(s.as_bytes()))
}

/// The `trainer fit` arguments of `unit` into `dir`.
fn fit_arguments(unit: &Unit, spec: Option<&Path>, batch: &str, dir: &Path) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> = vec!["fit".into(), "-q".into()];
    args.extend(unit.train.iter().map(|p| p.as_os_str().to_owned()));
    for h in &unit.holdout {
        args.extend(["--holdout".into(), h.as_os_str().to_owned()]);
    }
    args.extend(["--serial", &unit.serial, "--batch", batch, "--force"].map(Into::into));
    if let Some(spec) = spec {
        args.extend(["--spec".into(), spec.as_os_str().to_owned()]);
    }
    args.extend(unit.options.iter().map(Into::into));
    args.extend([
        "-o".into(),
        dir.join("model.bin").into_os_string(),
        "--json".into(),
        dir.join("fit.json").into_os_string(),
    ]);
    args
}

/// Fits one unit with `trainer fit` (`args`, [`fit_arguments`]) into `dir`.
fn fit_unit(unit: &Unit, args: &[std::ffi::OsString], dir: &Path, digest: &str) -> Outcome {
    let mut cmd = match std::env::current_exe() {
        Ok(exe) => Command::new(exe),
        Err(e) => return Outcome::error(&unit.serial, format!("cannot find the trainer binary: {e}")),
    };
    cmd.args(args);
    if let Err(e) = std::fs::create_dir_all(dir) {
        return Outcome::error(&unit.serial, format!("{}: cannot create: {e}", text::path(dir)));
    }
    let _ = std::fs::remove_file(dir.join(DIGEST_FILE));
    let out = match cmd.output() {
        Ok(o) => o,
        Err(e) => return Outcome::error(&unit.serial, format!("cannot run trainer fit: {e}")),
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    let fit = std::fs::read(dir.join("fit.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
    match (out.status.code(), fit) {
        (Some(0 | 3), Some(fit)) => {
            let _ = std::fs::write(dir.join(DIGEST_FILE), digest);
            Outcome::fitted(&unit.serial, fit, false)
        }
        _ => {
            let why = stderr
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("trainer fit failed without a message")
                .trim_start_matches("error: ")
                .to_owned();
            Outcome::error(&unit.serial, why)
        }
    }
}

/// The file in each unit's directory that holds the digest of its inputs.
const DIGEST_FILE: &str = "inputs.sha256";

/// A resumed unit's earlier result, if its inputs are unchanged and its outputs whole.
fn earlier(unit: &Unit, dir: &Path, digest: &str) -> Option<Outcome> {
    let stored = std::fs::read_to_string(dir.join(DIGEST_FILE)).ok()?;
    if stored.trim() != digest {
        return None;
    }
    let blob = std::fs::read(dir.join("model.bin")).ok()?;
    if trainer::blobfile::file_problem(&blob).is_some() {
        return None;
    }
    let fit: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("fit.json")).ok()?).ok()?;
    Some(Outcome::fitted(&unit.serial, fit, true))
}

/// The columns of summary.csv and of the HTML table, in order: every figure of the row.
const COLUMNS: [&str; 19] = [
    "serial",
    "axis",
    "status",
    "reasons",
    "model_kind",
    "training_std100_dph",
    "holdout_std100_before_dph",
    "holdout_std100_after_dph",
    "holdout_std100_gain_pct",
    "forecast_in_use_std100_dph",
    "forecast_settled_spread_dph",
    "clamped_pct",
    "bias_instability_after_dph",
    "missing",
    "settled_forecast",
    "training_settled_spread_dph",
    "unmodelled_dynamics",
    "blob_bytes",
    "resumed",
];

fn cell(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Array(a) => a.iter().map(cell).collect::<Vec<_>>().join("; "),
        serde_json::Value::Number(n) => n.as_f64().map_or_else(|| n.to_string(), |x| format!("{x:.6}")),
        other => other.to_string(),
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// summary.csv: a header and a row per unit.
fn summary_csv(rows: &[serde_json::Value]) -> String {
    let mut out = COLUMNS.join(",") + "\n";
    for r in rows {
        let line: Vec<String> = COLUMNS.iter().map(|c| csv_field(&cell(&r[*c]))).collect();
        out += &(line.join(",") + "\n");
    }
    out
}

/// index.html: one self-contained page, failing units first.
fn summary_html(batch: &str, rows: &[serde_json::Value]) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>Batch {b}</title><style>body{{font-family:sans-serif}}\
         table{{border-collapse:collapse}}td,th{{border:1px solid #999;padding:3px 6px}}.fail{{background:#fdd}}\
         .error{{background:#fbb}}.pass{{background:#dfd}}</style></head><body>\n<h1>Batch {b}</h1>\n",
        b = html_escape(batch)
    );
    let count = |s: &str| rows.iter().filter(|r| r["status"] == s).count();
    let _ = writeln!(
        h,
        "<p>{} pass, {} fail, {} error</p>",
        count("pass"),
        count("fail"),
        count("error")
    );
    h += "<table><tr>";
    for c in COLUMNS {
        let _ = write!(h, "<th>{c}</th>");
    }
    h += "</tr>\n";
    for r in rows {
        let _ = write!(h, "<tr class=\"{}\">", cell(&r["status"]));
        for c in COLUMNS {
            let _ = write!(h, "<td>{}</td>", html_escape(&cell(&r[c])));
        }
        h += "</tr>\n";
    }
    h += "</table>\n";
    h += &gain_chart_svg(rows);
    h += "</body></html>\n";
    h
}

/// Height of one bar of [`gain_chart_svg`] and the gap below it, px.
const BAR_PX: (usize, usize) = (14, 4);
/// Width of the labels' column and of the 0 … 100 % scale, px.
const CHART_PX: (usize, usize) = (170, 400);

/// An inline SVG of every row's holdout STD100 gain (the worst holdout run), one bar per
/// unit and axis in the summary's order, coloured by its status; a row without a holdout
/// figure (an error, or no holdout run) has its label and no bar. Empty without rows.
fn gain_chart_svg(rows: &[serde_json::Value]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let (bar, gap) = BAR_PX;
    let (label_w, scale_w) = CHART_PX;
    let height = rows.len() * (bar + gap) + 24;
    let mut svg = format!(
        "<h2>Holdout STD100 gain, worst holdout run [%]</h2>\n<svg xmlns=\"http://www.w3.org/2000/svg\" \
         width=\"{w}\" height=\"{height}\" font-family=\"sans-serif\" font-size=\"11\">\n",
        w = label_w + scale_w + 60
    );
    for (i, r) in rows.iter().enumerate() {
        let y = i * (bar + gap);
        let label = format!("{} {}", cell(&r["serial"]), cell(&r["axis"]));
        let _ = writeln!(
            svg,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{}</text>",
            label_w - 6,
            y + bar - 3,
            html_escape(label.trim())
        );
        let Some(gain) = r["holdout_std100_gain_pct"].as_f64() else {
            continue;
        };
        let colour = match r["status"].as_str() {
            Some("pass") => "#4a4",
            Some("fail") => "#c33",
            _ => "#999",
        };
        let width = (gain.clamp(0.0, 100.0) / 100.0 * scale_w as f64).round();
        let _ = writeln!(
            svg,
            "<rect x=\"{label_w}\" y=\"{y}\" width=\"{width}\" height=\"{bar}\" fill=\"{colour}\"/>\
             <text x=\"{}\" y=\"{}\">{gain:.1}</text>",
            label_w as f64 + width + 4.0,
            y + bar - 3
        );
    }
    let axis_y = rows.len() * (bar + gap) + 12;
    for pct in [0, 50, 100] {
        let _ = writeln!(
            svg,
            "<text x=\"{}\" y=\"{axis_y}\" text-anchor=\"middle\">{pct}</text>",
            label_w + scale_w * pct / 100
        );
    }
    svg += "</svg>\n";
    svg
}

/// Writes `outcome`'s calibration records into `store`, its blob in `dir` already committed:
/// one per summary row (per axis); a fitted unit's from its blob; a kept unit's (`--resume`)
/// only where the store lacks it (a batch killed before writing it); an error's with what
/// its fit would have recorded. A record that cannot be written makes the unit an error
/// that says so.
fn write_records(
    store: &Mutex<Store>,
    unit: &Unit,
    mut outcome: Outcome,
    dir: &Path,
    spec: Option<&Path>,
    batch: &str,
    args: &[String],
) -> Outcome {
    let written = (|| -> anyhow::Result<()> {
        let mut store = store
            .lock()
            .map_err(|_| anyhow::anyhow!("another unit's record write failed"))?;
        let blob = match outcome.status {
            Status::Error => None,
            _ => Some(
                std::fs::read(dir.join("model.bin"))
                    .with_context(|| format!("{}: cannot read", text::path(&dir.join("model.bin"))))?,
            ),
        };
        for row in rows(&outcome) {
            let record = match &blob {
                None => {
                    let provenance = trainer::provenance::ProvenanceRecord::for_fit(
                        Some(&unit.serial),
                        &unit.train,
                        spec,
                        Some(batch),
                    )?;
                    Record::new(&row, &provenance, args)?
                }
                Some(blob) => Record::fitted(&row, blob, args)?,
            };
            if outcome.resumed
                && let Some(id) = record.model_id
                && store.has_model(&record.serial, &record.axis, id)?
            {
                continue;
            }
            store.insert(&record)?;
        }
        Ok(())
    })();
    if let Err(e) = written {
        outcome.status = Status::Error;
        outcome
            .reasons
            .push(format!("its calibration record was not written: {e:#}"));
    }
    outcome
}

/// Runs `trainer batch`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let (batch, spec, units) = read_manifest(&a.manifest)?;
    if a.output.exists() {
        anyhow::ensure!(
            a.force || a.resume,
            "{}: exists; --resume completes it, --force replaces its units' files",
            text::path(&a.output)
        );
    }
    // The store before any fit: one that cannot take the records fails the batch now.
    let store = a
        .records
        .as_deref()
        .map(|locator| Store::open(locator, Access::Write))
        .transpose()?
        .map(Mutex::new);
    std::fs::create_dir_all(&a.output).with_context(|| format!("{}: cannot create", text::path(&a.output)))?;
    let workers = a
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, units.len());
    eprintln!("batch {batch}: {} units, {workers} at a time", units.len());
    let started = Instant::now();
    // Time spent writing records, summed over the workers (what the records cost the batch).
    let records_time = Mutex::new(Duration::ZERO);
    let next = Mutex::new(0usize);
    let results: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; units.len()]);
    let done = Mutex::new(0usize);
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let i = {
                        let Ok(mut n) = next.lock() else { return };
                        let i = *n;
                        *n += 1;
                        i
                    };
                    let Some(unit) = units.get(i) else { return };
                    let dir = a.output.join(&unit.serial);
                    let args = fit_arguments(unit, spec.as_deref(), &batch, &dir);
                    let mut result = match inputs_digest(unit, spec.as_deref(), &batch) {
                        Err(e) => Outcome::error(&unit.serial, format!("{e:#}")),
                        Ok(digest) => match a.resume.then(|| earlier(unit, &dir, &digest)).flatten() {
                            Some(r) => r,
                            None => fit_unit(unit, &args, &dir, &digest),
                        },
                    };
                    if let Some(store) = &store {
                        let recording = Instant::now();
                        let args: Vec<String> = args.iter().map(|s| s.to_string_lossy().into_owned()).collect();
                        result = write_records(store, unit, result, &dir, spec.as_deref(), &batch, &args);
                        if let Ok(mut t) = records_time.lock() {
                            *t += recording.elapsed();
                        }
                    }
                    let n = done.lock().map(|mut d| {
                        *d += 1;
                        *d
                    });
                    let first = result.reasons.first().map_or(String::new(), |r| format!(": {r}"));
                    eprintln!(
                        "[{}/{}] {} {}{}{}",
                        n.unwrap_or(0),
                        units.len(),
                        unit.serial,
                        result.status.as_str(),
                        if result.resumed { " (unchanged, kept)" } else { "" },
                        first
                    );
                    if let Ok(mut r) = results.lock()
                        && let Some(slot) = r.get_mut(i)
                    {
                        *slot = Some(result);
                    }
                }
            });
        }
    });
    let results: Vec<Outcome> = results
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a worker failed"))?
        .into_iter()
        .flatten()
        .collect();
    // Failing units first (errors, then fails), each group in manifest order.
    let mut rows: Vec<serde_json::Value> = results.iter().flat_map(rows).collect();
    rows.sort_by_key(|r| match r["status"].as_str() {
        Some("error") => 0,
        Some("fail") => 1,
        _ => 2,
    });
    let summary = serde_json::json!({"batch": batch, "units": rows});
    // The three summaries are committed together, or none changes.
    let summarising = Instant::now();
    let mut transaction = trainer::output::Transaction::new();
    for (name, bytes) in [
        ("summary.json", serde_json::to_string_pretty(&summary)?.into_bytes()),
        ("summary.csv", summary_csv(&rows).into_bytes()),
        ("index.html", summary_html(&batch, &rows).into_bytes()),
    ] {
        let path = a.output.join(name);
        let mut out = trainer::output::Output::create(&path, &[], trainer::output::Existing::Replace)?;
        std::io::Write::write_all(&mut out, &bytes).with_context(|| format!("{}: write failed", text::path(&path)))?;
        transaction.add(out);
    }
    transaction.commit()?;
    let summaries = summarising.elapsed();
    let records = records_time.into_inner().unwrap_or_default();
    let wall = started.elapsed();
    eprintln!(
        "batch {batch}: {:.1} s; summaries {:.3} s, records {:.3} s: {:.2} % of the worker time",
        wall.as_secs_f64(),
        summaries.as_secs_f64(),
        records.as_secs_f64(),
        100.0 * (summaries + records).as_secs_f64() / (wall.as_secs_f64() * workers as f64).max(1e-9)
    );
    let bad = rows.iter().filter(|r| r["status"] != "pass").count();
    println!(
        "batch {batch}: {} pass, {bad} fail or error; wrote {}",
        rows.len() - bad,
        text::path(&a.output.join("summary.json"))
    );
    if bad > 0 {
        return Err(Rejected(format!(
            "{bad} of {} units (axes) failed or could not be calibrated",
            rows.len()
        ))
        .into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// summary.csv and index.html show every figure the summary row holds.
    #[test]
    fn every_figure_of_the_summary_row_is_a_column() {
        let r = rows(&Outcome::error("FOG-1", "broken.csv:3:1: not a number".to_owned())).remove(0);
        for key in r.as_object().unwrap().keys() {
            assert!(COLUMNS.contains(&key.as_str()), "{key} is not a column");
        }
        assert_eq!(r.as_object().unwrap().len(), COLUMNS.len());
    }

    /// The page's chart has a bar per row with a holdout gain, as long as its share of the
    /// scale and coloured by its status, in the summary's order; a row without one keeps its
    /// label and has no bar.
    #[test]
    fn the_gain_chart_draws_a_bar_per_judged_row_in_order_coloured_by_status() {
        let rows = [
            serde_json::json!({"serial": "FOG-2", "axis": "", "status": "fail", "holdout_std100_gain_pct": 50.0}),
            serde_json::json!({"serial": "FOG-3", "axis": "", "status": "error", "holdout_std100_gain_pct": null}),
            serde_json::json!({"serial": "FOG-1", "axis": "", "status": "pass", "holdout_std100_gain_pct": 95.5}),
        ];
        let svg = gain_chart_svg(&rows);
        let bars: Vec<&str> = svg.lines().filter(|l| l.starts_with("<rect")).collect();
        assert_eq!(bars.len(), 2, "{svg}");
        let half = CHART_PX.1 / 2;
        assert!(
            bars[0].contains(&format!("width=\"{half}\"")) && bars[0].contains("#c33"),
            "{}",
            bars[0]
        );
        assert!(bars[1].contains("#4a4") && bars[1].contains(">95.5<"), "{}", bars[1]);
        let order: Vec<usize> = ["FOG-2", "FOG-3", "FOG-1"]
            .iter()
            .map(|s| svg.find(s).unwrap())
            .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{svg}");
        assert!(gain_chart_svg(&[]).is_empty());
    }
}
