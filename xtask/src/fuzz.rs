//! `cargo xtask fuzz --seconds N`: every libFuzzer target in fuzz/ for N
//! seconds, side by side, from a seed corpus written fresh by the current
//! encoders.
//!
//! The targets run without a sanitizer (`cargo fuzz run -s none`): the code
//! they reach forbids `unsafe`, so AddressSanitizer (nightly only) would have
//! nothing to add, and the defects left (panics, failed invariants, overflow,
//! runaway memory or time) are caught by libFuzzer itself with debug
//! assertions and overflow checks on. Runs on the stable toolchain.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};
use gyro_wire::frame::{self, MAX_FRAME_LEN, OutputFrame};
use rbf_core::blob::{self, HEADER_LEN, MAX_BLOB_LEN};
use rbf_core::model::{ModelBody, ModelInfo};
use rbf_core::poly::Poly3;
use rbf_core::{FeatureConfig, FeatureSet, Model};
use trainer::fit::{self, CenterBudget, FitOptions, LagBankOptions, Method, RbfInputs, RbfSearch};
use trainer::reading::run::samples::Run;

use crate::{output, run, workspace_root};

/// The fuzz targets (fuzz/fuzz_targets/*.rs; their checks are in e2e-tests' `robustness`).
pub const TARGETS: [&str; 3] = ["blob_decode", "run_reader", "frame_decode"];

/// What one target's run found.
#[derive(Clone, Debug)]
pub struct FuzzOutcome {
    /// Target name.
    pub target: &'static str,
    /// Inputs executed.
    pub executions: u64,
    /// Inputs in the working corpus afterwards.
    pub corpus: usize,
    /// Crash, timeout, OOM or leak reproducers written (0 = nothing found).
    pub findings: Vec<PathBuf>,
}

/// Installs cargo-fuzz when missing.
pub fn ensure_cargo_fuzz() -> anyhow::Result<()> {
    if output("cargo", &["fuzz", "--version"]).starts_with("cargo-fuzz") {
        return Ok(());
    }
    run("cargo", &["install", "cargo-fuzz", "--locked"])
}

/// Builds every target and runs each for `seconds`, all at once; prints a table and fails on
/// any finding.
pub fn fuzz(seconds: u32) -> anyhow::Result<Vec<FuzzOutcome>> {
    build_targets()?;
    run_targets(seconds)
}

/// Installs cargo-fuzz when missing and builds every target (`--dev`, no sanitizer).
pub fn build_targets() -> anyhow::Result<()> {
    ensure_cargo_fuzz()?;
    run("cargo", &["fuzz", "build", "--dev", "--fuzz-dir", "fuzz", "-s", "none"])
}

/// Runs every target (built by [`build_targets`]) for `seconds`, all at once, from a fresh
/// seed corpus; prints a table and fails on any finding.
pub fn run_targets(seconds: u32) -> anyhow::Result<Vec<FuzzOutcome>> {
    let work = crate::target_dir().join("fuzz");
    write_seeds(&work.join("seeds"))?;
    // The targets side by side: each is one libFuzzer process, and CI waits
    // for `seconds` once rather than once per target.
    let outcomes = std::thread::scope(|scope| {
        let runs: Vec<_> = TARGETS
            .map(|target| scope.spawn(|| fuzz_target(&work, target, seconds)))
            .into_iter()
            .collect();
        runs.into_iter()
            .map(|run| {
                run.join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("a fuzz target's thread panicked")))
            })
            .collect::<anyhow::Result<Vec<FuzzOutcome>>>()
    })?;
    println!("\n| target | seconds | executions | corpus | findings |\n|---|---:|---:|---:|---:|");
    for o in &outcomes {
        println!(
            "| {} | {seconds} | {} | {} | {} |",
            o.target,
            o.executions,
            o.corpus,
            o.findings.len()
        );
    }
    let found: Vec<String> = outcomes
        .iter()
        .flat_map(|o| o.findings.iter().map(|p| p.display().to_string()))
        .collect();
    if !found.is_empty() {
        bail!(
            "fuzzing found {} input(s) that break a target; reproduce with \
             `cargo fuzz run --dev -s none --fuzz-dir fuzz TARGET FILE`:\n{}",
            found.len(),
            found.join("\n")
        );
    }
    Ok(outcomes)
}

fn fuzz_target(work: &Path, target: &'static str, seconds: u32) -> anyhow::Result<FuzzOutcome> {
    let corpus = work.join("corpus").join(target);
    let seeds = work.join("seeds").join(target);
    let artifacts = work.join("artifacts").join(target);
    for dir in [&corpus, &artifacts] {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    eprintln!("\n==> cargo fuzz run {target} for {seconds} s");
    let result = Command::new("cargo")
        .args(["fuzz", "run", "--dev", "--fuzz-dir", "fuzz", "-s", "none", target])
        .arg(&corpus)
        .arg(&seeds)
        .arg("--")
        .arg(format!("-max_total_time={seconds}"))
        .arg(format!("-artifact_prefix={}/", artifacts.display()))
        .arg("-print_final_stats=1")
        .current_dir(workspace_root())
        .output()
        .context("cannot start cargo fuzz")?;
    let log = String::from_utf8_lossy(&result.stderr);
    let executions = log
        .lines()
        .find_map(|l| l.strip_prefix("Done ")?.split_whitespace().next()?.parse().ok())
        .or_else(|| {
            log.lines()
                .find_map(|l| l.strip_prefix("stat::number_of_executed_units:")?.trim().parse().ok())
        })
        .unwrap_or(0);
    let findings: Vec<PathBuf> = std::fs::read_dir(&artifacts)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| !n.to_string_lossy().starts_with('.')))
        .collect();
    if !result.status.success() && findings.is_empty() {
        eprintln!("{log}");
        bail!(
            "cargo fuzz run {target} failed ({}) without a reproducer",
            result.status
        );
    }
    if !findings.is_empty() {
        eprintln!("{log}");
    }
    Ok(FuzzOutcome {
        target,
        executions,
        corpus: std::fs::read_dir(&corpus)?.count(),
        findings,
    })
}

/// Writes the seed corpus of every target under `dir/<target>/`, from the
/// current encoders and the bundled example runs.
pub fn write_seeds(dir: &Path) -> anyhow::Result<()> {
    let data = workspace_root().join("examples/data");
    let write = |target: &str, name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let d = dir.join(target);
        std::fs::create_dir_all(&d)?;
        std::fs::write(d.join(name), bytes).with_context(|| format!("{}: cannot write seed", d.display()))
    };

    // Model blobs: a fitted default (lag-bank) and multiscale model, the paper's network, a cubic; each
    // also in the target's "sealed" form (header fields from byte 6, then payload).
    let run = Run::load(&data.join("ifog_verify_3cpm.csv"))?;
    let search = RbfSearch {
        centers: CenterBudget::Fixed(8),
        rate_windows_s: vec![60.0],
        ..RbfSearch::default()
    };
    let fitted = |method| -> anyhow::Result<Model> {
        let opts = FitOptions {
            method,
            ..FitOptions::default()
        };
        Ok(fit::fit(std::slice::from_ref(&run), &[], &opts)?.model)
    };
    let cubic = Model::new(
        FeatureConfig::single(FeatureSet::Temp, 0.0),
        &[(-40.0, 60.0)],
        ModelBody::Poly3(Poly3::new(25.0, [0.5, -0.01, 1e-4, -2e-6]).context("cubic")?),
        ModelInfo::default(),
    )
    .context("cubic model")?;
    let models = [
        (
            "default",
            fitted(Method::LagBank(LagBankOptions {
                centers: Some(8),
                structure_choice: false,
            }))?,
        ),
        ("multiscale", fitted(Method::MultiscaleValidated(search.clone()))?),
        (
            "paper",
            fitted(Method::Rbf {
                inputs: RbfInputs::Paper,
                search,
            })?,
        ),
        ("cubic", cubic),
    ];
    for (name, model) in &models {
        let mut buf = vec![0u8; MAX_BLOB_LEN];
        let len = blob::encode(model, &mut buf)?;
        buf.truncate(len);
        write("blob_decode", &format!("{name}.bin"), &buf)?;
        let sealed: Vec<u8> = buf[6..12].iter().chain(&buf[HEADER_LEN..len - 4]).copied().collect();
        write("blob_decode", &format!("{name}.sealed"), &sealed)?;
    }
    // A three-axis blob of three of them, raw and in the multi-axis sealed
    // form (the axis mask, then the payload).
    let mut axes = Box::new(rbf_core::blob::axes::AxisModels::EMPTY);
    for (axis, (_, model)) in rbf_core::axis::Axis::ALL
        .into_iter()
        .zip([&models[0], &models[1], &models[3]])
    {
        axes.insert(axis, model.clone());
    }
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = rbf_core::blob::axes::encode_axes(&axes, &mut buf).map_err(|e| anyhow::anyhow!("{e}"))?;
    write("blob_decode", "three-axis.bin", &buf[..len])?;
    let sealed: Vec<u8> = [buf[6]].iter().chain(&buf[HEADER_LEN..len - 4]).copied().collect();
    write("blob_decode", "three-axis.sealed", &sealed)?;
    // A shared-basis blob: the paper model's basis, its layer on x and
    // scaled copies of it on y and z; raw and in the sealed form.
    let paper = &models[2].1;
    let mut shared = Box::new(
        rbf_core::shared_basis::SharedAxisModels::from_models(&[(rbf_core::axis::Axis::X, paper)])
            .map_err(|e| anyhow::anyhow!("{e}"))?,
    );
    if let ModelBody::Rbf(net) = paper.body() {
        for (axis, gain) in [(rbf_core::axis::Axis::Y, -0.5f32), (rbf_core::axis::Axis::Z, 0.25)] {
            let weights: Vec<f32> = net.weights().iter().map(|w| w * gain).collect();
            let linear: Vec<f32> = net.linear().iter().map(|a| a * gain).collect();
            let layer = rbf_core::shared_basis::OutputLayer {
                weights: &weights,
                linear: &linear,
                constant: net.constant() * gain,
            };
            shared.assign_layer(axis, &layer).map_err(|e| anyhow::anyhow!("{e}"))?;
        }
    }
    let len = rbf_core::blob::shared_layout::encode_shared(&shared, &mut buf).map_err(|e| anyhow::anyhow!("{e}"))?;
    write("blob_decode", "shared-basis.bin", &buf[..len])?;
    let sealed: Vec<u8> = [buf[6]].iter().chain(&buf[HEADER_LEN..len - 4]).copied().collect();
    write("blob_decode", "shared-basis.sealed", &sealed)?;

    // Output frames: a normal one, one with every flag and NaN temperature, a capture of three.
    let frames = [
        OutputFrame {
            seq: 7,
            rate_dph: 15.04,
            bias_dph: 0.8,
            rate_comp_dph: 14.24,
            temp_c: 25.5,
            flags: 0,
        },
        OutputFrame {
            seq: u32::MAX,
            rate_dph: f32::NAN,
            bias_dph: 0.0,
            rate_comp_dph: f32::NAN,
            temp_c: f32::NAN,
            flags: 0x1f,
        },
    ];
    let mut capture = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = frame::encode(f, &mut buf)?;
        write("frame_decode", &format!("frame{i}.bin"), &buf[..n])?;
        capture.extend_from_slice(&buf[..n]);
    }
    write("frame_decode", "capture.bin", &capture)?;

    // Recorded runs: the head of every example and some near misses.
    for entry in std::fs::read_dir(&data)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "csv") {
            let text = std::fs::read_to_string(&path)?;
            let head: String = text.lines().take(40).flat_map(|l| [l, "\n"]).collect();
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            write("run_reader", &name, head.as_bytes())?;
        }
    }
    let near_misses: [(&str, &str); 5] = [
        (
            "bom_crlf.csv",
            "\u{feff}# sample_rate_hz: 1\r\ntime_s,rate_dph,temp_c\r\n0,1.5,20\r\n1,1.6,20.1\r\n",
        ),
        (
            "fault.csv",
            "time_s,rate_dph,temp_c,temp_fault,ref_dph\n0,1,20,0,0.1\n1,1,,1,0.1\n2,1,nan,1,0.1\n",
        ),
        ("bad_number.csv", "time_s,rate_dph,temp_c\n0,1,20\n1,1.2.3,20\n"),
        ("time_backwards.csv", "time_s,rate_dph,temp_c\n1,1,20\n0.5,1,20\n"),
        (
            "multi.csv",
            "time_s,rate_dph,temp_a,temp_b,temp_c,temp_h\n0,1,20,21,22,23\n1,1,20,21,22,23\n",
        ),
    ];
    for (name, text) in near_misses {
        write("run_reader", name, text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blob target starts from a decodable blob of every model kind the
    /// trainer writes by default, so the fuzzer mutates the layout users flash.
    #[test]
    fn blob_seeds_hold_the_default_lag_bank_model_and_every_other_kind() {
        let dir = tempfile::tempdir().unwrap();
        write_seeds(dir.path()).unwrap();
        let blobs = dir.path().join("blob_decode");
        let decoded = |name: &str| blob::decode(&std::fs::read(blobs.join(name)).unwrap()).unwrap().model;
        assert!(matches!(decoded("default.bin").features().set, FeatureSet::LagBank(_)));
        for name in ["multiscale.bin", "paper.bin", "cubic.bin"] {
            assert!(!matches!(decoded(name).features().set, FeatureSet::LagBank(_)));
        }
        let three = std::fs::read(blobs.join("three-axis.bin")).unwrap();
        let mut axes = Box::new(rbf_core::blob::axes::AxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
        assert_eq!(
            rbf_core::blob::axes::decode_axes_into(&mut axes, &three),
            Ok(three.len())
        );
        assert_eq!(axes.axes().count(), 3);
        let shared = std::fs::read(blobs.join("shared-basis.bin")).unwrap();
        let mut models = Box::new(rbf_core::shared_basis::SharedAxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
        assert_eq!(
            rbf_core::blob::shared_layout::decode_shared_into(&mut models, &shared),
            Ok(shared.len())
        );
        assert_eq!(models.mask(), 0b111);
    }
}
