"""Times `trainer fit` and the pandas + scikit-learn pipeline on the same
large recorded run, one after the other, with each one's peak memory
(os.wait4's ru_maxrss of that child alone).

Usage: python run.py TRAINER RUN.csv WORK_DIR
Called by `cargo xtask bench-large-run`, which makes RUN.csv with
`trainer simulate` and the venv with pandas and scikit-learn.
"""

import json
import os
import subprocess
import sys
import time


def timed(cmd, log_path):
    """Runs cmd; returns (seconds, peak RSS in MB, stdout)."""
    with open(log_path, "w") as log:
        started = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
        elapsed = time.perf_counter() - started
    with open(log_path) as log:
        out = log.read()
    if status != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{out}")
    return elapsed, usage.ru_maxrss / 1024.0, out


def main(trainer, run, work):
    here = os.path.dirname(os.path.abspath(__file__))
    model = os.path.join(work, "model.bin")
    report = os.path.join(work, "fit.json")
    rows = sum(1 for line in open(run) if line[:1].isdigit())
    size_mb = os.path.getsize(run) / 1e6
    ours_s, ours_mb, _ = timed(
        [trainer, "fit", "-q", "--force", run, "-o", model, "--json", report],
        os.path.join(work, "trainer.log"),
    )
    fit = json.load(open(report))
    ours_pct = fit["runs"][0]["evaluation"]["cluster_std_improvement_pct"]
    theirs_s, theirs_mb, out = timed(
        [sys.executable, os.path.join(here, "pandas_pipeline.py"), run],
        os.path.join(work, "pandas.log"),
    )
    theirs_pct = float(out.strip().split("improvement ")[-1].split(" ")[0])
    print(f"large run: {rows} rows, {size_mb:.0f} MB ({run})")
    print(f"{'pipeline':<24} {'wall [s]':>9} {'peak RSS [MB]':>14} {'100-s STD improvement [%]':>26}")
    print(f"{'trainer fit':<24} {ours_s:>9.2f} {ours_mb:>14.0f} {ours_pct:>26.1f}")
    print(f"{'pandas + scikit-learn':<24} {theirs_s:>9.2f} {theirs_mb:>14.0f} {theirs_pct:>26.1f}")
    print(f"trainer fit is {theirs_s / ours_s:.1f}x faster, peak memory {ours_mb:.0f} MB")


if __name__ == "__main__":
    main(*sys.argv[1:4])
