//! `trainer fit`: fit a bias model to recorded runs and write the model blob.

use std::io::Write;
use std::path::{Path, PathBuf};

use trainer::acceptance::{Rejected, Spec};
use trainer::blobfile::encode_model;
use trainer::dataset::RunFiles;
use trainer::evaluation::evaluate::{RunEvaluation, RunModels, evaluate_file, evaluate_reader, only_axis};
use trainer::evaluation::table::print_table;
use trainer::fit;
use trainer::output::{self, Output, StagedDir, Transaction};
use trainer::provenance::ProvenanceRecord;
use trainer::reading::plausible;
use trainer::reading::run::RunReader;
use trainer::records::{Access, Store};
use trainer::text;
use trainer::{evaluation::diagnose, reading::input};

use super::common::{JsonSink, print_json_and_commit, print_notes};

mod args;
mod axes;
mod blob_out;
pub(super) mod json;
mod judging;
mod record_out;
mod summary;

pub use self::args::Args;
use self::blob_out::write_blob;
use self::json::{outcome_json, runs_json};
use self::judging::{Calibration, judge_axis, verdict_text};
use self::record_out::write_records;
use self::summary::{FitHow, training_loop_range_c, training_settled_floor, write_summary, write_vouching};

/// Runs `trainer fit`.
pub fn run(a: Args) -> anyhow::Result<()> {
    // A fit reads its runs several times: files only. Outputs are checked
    // against them before any work; the model and the JSON are written last,
    // after every fallible step, so a failure never leaves a replaced model.
    let all_runs: Vec<&Path> = a
        .runs
        .iter()
        .chain(&a.validate)
        .chain(&a.holdout)
        .map(|p| p.as_path())
        .collect();
    input::require_seekable(all_runs.iter().copied(), "`trainer fit` reads its runs several times")?;
    let in_use = a.in_use()?;
    let opts = a.fit_options()?;
    let existing = a.force.existing();
    let json_file = a.json.json.as_deref().filter(|p| !input::is_stdin(p));
    let outputs: Vec<&Path> = std::iter::once(a.output.as_path()).chain(json_file).collect();
    let mut targets = output::check_targets(&outputs, &all_runs, existing)?.into_iter();
    let report_runs: Vec<PathBuf> = all_runs.iter().map(|p| p.to_path_buf()).collect();
    // The report directory is replaced as a whole: no other output may lie in it.
    let report_target = match &a.report {
        Some(dir) => Some(trainer::report::check_report_targets(&report_runs, dir, &all_runs, &outputs, existing)?.1),
        None => None,
    };
    // Runs are streamed (memory stays flat whatever their length); their
    // headers and first rows are checked now, so a bad file is reported
    // before any work (a multi-axis run's other axes: by `axes::run`).
    for path in &all_runs {
        RunReader::open(path)?.require_temp()?;
    }
    trainer::reading::distinct::require_distinct_runs(&[
        ("training", &a.runs),
        ("--validate", &a.validate),
        ("--holdout", &a.holdout),
    ])?;
    let spec = a.spec.as_deref().map(Spec::read).transpose()?;
    // The records store before the fit: one that cannot take the record fails the fit now.
    let store = a
        .records
        .as_deref()
        .map(|locator| Store::open(locator, Access::Write))
        .transpose()?;
    // Digests and the fit time, taken before the fit reads the runs.
    let provenance = ProvenanceRecord::for_fit(a.serial.as_deref(), &a.runs, a.spec.as_deref(), a.batch.as_deref())?;
    let train = RunFiles::new(&a.runs);
    let validate = RunFiles::new(&a.validate);
    let axes = trainer::evaluation::axes::common_axes(&all_runs)?;
    let model_out = targets.next().map(Output::open).transpose()?;
    let json_out = match targets.next() {
        Some(target) => JsonSink::File(Output::open(target)?),
        None if a.json.json.is_some() => JsonSink::Stdout,
        None => JsonSink::None,
    };
    if !axes.is_empty() {
        let how = FitHow::new(&opts, !a.validate.is_empty());
        let calibration = Calibration {
            provenance: &provenance,
            spec: spec.as_ref(),
            store,
        };
        return axes::run(&a, &opts, &how, &axes, model_out, json_out, calibration);
    }
    let started = std::time::Instant::now();
    let outcome = fit_diagnosed(&a, &train, &validate, &opts)?;
    let fit_s = started.elapsed().as_secs_f64();
    // The checks `eval` and `compensate` make (units of time, rate and
    // temperature), on the runs the fit read only in blocks; after the fit,
    // whose own refusal names the cause better when nothing was usable.
    // Their gaps are named as `eval` and `compensate` name them.
    let training_and_validation: Vec<PathBuf> = a.runs.iter().chain(&a.validate).cloned().collect();
    let findings = diagnose::run_findings(&training_and_validation, None)?;
    plausible::require_plausible(&findings.implausible, a.allow_implausible)?;
    print_notes(&findings.gap_notices);
    if let Some((lo, hi)) = training_loop_range_c(&outcome) {
        let finding = plausible::range_finding("the training runs' loop temperature", lo, hi);
        plausible::require_plausible(finding.as_slice(), a.allow_implausible)?;
    }
    // Every run scored as `trainer eval` and `trainer report` score it: every
    // sample, MSD of 1-s means, warm-up included (one convention: a run gets
    // the same figures whichever command reports it).
    drop((train, validate));
    let evals = score_runs(&a, &outcome.model)?;
    let blob = encode_model(&outcome.model, Some(&provenance))?;

    // Printed once everything is written.
    let mut out: Vec<u8> = Vec::new();
    let how = FitHow::new(&opts, !a.validate.is_empty());
    write_summary(&mut out, &outcome, &how)?;
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    if let Some(search) = outcome.bank_search() {
        writeln!(out)?;
        for line in search
            .coverage
            .lines(&in_use, fit::coverage::model_range_c(&outcome.model))
        {
            writeln!(out, "{line}")?;
        }
    }
    let settled_floor = training_settled_floor(&evals, None);
    if outcome.bank_search().is_none() && settled_floor.is_some() {
        writeln!(out)?;
    }
    write_vouching(&mut out, &outcome, &in_use, settled_floor.as_ref())?;
    let verdict = spec
        .as_ref()
        .map(|spec| judge_axis(spec, &in_use, &outcome, &evals, None));
    if let Some(v) = &verdict {
        writeln!(out, "\n{}", verdict_text(v))?;
    }
    writeln!(out, "\nwrote {} ({} bytes)", text::path(&a.output), blob.len())?;
    let mut json = outcome_json(&outcome, &in_use, settled_floor.as_ref());
    json["method"] = serde_json::json!(opts.method.name());
    json["fit_seconds"] = serde_json::json!(fit_s);
    json["blob_bytes"] = serde_json::json!(blob.len());
    json["runs"] = runs_json(&evals);
    json["acceptance"] = match &verdict {
        Some(v) => serde_json::json!({"status": if v.passed() { "pass" } else { "fail" }, "reasons": v.reasons}),
        None => serde_json::Value::Null,
    };
    // Every output staged, then printed, then committed together.
    let mut transaction = Transaction::new();
    if let Some(target) = report_target {
        let staged = stage_report(&a, &outcome.model, &report_runs, target, &mut out)?;
        transaction.add_dir(staged);
    }
    write_blob(model_out, &blob, &mut transaction)?;
    let json_on_stdout = json_out.is_stdout();
    let json_doc = json;
    let json = json_out.write(&json_doc, &mut transaction)?;
    print_json_and_commit(&out, json_on_stdout, json, transaction)?;
    write_records(store, a.serial.as_deref(), &json_doc, &blob)?;
    match verdict {
        Some(v) if !v.passed() => {
            Err(Rejected(format!("the unit missed its acceptance spec: {}", v.reasons.join("; "))).into())
        }
        _ => Ok(()),
    }
}

/// The single-axis fit of `train` (validated on `validate`) with `opts`; a
/// refusal names its cause: a validation run too short to score blames
/// itself, an unidentifiable fit the runs' shortcomings.
fn fit_diagnosed(
    a: &Args,
    train: &RunFiles,
    validate: &RunFiles,
    opts: &fit::FitOptions,
) -> anyhow::Result<fit::FitOutcome> {
    fit::fit(train, validate, opts).map_err(|e| {
        let short = diagnose::short_runs(&a.validate, "--validate", fit::excitation::MIN_USABLE_S);
        if !short.is_empty() {
            anyhow::anyhow!("{}", short.join("; "))
        } else if e.chain().any(|c| c.is::<fit::Unidentifiable>()) {
            diagnose::with_causes(e, &a.runs, opts.method.thermometers())
        } else {
            e
        }
    })
}

/// Every run of the fit scored with `model` as `trainer eval` scores it, by
/// role (train, validate, holdout); a holdout run implausible as a gyro
/// recording is refused unless allowed.
fn score_runs(a: &Args, model: &rbf_core::Model) -> anyhow::Result<Vec<(&'static str, RunEvaluation)>> {
    let mut evals: Vec<(&'static str, RunEvaluation)> = Vec::new();
    for (role, paths) in [("train", &a.runs), ("validate", &a.validate)] {
        for path in paths {
            evals.push((role, evaluate_file(model, path, None)?));
        }
    }
    for path in &a.holdout {
        let reader = RunReader::open(path)?;
        let models = RunModels::one(Some(model), &reader);
        let (evaluation, diagnosis, _) = only_axis(evaluate_reader(&models, reader)?)?;
        plausible::require_plausible(&diagnosis.implausible(), a.allow_implausible)?;
        print_notes(diagnosis.gap_notice().as_slice());
        evals.push(("holdout", evaluation));
    }
    Ok(evals)
}

/// `--report DIR`, staged: what `trainer report` writes for every run of the
/// fit, and fit.txt (`out`, what the command printed, to which the line
/// saying so is then added).
fn stage_report(
    a: &Args,
    model: &rbf_core::Model,
    report_runs: &[PathBuf],
    target: output::DirTarget,
    out: &mut Vec<u8>,
) -> anyhow::Result<StagedDir> {
    let staged = StagedDir::create(target)?;
    // The fit has checked its runs; the report takes them as they are.
    let accept = trainer::evaluation::axes::Acceptance {
        uncompensated: true,
        implausible: true,
    };
    let (files, ..) = trainer::report::write_report(
        model,
        &a.output,
        trainer::report::ReportRuns {
            paths: report_runs,
            trained_on: Some(a.runs.len()),
        },
        &staged,
        Path::new(""),
        accept,
        None,
    )?;
    staged.write(Path::new(FIT_TEXT), out)?;
    writeln!(out, "wrote {} files into {}", files + 1, text::path(staged.target()))?;
    Ok(staged)
}

/// The file in `--report DIR` that holds what `fit` prints.
const FIT_TEXT: &str = "fit.txt";
