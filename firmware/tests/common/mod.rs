//! Shared fixtures: a short chamber run with sensor faults and a model fitted on it.

use std::path::{Path, PathBuf};

use trainer::fit::{self, FitOptions};
use trainer::run::Run;
use trainer::simulate::ChamberRun;

/// Rows of the fault-injected slice.
pub const ROWS: usize = 4000;

/// True on the rows where the temperature sensor is made to fail: a single
/// sample, a 5-sample burst and a 40-sample outage (longer than the 10-s hold).
pub fn faulty(row: usize) -> bool {
    row == 500 || (1500..1505).contains(&row) || (2500..2540).contains(&row)
}

/// Writes the training run and a fault-injected slice of a second run into `dir`;
/// returns (model, slice path).
pub fn model_and_faulty_slice(dir: &Path) -> (rbf_core::Model, PathBuf) {
    let mut chamber = ChamberRun::ifog(1.0, 31);
    chamber.hold_s = 1800.0;
    let train_path = dir.join("train.csv");
    std::fs::write(&train_path, chamber.to_csv()).unwrap();
    let train = Run::load(&train_path).unwrap();
    let opts = FitOptions {
        centers: Some(16),
        rate_windows_s: vec![60.0],
        ..FitOptions::default()
    };
    let model = fit::fit(std::slice::from_ref(&train), &[], &opts).unwrap().model;

    let verify = ChamberRun::ifog(2.0, 32).to_csv();
    let mut text = String::new();
    let mut data = 0;
    for line in verify.lines() {
        if line.starts_with('#') {
            text.push_str(line);
            text.push('\n');
        } else if line.starts_with("time_s") {
            text.push_str(&format!("{line},temp_fault\n"));
        } else if data < ROWS {
            text.push_str(&format!("{line},{}\n", u8::from(faulty(data))));
            data += 1;
        }
    }
    let slice = dir.join("slice.csv");
    std::fs::write(&slice, text).unwrap();
    (model, slice)
}
