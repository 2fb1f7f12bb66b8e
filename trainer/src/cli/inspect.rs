//! `trainer inspect`: what a model blob holds and whether it is intact.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use rbf_core::blob::axes::{AXES_FORMAT_VERSION, AxesHeader, AxisModels, decode_axes_into};
use rbf_core::blob::{self, AXES_PROVENANCE_FORMAT_VERSION, BlobKind, Header};
use rbf_core::model::ModelBody;
use trainer::blobfile::{file_problem, read_blob};
use trainer::describe::summary::{count, sig};
use trainer::output::Existing;
use trainer::text;

use super::common::{JsonArg, print_json_and_commit};
use super::fit::json::features_json;
use super::toml;
use trainer::output::Transaction;

/// Show what a model blob holds and whether it is intact.
///
/// Prints a summary (format, shape, model form, inputs with the temperature and rate
/// ranges the training covered, serial, CRC); `--format toml|json` prints every
/// parameter instead, in a text form two models can be diffed in. A
/// multi-axis blob shows each axis's model.
#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:\n  trainer inspect --model model.bin\n  \
                        trainer inspect --model model.bin --format toml > model.toml")]
pub struct Args {
    /// Model blob written by `trainer fit` (- reads standard input).
    #[arg(
        long = "model",
        id = "model_option",
        value_name = "MODEL.bin",
        help_heading = "Model",
        required_unless_present = "model",
        conflicts_with = "model"
    )]
    model_option: Option<PathBuf>,
    /// The model blob given without --model.
    #[arg(value_name = "MODEL.bin", hide = true)]
    model: Option<PathBuf>,
    /// What to print: a summary, or every parameter as TOML or JSON.
    #[arg(long, value_enum, default_value_t = Format::Text, help_heading = "Output")]
    format: Format,
    #[command(flatten)]
    json: JsonArg,
    /// Replace the JSON file if it exists.
    #[arg(long, help_heading = "Output")]
    force: bool,
}

/// `inspect`'s printed forms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// A summary for people.
    Text,
    /// Every parameter as TOML.
    Toml,
    /// Every parameter as JSON.
    Json,
}

/// Runs `trainer inspect`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let Some(path) = a.model_option.or(a.model) else {
        anyhow::bail!("inspect needs a model: trainer inspect --model MODEL.bin");
    };
    let json_out = a.json.sink(&[&path], Existing::from_force(a.force))?;
    let bytes = read_blob(&path)?;
    let refused = |e: blob::DecodeError| anyhow::anyhow!("{}: model refused: {e}", text::path(&path));
    match blob::blob_kind(&bytes).map_err(refused)? {
        BlobKind::SingleAxis => {}
        BlobKind::PerAxis | BlobKind::SharedBasis => return inspect_axes(&path, &bytes, a.format, json_out),
    }
    let header = Header::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: model refused: {e}", text::path(&path)))?;
    let crc = blob::crc_status(&bytes, &header);
    let decoded = crc.and_then(|_| blob::decode(&bytes));
    // Also what a valid blob leaves over: a file holds one blob.
    let problem = decoded.as_ref().ok().and_then(|_| file_problem(&bytes));
    let mut info = inspect_json(&path, &bytes, &header, &crc, &decoded);
    if let Some(problem) = &problem {
        info["valid"] = serde_json::json!(false);
        info["error"] = serde_json::json!(problem);
    }
    let json_on_stdout = json_out.is_stdout();
    let mut transaction = Transaction::new();
    let json = json_out.write(&info, &mut transaction)?;
    let printed = match a.format {
        Format::Text => summary(&info),
        Format::Toml => toml::to_toml(&info),
        Format::Json => format!("{}\n", serde_json::to_string_pretty(&info)?),
    };
    print_json_and_commit(
        printed.as_bytes(),
        json_on_stdout && a.format == Format::Text,
        json,
        transaction,
    )?;
    match (decoded, problem) {
        (Ok(_), None) => Ok(()),
        (Ok(_), Some(problem)) => Err(anyhow::anyhow!("{}: model refused: {problem}", text::path(&path))),
        (Err(e), _) => Err(anyhow::anyhow!("{}: model refused: {e}", text::path(&path))),
    }
}

/// Every field of a blob as `--format json`, `--format toml` and `--json` give it.
fn inspect_json(
    path: &Path,
    bytes: &[u8],
    header: &Header,
    crc: &Result<(), blob::DecodeError>,
    decoded: &Result<blob::Decoded, blob::DecodeError>,
) -> serde_json::Value {
    let mut v = serde_json::json!({
        "file": text::path(path),
        "file_bytes": bytes.len(),
        "blob_bytes": header.blob_len(),
        "format_version": header.version,
        "kind": rbf_core::model::ModelKind::from_code(header.kind_code).map(|k| k.name()),
        "inputs": header.inputs,
        "centers": header.centers,
        "crc": match crc { Ok(()) => "ok".to_owned(), Err(e) => e.to_string() },
        "valid": decoded.is_ok(),
    });
    add_provenance_json(&mut v, bytes, header.blob_len());
    if let Ok(d) = decoded {
        add_model_json(&mut v, &d.model);
    } else if let Err(e) = decoded {
        v["error"] = serde_json::json!(e.to_string());
    }
    v
}

/// Adds the blob's CRC-32 (`"crc32": "0x…"`, the value the unit's health report names) and
/// its provenance (`null`: a blob written before provenance existed) to an inspect JSON object.
fn add_provenance_json(v: &mut serde_json::Value, bytes: &[u8], blob_len: usize) {
    let crc = bytes
        .get(..blob_len)
        .filter(|b| b.len() == blob_len)
        .map(trainer::blobfile::blob_crc32);
    v["crc32"] = serde_json::json!(crc.map(trainer::provenance::crc32_text));
    v["provenance"] = match trainer::blobfile::blob_provenance(bytes) {
        Ok(Some((record, id))) => record.to_json(id),
        Ok(None) => serde_json::Value::Null,
        Err(e) => serde_json::json!({ "error": format!("{e:#}") }),
    };
}

/// Adds what `m` holds to an inspect JSON object: features, training ranges,
/// units, serial and every parameter.
fn add_model_json(v: &mut serde_json::Value, m: &rbf_core::Model) {
    {
        let f = m.features();
        let ranges: Vec<_> = (0..f.dims())
            .map(|i| {
                let (lo, hi) = m.input_range(i).unwrap_or((f32::NAN, f32::NAN));
                serde_json::json!({"input": f.set.name(i).map(|n| n.to_string()), "min": lo, "max": hi})
            })
            .collect();
        v["features"] = features_json(f);
        v["description"] = serde_json::json!(trainer::describe::describe(m));
        v["training_ranges"] = serde_json::Value::Array(ranges);
        v["units"] = serde_json::json!({"bias": "deg/h", "temperature": "degC", "rate_of_change": "degC/min"});
        v["serial"] = serde_json::json!(m.info().serial.as_ref().map(|s| s.as_str()));
        match m.body() {
            ModelBody::Rbf(net) => {
                v["rbf"] = serde_json::json!({
                    "offset": net.offset(), "scale": net.scale(),
                    "widths": net.widths(), "weights_dph": net.weights(),
                    "linear_dph": net.linear(), "constant_dph": net.constant(),
                });
            }
            ModelBody::Poly3(p) => {
                v["poly3"] = serde_json::json!({"ref_temp_c": p.ref_temp_c, "coeffs": p.coeffs});
            }
        }
    }
}

/// `trainer inspect` of a multi-axis blob: the blob's facts once, then each
/// axis's model as a single-axis blob's is shown.
fn inspect_axes(path: &Path, bytes: &[u8], format: Format, json_out: super::common::JsonSink) -> anyhow::Result<()> {
    let refused = |e: &dyn std::fmt::Display| anyhow::anyhow!("{}: model refused: {e}", text::path(path));
    let header = AxesHeader::parse(bytes).map_err(|e| refused(&e))?;
    let mut models = Box::new(AxisModels::EMPTY);
    // A shared-basis blob shows each axis as the model of the basis and its layer.
    let decoded = if header.shared_basis {
        let mut shared = Box::new(rbf_core::shared_basis::SharedAxisModels::EMPTY);
        let decoded = rbf_core::blob::shared_layout::decode_shared_into(&mut shared, bytes);
        for axis in shared.axes() {
            if let Some(Ok(model)) = shared.axis_model(axis) {
                models.insert(axis, model);
            }
        }
        decoded
    } else {
        decode_axes_into(&mut models, bytes)
    };
    let problem = match &decoded {
        Ok(_) => file_problem(bytes),
        Err(e) => Some(e.to_string()),
    };
    let crc = match decoded {
        Err(e @ (blob::DecodeError::CrcMismatch { .. } | blob::DecodeError::Truncated { .. })) => e.to_string(),
        _ => "ok".to_owned(),
    };
    let axis_json: Vec<serde_json::Value> = models
        .axes()
        .filter_map(|axis| {
            let m = models.get(axis)?;
            let (centers, kind) = match m.body() {
                ModelBody::Rbf(net) => (net.centers_used(), m.kind()),
                ModelBody::Poly3(_) => (0, m.kind()),
            };
            let mut v = serde_json::json!({
                "axis": axis.name(), "kind": kind.name(), "inputs": m.features().dims(), "centers": centers,
            });
            add_model_json(&mut v, m);
            Some(v)
        })
        .collect();
    let mut info = serde_json::json!({
        "file": text::path(path),
        "file_bytes": bytes.len(),
        "blob_bytes": header.blob_len(),
        "format_version": if header.provenance { AXES_PROVENANCE_FORMAT_VERSION } else { AXES_FORMAT_VERSION },
        "axis_mask": header.axis_mask,
        "shared_basis": header.shared_basis,
        "crc": crc,
        "valid": problem.is_none(),
        "error": problem,
        "axes": axis_json,
    });
    add_provenance_json(&mut info, bytes, header.blob_len());
    let json_on_stdout = json_out.is_stdout();
    let mut transaction = Transaction::new();
    let json = json_out.write(&info, &mut transaction)?;
    let printed = match format {
        Format::Text => {
            let mut text = summary(&info)
                .lines()
                .filter(|l| !l.starts_with("kind") && !l.starts_with("shape"))
                .fold(String::new(), |t, l| t + l + "\n");
            if header.shared_basis {
                text.push_str(
                    "shared basis    yes: one thermometer, features, normalisation, centres and width; per axis \
                     weights, linear terms, constant\n",
                );
            }
            for (axis, v) in models.axes().zip(info["axes"].as_array().into_iter().flatten()) {
                let _ = writeln!(text, "axis {}", axis.name());
                for line in summary(v).lines() {
                    if !["file", "format version", "CRC-32", "valid"]
                        .iter()
                        .any(|k| line.starts_with(k))
                    {
                        let _ = writeln!(text, "  {line}");
                    }
                }
            }
            text
        }
        Format::Toml => toml::to_toml(&info),
        Format::Json => format!("{}\n", serde_json::to_string_pretty(&info)?),
    };
    print_json_and_commit(
        printed.as_bytes(),
        json_on_stdout && format == Format::Text,
        json,
        transaction,
    )?;
    match problem {
        None => Ok(()),
        Some(problem) => Err(refused(&problem)),
    }
}

/// The summary `trainer inspect` prints: one labelled line per fact, numbers
/// to the digits that matter, strings from the blob with control characters escaped.
pub fn summary(v: &serde_json::Value) -> String {
    let mut out = String::new();
    let num = |k: &str| v[k].as_u64().unwrap_or(0);
    let string = |x: &serde_json::Value| x.as_str().map(|s| text::escape_controls(s).into_owned());
    let _ = writeln!(
        out,
        "file            {} ({} bytes, blob {} bytes)",
        string(&v["file"]).unwrap_or_default(),
        num("file_bytes"),
        num("blob_bytes")
    );
    let _ = writeln!(out, "format version  {}", num("format_version"));
    let description = &v["description"];
    let stored = string(&v["kind"]).unwrap_or_else(|| "unknown".to_owned());
    let _ = match string(&description["kind"]) {
        Some(kind) => writeln!(out, "kind            {kind} (stored as {stored})"),
        None => writeln!(out, "kind            {stored}"),
    };
    let _ = writeln!(
        out,
        "shape           {}, {}",
        count(num("inputs"), "input", "inputs"),
        count(num("centers"), "centre", "centres")
    );
    let _ = match string(&v["crc32"]) {
        Some(value) => writeln!(
            out,
            "CRC-32          {} ({value})",
            string(&v["crc"]).unwrap_or_default()
        ),
        None => writeln!(out, "CRC-32          {}", string(&v["crc"]).unwrap_or_default()),
    };
    if let Some(p) = v.get("provenance") {
        provenance_lines(&mut out, p);
    }
    if let Some(form) = string(&description["form"]) {
        let _ = writeln!(out, "model           {form}");
    }
    if let Some(t0) = description["ref_temp_c"].as_f64() {
        let _ = writeln!(out, "T₀              {} °C (reference temperature)", sig(t0, 4));
    }
    let f = &v["features"];
    if f.is_object() {
        let windows: Vec<String> = f["windows_s"]
            .as_array()
            .map(|w| w.iter().map(|x| sig(x.as_f64().unwrap_or(f64::NAN), 4)).collect())
            .unwrap_or_default();
        let lag = match f["coil_lag_min"].as_u64() {
            Some(l) => format!(", coil lag {l} min"),
            None => String::new(),
        };
        let _ = writeln!(
            out,
            "ΔT windows      {} s{lag}; warm-up {} s",
            windows.join(", "),
            sig(f["warmup_s"].as_f64().unwrap_or(f64::NAN), 4)
        );
    }
    if let Some(ranges) = v["training_ranges"].as_array() {
        let _ = writeln!(out, "training ranges");
        for r in ranges {
            let _ = writeln!(
                out,
                "  {:<24} {} … {}",
                string(&r["input"]).unwrap_or_else(|| "?".to_owned()),
                sig(r["min"].as_f64().unwrap_or(f64::NAN), 4),
                sig(r["max"].as_f64().unwrap_or(f64::NAN), 4)
            );
        }
    }
    if v.get("serial").is_some() {
        let _ = writeln!(
            out,
            "serial          {}",
            string(&v["serial"]).unwrap_or_else(|| "none".to_owned())
        );
    }
    let valid = v["valid"].as_bool().unwrap_or(false);
    let _ = writeln!(
        out,
        "valid           {}{}",
        if valid { "yes" } else { "no" },
        string(&v["error"]).map_or(String::new(), |e| format!(" ({e})"))
    );
    out
}

/// The provenance lines of the summary: "none" for a blob written before provenance existed.
fn provenance_lines(out: &mut String, p: &serde_json::Value) {
    let string = |x: &serde_json::Value| x.as_str().map(|s| text::escape_controls(s).into_owned());
    if p.is_null() {
        let _ = writeln!(out, "provenance      none (a blob written before format 4)");
        return;
    }
    if let Some(e) = string(&p["error"]) {
        let _ = writeln!(out, "provenance      unreadable: {e}");
        return;
    }
    let _ = writeln!(out, "model id        {}", string(&p["model_id"]).unwrap_or_default());
    let _ = writeln!(
        out,
        "fitted          {} by trainer {} ({})",
        string(&p["fitted_utc"]).unwrap_or_default(),
        string(&p["trainer_version"]).unwrap_or_default(),
        string(&p["trainer_commit"]).unwrap_or_default()
    );
    for run in p["training_runs"].as_array().into_iter().flatten() {
        let _ = writeln!(
            out,
            "training run    {} sha256 {}",
            string(&run["file"]).unwrap_or_default(),
            string(&run["sha256"]).unwrap_or_default()
        );
    }
    let _ = writeln!(
        out,
        "spec sha256     {}",
        string(&p["spec_sha256"]).unwrap_or_else(|| "none".to_owned())
    );
    let _ = writeln!(
        out,
        "batch           {}",
        string(&p["batch"]).unwrap_or_else(|| "none".to_owned())
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> serde_json::Value {
        serde_json::json!({
            "file": "m\u{1b}.bin", "file_bytes": 300, "blob_bytes": 300, "format_version": 3,
            "kind": "gaussian-rbf", "inputs": 1, "centers": 1, "crc": "ok", "valid": true,
            "features": {"windows_s": [15.000000953674316, 240.0], "coil_lag_min": null, "warmup_s": 900.0},
            "training_ranges": [{"input": "T [°C]", "min": -9.876543212890625, "max": 40.1234}],
            "serial": null,
        })
    }

    #[test]
    fn the_summary_is_tidy() {
        let s = summary(&info());
        assert!(s.contains("shape           1 input, 1 centre\n"), "{s}");
        assert!(s.contains("ΔT windows      15, 240 s; warm-up 900 s\n"), "{s}");
        assert!(s.contains("  T [°C]                   -9.877 … 40.12\n"), "{s}");
        assert!(s.contains("serial          none\n"), "{s}");
        assert!(s.contains("valid           yes\n"), "{s}");
        assert!(s.contains("file            m\\u{1b}.bin (300 bytes"), "{s}");
        assert!(!s.contains('"') && !s.contains("null"), "{s}");
    }

    #[test]
    fn a_refused_blob_says_why() {
        let mut v = info();
        v["valid"] = serde_json::json!(false);
        v["error"] = serde_json::json!("14 bytes follow the blob's end");
        v["centers"] = serde_json::json!(12);
        let s = summary(&v);
        assert!(s.contains("valid           no (14 bytes follow the blob's end)"), "{s}");
        assert!(s.contains("12 centres"), "{s}");
    }
}
