//! `cargo xtask qemu-replay`: a recorded run through the real firmware image
//! under QEMU, output byte-identical to `trainer compensate`.

use std::path::Path;
use std::time::Duration;

use std::io::Write;

use anyhow::{Context, bail};
use trainer::evaluation::axes::{Acceptance, compensate_command};
use trainer::output::{Existing, Output, Transaction};
use trainer::reading::run::samples::Run;

use crate::{firmware, qemu};

/// Flash address of model slot MODEL_A (memory.x).
pub const MODEL_SLOT_A: u32 = 0x080C_0000;

/// What a replay produced besides the output file.
#[derive(Debug)]
pub struct ReplaySummary {
    /// Samples the firmware processed.
    pub samples: usize,
    /// The firmware's closing line (counters, stack use).
    pub report: String,
}

/// Replays `run` with `model` through the `qemu-replay` image; writes the
/// compensated run to `output` and, if asked, the UART frames to `frames`,
/// replacing them ([`qemu_replay_checked`] with [`Existing::Replace`] and
/// nothing accepted that `trainer compensate` refuses by default).
pub fn qemu_replay(model: &Path, run: &Path, output: &Path, frames: Option<&Path>) -> anyhow::Result<ReplaySummary> {
    qemu_replay_checked(model, run, output, frames, Existing::Replace, Acceptance::default())
}

/// `e` with the `cargo xtask qemu-replay` flag that changes the outcome
/// named, as `trainer compensate` names its own ([`trainer::refusals`]).
pub fn with_flag_hint(e: anyhow::Error) -> anyhow::Error {
    match trainer::refusals::flag_hint(&e) {
        "" => e,
        hint => anyhow::anyhow!("{e:#}{hint}"),
    }
}

/// [`qemu_replay`] as `cargo xtask qemu-replay` runs it: first everything
/// `trainer compensate` checks, by running it (its output discarded), so
/// that the replay refuses what compensate refuses, with its messages (a
/// model for other axes, a run no row of which could be compensated, an
/// implausible run unless `accept` says so, an output that exists unless
/// `existing` allows it); the outputs appear together at the end, or none.
pub fn qemu_replay_checked(
    model: &Path,
    run: &Path,
    output: &Path,
    frames: Option<&Path>,
    existing: Existing,
    accept: Acceptance,
) -> anyhow::Result<ReplaySummary> {
    let inputs = [model, run];
    if let Some(frames) = frames {
        trainer::output::check_target(frames, &inputs, existing)?;
    }
    drop(compensate_command(model, run, output, existing, accept)?);
    let rows = Run::load(run)?.len();
    let elf = firmware::build(firmware::HARNESS, "qemu-replay", &[])?;
    let dir = tempfile::TempDir::new().context("cannot create a working directory")?;
    std::fs::copy(run, dir.path().join("input.csv")).with_context(|| format!("{}: cannot copy", run.display()))?;
    std::fs::copy(model, dir.path().join("model.bin")).with_context(|| format!("{}: cannot copy", model.display()))?;
    let loader = format!("loader,file=model.bin,addr={MODEL_SLOT_A:#x}");
    let deadline = Duration::from_secs(120 + rows as u64 / 5_000);
    let result = qemu::run(&elf, dir.path(), &["-device".into(), loader], deadline)?;
    let report = result
        .log
        .lines()
        .find(|l| l.starts_with("replay: samples"))
        .unwrap_or("")
        .to_owned();
    if !result.success {
        bail!("the firmware replay failed:\n{}", result.log);
    }
    let samples: usize = report
        .split_whitespace()
        .nth(2)
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    if samples != rows {
        bail!("the firmware processed {samples} samples of {rows}:\n{}", result.log);
    }
    let mut transaction = Transaction::new();
    let written = [Some((output, "output.csv")), frames.map(|f| (f, "frames.bin"))];
    // The compensated run starts with the model's provenance lines, as
    // trainer compensate's does; the firmware writes the rest.
    let provenance = trainer::blobfile::provenance_lines(model, &std::fs::read(dir.path().join("model.bin"))?);
    for (target, produced) in written.into_iter().flatten() {
        let bytes =
            std::fs::read(dir.path().join(produced)).with_context(|| format!("the replay wrote no {produced}"))?;
        let mut out = Output::create(target, &inputs, existing)?;
        if produced == "output.csv" {
            out.write_all(provenance.as_bytes())
                .with_context(|| format!("{}: cannot write", target.display()))?;
        }
        out.write_all(&bytes)
            .with_context(|| format!("{}: cannot write", target.display()))?;
        transaction.add(out);
    }
    transaction.commit()?;
    Ok(ReplaySummary { samples, report })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rbf_core::model::{ModelBody, ModelInfo};
    use rbf_core::poly::Poly3;
    use rbf_core::{FeatureConfig, FeatureSet, Model};

    #[test]
    fn the_replay_refuses_what_compensate_refuses_before_running_the_firmware() {
        let dir = tempfile::tempdir().unwrap();
        let model = Model::new(
            FeatureConfig::single(FeatureSet::Temp, 0.0),
            &[(-40.0, 60.0)],
            ModelBody::Poly3(Poly3::new(25.0, [0.5, -0.01, 1e-4, -2e-6]).unwrap()),
            ModelInfo::default(),
        )
        .unwrap();
        let model_path = dir.path().join("m.bin");
        std::fs::write(&model_path, trainer::blobfile::encode_model(&model, None).unwrap()).unwrap();
        // A 0.1 °C/min ramp from `from_c`, 1 Hz.
        let run = |name: &str, from_c: f64| {
            let path = dir.path().join(name);
            let mut text = String::from("time_s,rate_dph,temp_c\n");
            for i in 0..2000 {
                text.push_str(&format!(
                    "{i},{},{}\n",
                    0.01 * f64::from(i % 5),
                    from_c + f64::from(i) / 600.0
                ));
            }
            std::fs::write(&path, text).unwrap();
            path
        };
        let (good, hot) = (run("good.csv", 20.0), run("hot.csv", 120.0));
        let out = dir.path().join("out.csv");
        std::fs::write(&out, "kept").unwrap();
        let refused = |run: &Path, existing| {
            let e = qemu_replay_checked(&model_path, run, &out, None, existing, Acceptance::default()).unwrap_err();
            with_flag_hint(e).to_string()
        };
        let exists = refused(&good, Existing::Refuse);
        assert!(exists.contains("out.csv: exists; pass --force"), "{exists}");
        let implausible = refused(&hot, Existing::Replace);
        assert!(
            implausible.contains("hot.csv: temp_c:") && implausible.contains("--allow-implausible"),
            "{implausible}"
        );
        assert_eq!(
            std::fs::read_to_string(&out).unwrap(),
            "kept",
            "a refused replay changes no file"
        );
    }
}
