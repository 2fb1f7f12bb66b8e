//! Fixtures shared by the firmware host tests and the QEMU tests: a short
//! chamber run, a model fitted on it, and a slice of another run with
//! injected temperature-sensor faults.

use std::path::{Path, PathBuf};

use trainer::fit::{self, FitOptions};
use trainer::reading::run::samples::Run;
use trainer::simulate::ChamberRun;

/// Rows of the fault-injected slice.
pub const ROWS: usize = 4000;

/// True on the rows where the temperature sensor is made to fail: a single
/// sample, a 5-sample burst and a 40-sample outage (longer than the 10-s hold).
pub fn faulty(row: usize) -> bool {
    row == 500 || (1500..1505).contains(&row) || (2500..2540).contains(&row)
}

/// Rows [`faulty`] marks.
pub const FAULTY_ROWS: u32 = 46;

/// `chamber`'s run written into `dir` as `name` and read back as the trainer reads it.
fn recorded(dir: &Path, chamber: &ChamberRun, name: &str) -> Run {
    let path = dir.join(name);
    std::fs::write(&path, chamber.to_csv()).expect("write training run");
    Run::load(&path).expect("simulated run reads")
}

/// Fits a 16-centre model of the default features (the lag bank) on a
/// 1 °C/min run and writes a fault-injected slice of a 2 °C/min run into
/// `dir`; returns (model, slice path).
pub fn model_and_faulty_slice(dir: &Path) -> (rbf_core::Model, PathBuf) {
    let mut chamber = ChamberRun::ifog(1.0, 31);
    chamber.hold_s = 1800.0;
    let train = recorded(dir, &chamber, "train.csv");
    let opts = FitOptions {
        method: fit::Method::LagBank(fit::LagBankOptions {
            centers: Some(16),
            structure_choice: true,
        }),
        ..FitOptions::default()
    };
    let model = fit::fit(std::slice::from_ref(&train), &[], &opts).expect("fit").model;
    (
        model,
        faulty_slice(dir, &ChamberRun::ifog(2.0, 32).to_csv(), "slice.csv"),
    )
}

/// Fits a thermal response bank (`Method::ResponseBank`: 12 filters,
/// no centres) on a 1 °C/min run and writes a fault-injected slice of a
/// 2 °C/min run into `dir`; returns (model, slice path).
pub fn response_bank_model_and_faulty_slice(dir: &Path) -> (rbf_core::Model, PathBuf) {
    let mut chamber = ChamberRun::ifog(1.0, 61);
    chamber.hold_s = 1800.0;
    let train = recorded(dir, &chamber, "train_response.csv");
    let opts = FitOptions {
        method: fit::Method::ResponseBank,
        ..FitOptions::default()
    };
    let model = fit::fit(std::slice::from_ref(&train), &[], &opts).expect("fit").model;
    (
        model,
        faulty_slice(dir, &ChamberRun::ifog(2.0, 62).to_csv(), "slice_response.csv"),
    )
}

/// Fits a 16-centre network of the lagged second-order set
/// (`FeatureSet::MultiScaleLagged`, coil lag 40 min: Gaussians over
/// T − L·ΔT₃) on a 1 °C/min cycle run and writes a fault-injected slice of a
/// 3 °C/min cycle run into `dir`; returns (model, slice path).
pub fn lagged_model_and_faulty_slice(dir: &Path) -> (rbf_core::Model, PathBuf) {
    let mut chamber = ChamberRun::cycle(1.0, 51);
    chamber.hold_s = 1800.0;
    let train = recorded(dir, &chamber, "train_cycle.csv");
    let search = fit::RbfSearch {
        centers: fit::CenterBudget::Fixed(16),
        rate_windows_s: vec![15.0],
        ..fit::RbfSearch::default()
    };
    let set = rbf_core::FeatureSet::MultiScaleLagged { coil_lag_min: 40 };
    let progress = fit::Progress::new(false);
    let train = std::slice::from_ref(&train);
    let (model, _) = fit::rbf::fit(train, &[], set, &FitOptions::default(), &search, &progress).expect("fit");
    (
        model,
        faulty_slice(dir, &ChamberRun::cycle(3.0, 52).to_csv(), "slice_cycle.csv"),
    )
}

/// Fits a 16-centre `svr-pso` model on multi-point inputs (the loop
/// temperature temp_c and the gradients temp_a − temp_e and temp_c − temp_d)
/// on a 1 °C/min multi-point run and writes a fault-injected slice of a
/// 2 °C/min multi-point run into `dir` (`temp_fault` fails every
/// thermometer); returns (model, slice path).
pub fn multipoint_model_and_faulty_slice(dir: &Path) -> (rbf_core::Model, PathBuf) {
    use rbf_core::features::Probe;
    let mut chamber = ChamberRun::ifog(1.0, 41);
    chamber.hold_s = 1800.0;
    chamber.multi = true;
    let train = recorded(dir, &chamber, "train_multi.csv");
    let opts = FitOptions {
        method: fit::Method::SvrPso(fit::SvrOptions {
            centers: fit::CenterBudget::Fixed(16),
            rate_windows_s: fit::RbfSearch::default().rate_windows_s,
            inputs: fit::SvrInputs::Named(vec![Probe::Temp(2), Probe::Gradient(0, 4), Probe::Gradient(2, 3)]),
        }),
        ..FitOptions::default()
    };
    let model = fit::fit(std::slice::from_ref(&train), &[], &opts).expect("fit").model;
    let mut verify = ChamberRun::ifog(2.0, 42);
    verify.multi = true;
    (model, faulty_slice(dir, &verify.to_csv(), "slice_multi.csv"))
}

/// The first [`ROWS`] data rows of `run_csv` with a `temp_fault` column marking [`faulty`] rows.
pub fn faulty_slice(dir: &Path, run_csv: &str, name: &str) -> PathBuf {
    let mut text = String::new();
    let mut data = 0;
    for line in run_csv.lines() {
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
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write slice");
    path
}

/// A small valid cubic-in-T model (a second, different model for update tests).
pub fn cubic_model() -> rbf_core::Model {
    firmware_harness::fault_injection::cubic_model().expect("valid cubic model")
}

/// Data rows of the three-axis slice.
pub const AXES_ROWS: usize = 15_000;

/// True on the three-axis slice's rows with `temp_fault` = 1 (every
/// axis's thermometers fail): a burst and an outage past the 10-s hold.
pub fn axes_faulty(row: usize) -> bool {
    (3000..3005).contains(&row) || (9000..9040).contains(&row)
}

/// A three-axis IMU as `trainer simulate --axes 3` writes it: fits each
/// axis of a 1 °C/min chamber run with the default features (asking for
/// 32, 24 and 16 centres, so the axes differ in model; OLS keeps at most 16), writes the multi-axis blob as `trainer fit` does
/// and the first [`AXES_ROWS`] rows of a 2 °C/min cycle run with a
/// `temp_fault` column ([`axes_faulty`]) into `dir`; returns (blob path,
/// slice path).
pub fn axes_blob_and_slice(dir: &Path) -> (PathBuf, PathBuf) {
    use rbf_core::axis::Axis;
    use trainer::dataset::RunFiles;
    use trainer::simulate::axes::write_axes_csv;

    let mut chamber = ChamberRun::ifog(1.0, 61);
    chamber.hold_s = 1800.0;
    let mut train_csv = Vec::new();
    write_axes_csv(&chamber, 3, false, &mut train_csv).expect("simulate three axes");
    let train = dir.join("train_axes.csv");
    std::fs::write(&train, &train_csv).expect("write training run");
    let none: &[Run] = &[];
    let mut models = Vec::new();
    for (axis, centers) in [(Axis::X, 32), (Axis::Y, 24), (Axis::Z, 16)] {
        let opts = FitOptions {
            method: fit::Method::LagBank(fit::LagBankOptions {
                centers: Some(centers),
                structure_choice: true,
            }),
            ..FitOptions::default()
        };
        let runs = RunFiles::for_axis(std::slice::from_ref(&train), Some(axis));
        let model = fit::fit(&runs, none, &opts).expect("fit an axis").model;
        models.push((axis, model));
    }
    let refs: Vec<(Axis, &rbf_core::Model)> = models.iter().map(|(a, m)| (*a, m)).collect();
    let blob = trainer::blobfile::encode_axis_models(&refs, None).expect("encode the axes");
    let blob_path = dir.join("axes.bin");
    std::fs::write(&blob_path, blob).expect("write blob");
    (blob_path, axes_slice(dir, false))
}

/// [`axes_blob_and_slice`] for an IMU whose three coils read one
/// thermometer (`simulate --axes 3 --shared-thermometer`): axis x's fit
/// (16 centres asked for) is the basis, every axis's output layer is
/// refitted on it ([`fit::joint::refit_layers`], as `trainer fit` does),
/// written as a shared-basis blob; the slice as there, with one
/// thermometer. Returns (blob path, slice path).
pub fn shared_blob_and_slice(dir: &Path) -> (PathBuf, PathBuf) {
    use rbf_core::axis::Axis;
    use trainer::dataset::RunFiles;
    use trainer::simulate::axes::write_axes_csv;

    let mut chamber = ChamberRun::ifog(1.0, 61);
    chamber.hold_s = 1800.0;
    let mut train_csv = Vec::new();
    write_axes_csv(&chamber, 3, true, &mut train_csv).expect("simulate three axes");
    let train = dir.join("train_shared.csv");
    std::fs::write(&train, &train_csv).expect("write training run");
    let none: &[Run] = &[];
    let opts = FitOptions {
        method: fit::Method::LagBank(fit::LagBankOptions {
            centers: Some(16),
            structure_choice: true,
        }),
        ..FitOptions::default()
    };
    let runs = RunFiles::for_axis(std::slice::from_ref(&train), Some(Axis::X));
    let basis = fit::fit(&runs, none, &opts).expect("fit axis x");
    let ridge = basis.rbf_choice().expect("an RBF fit").ridge;
    let trains: Vec<RunFiles> = Axis::ALL
        .iter()
        .map(|&axis| RunFiles::for_axis(std::slice::from_ref(&train), Some(axis)))
        .collect();
    let pairs: Vec<(Axis, &RunFiles)> = Axis::ALL.into_iter().zip(&trains).collect();
    let shared = fit::joint::refit_layers(&basis.model, ridge, &pairs, opts.block_s).expect("joint fit");
    assert!(shared.centers_used() > 1, "a basis of one centre tests little");
    let blob = trainer::blobfile::encode_shared_models(&shared, None).expect("encode the shared basis");
    let blob_path = dir.join("shared.bin");
    std::fs::write(&blob_path, blob).expect("write blob");
    (blob_path, axes_slice(dir, true))
}

/// The first [`AXES_ROWS`] rows of a three-axis 2 °C/min cycle run (one
/// thermometer for every coil when `shared_thermometer`) with a
/// `temp_fault` column ([`axes_faulty`]), written into `dir`; its path.
fn axes_slice(dir: &Path, shared_thermometer: bool) -> PathBuf {
    use trainer::simulate::axes::write_axes_csv;

    let mut verify_csv = Vec::new();
    write_axes_csv(&ChamberRun::cycle(2.0, 62), 3, shared_thermometer, &mut verify_csv).expect("simulate three axes");
    let verify = String::from_utf8(verify_csv).expect("UTF-8 run");
    let mut text = String::new();
    let mut data = 0;
    for line in verify.lines() {
        if line.starts_with('#') {
            text.push_str(line);
            text.push('\n');
        } else if line.starts_with("time_s") {
            text.push_str(&format!("{line},temp_fault\n"));
        } else if data < AXES_ROWS {
            text.push_str(&format!("{line},{}\n", u8::from(axes_faulty(data))));
            data += 1;
        }
    }
    assert_eq!(data, AXES_ROWS, "the verify run is shorter than the slice");
    let slice = dir.join(if shared_thermometer {
        "slice_shared.csv"
    } else {
        "slice_axes.csv"
    });
    std::fs::write(&slice, text).expect("write slice");
    slice
}
