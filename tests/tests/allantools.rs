//! The Allan deviation against allantools (the Python reference a navigation
//! engineer would check with), installed into a throwaway venv.
//!
//! Ignored in a plain `cargo test` (it needs PyPI); `cargo xtask ci` runs it.

use std::process::Command;

use trainer::evaluation::allan;
use trainer::reading::run::samples::Run;

#[test]
#[ignore = "installs allantools from PyPI into a temporary venv: run by `cargo xtask ci`"]
fn overlapping_allan_deviation_matches_allantools_to_1e_9() {
    let run = Run::load(&e2e_tests::example("ifog_verify_3cpm.csv")).unwrap();
    let reference = run.reference_dph();
    let rate: Vec<f64> = (0..run.len()).map(|i| run.rate_dph[i] - reference.at(i)).collect();
    let tau0 = run.nominal_period_s;
    let m = allan::octave_sizes(rate.len());
    let ours = allan::oadev(&rate, tau0, &m);

    let dir = tempfile::TempDir::new().unwrap();
    let venv = dir.path().join("venv");
    let ok = |c: &mut Command| c.status().map(|s| s.success()).unwrap_or(false);
    assert!(
        ok(Command::new("python3").args(["-m", "venv"]).arg(&venv)),
        "python3 -m venv failed"
    );
    let python = venv.join("bin/python");
    assert!(
        ok(Command::new(&python).args(["-m", "pip", "install", "--quiet", "allantools", "numpy"])),
        "pip install allantools failed"
    );
    let data = dir.path().join("rate.txt");
    std::fs::write(&data, rate.iter().map(|v| format!("{v:.17e}\n")).collect::<String>()).unwrap();
    let taus: Vec<String> = m.iter().map(|&m| format!("{}", m as f64 * tau0)).collect();
    let script = format!(
        "import numpy, allantools\n\
         y = numpy.loadtxt('{}')\n\
         t, d, e, n = allantools.oadev(y, rate={}, data_type='freq', taus=[{}])\n\
         print(' '.join(repr(float(v)) for v in d))\n",
        data.display(),
        1.0 / tau0,
        taus.join(",")
    );
    let out = Command::new(&python).args(["-c", &script]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let theirs: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(theirs.len(), ours.len(), "allantools returned {theirs:?}");
    for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        let rel = (a - b).abs() / b.abs();
        assert!(
            rel < 1e-9,
            "τ = {} s: ours {a}, allantools {b}, relative {rel:e}",
            m[i] as f64 * tau0
        );
    }
}
