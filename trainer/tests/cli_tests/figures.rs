//! Figures that tell one story (issue 49, item 10): a run gets the same MSD
//! and STD100 whichever command reports it, and a fit prints one held-out
//! figure, saying what the forecast rests on.

use crate::common::{fitted_model, stderr, stdout, trainer};
use tempfile::TempDir;

/// The figures of the table row of `run` in `printed`: everything after the
/// role and run name.
fn row_figures(printed: &str, run: &str) -> Vec<String> {
    let line = printed
        .lines()
        .find(|l| l.split_whitespace().nth(1) == Some(run))
        .unwrap_or_else(|| panic!("no row for {run} in {printed}"));
    line.split_whitespace().skip(2).map(str::to_owned).collect()
}

#[test]
fn a_training_run_gets_the_same_figures_from_fit_and_eval_and_one_held_out_figure() {
    let dir = TempDir::new().unwrap();
    let _ = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let model = dir.path().join("again.bin");
    let fit = trainer(&[
        "fit",
        "-q",
        "--block-s",
        "4",
        run.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
    ]);
    assert!(fit.status.success(), "{}", stderr(&fit));
    let fitted = stdout(&fit);
    let eval = trainer(&["eval", "--model", model.to_str().unwrap(), run.to_str().unwrap()]);
    assert!(eval.status.success(), "{}", stderr(&eval));
    assert_eq!(
        row_figures(&fitted, "train.csv"),
        row_figures(&stdout(&eval), "train.csv"),
        "{fitted}"
    );
    assert!(!fitted.contains("scored on the fit's"), "{fitted}");
    let held_out = fitted.matches("validation RMS").count() + fitted.matches("held-out RMS").count();
    assert_eq!(held_out, 1, "{fitted}");
    assert!(
        fitted.contains("(it chose the structure; the forecast above is the training residual times its factor"),
        "{fitted}"
    );
}
