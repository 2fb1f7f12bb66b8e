//! Running the trainer, naming files and reading what it writes, for the
//! accuracy benches.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};

/// Runs `exe` with `args`; its standard output, or an error with its standard error.
pub(crate) fn run_tool(exe: &Path, args: &[&str]) -> anyhow::Result<String> {
    let out = Command::new(exe)
        .args(args)
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    if !out.status.success() {
        bail!(
            "{} {} failed: {}",
            exe.display(),
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// `p` as text (the benches write under target/, always UTF-8).
pub(crate) fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 paths under target/")
}

/// The named columns of a CSV with `#` metadata lines, in the order asked.
pub(crate) fn read_columns(file: &Path, names: &[&str]) -> anyhow::Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(file).with_context(|| format!("cannot read {}", file.display()))?;
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let index: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .with_context(|| format!("{}: no column {n}", file.display()))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut columns = vec![Vec::new(); names.len()];
    for (row, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        for (column, &i) in columns.iter_mut().zip(&index) {
            let value = fields.get(i).and_then(|f| f.parse().ok());
            column.push(value.with_context(|| format!("{}: data row {}: bad field", file.display(), row + 1))?);
        }
    }
    Ok(columns)
}

/// What `trainer eval --json` reads on a soak test.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct SoakReading {
    /// Settled spread after compensation, °/h (`None`: fewer than two plateaus).
    pub after_dph: Option<f64>,
    /// The same uncompensated, °/h.
    pub before_dph: Option<f64>,
    /// Settled spread after compensation over the plateaus inside the
    /// model's training range, °/h (`None`: fewer than two there).
    pub in_range_dph: Option<f64>,
    /// Each plateau's loop temperature, °C, and settled bias after
    /// compensation, °/h.
    pub plateaus: Vec<(f64, f64)>,
    /// The same uncompensated: each plateau's loop temperature, °C, and
    /// settled bias, °/h.
    pub plateaus_before: Vec<(f64, f64)>,
}

/// `trainer eval --json` of `model` on the soak test `soak` (written to
/// `json`).
pub(crate) fn soak_spread(trainer: &Path, model: &Path, soak: &Path, json: &Path) -> anyhow::Result<SoakReading> {
    run_tool(
        trainer,
        &[
            "eval",
            "--model",
            path(model),
            path(soak),
            "--json",
            path(json),
            "--force",
        ],
    )?;
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(json)?)
        .with_context(|| format!("{}: trainer eval --json is not JSON", json.display()))?;
    let plateaus = |bias: &str| -> Vec<(f64, f64)> {
        v[0]["plateaus"]
            .as_array()
            .map(|ps| {
                ps.iter()
                    .filter_map(|p| Some((p["temp_c"].as_f64()?, p[bias].as_f64()?)))
                    .collect()
            })
            .unwrap_or_default()
    };
    Ok(SoakReading {
        after_dph: v[0]["settled_spread_dph"].as_f64(),
        before_dph: v[0]["settled_spread_before_dph"].as_f64(),
        in_range_dph: v[0]["settled_spread_in_range_dph"].as_f64(),
        plateaus: plateaus("bias_after_dph"),
        plateaus_before: plateaus("bias_before_dph"),
    })
}
