"""Times `trainer fit` and `trainer compensate` and the pandas pipelines
doing the same jobs on the same large recorded run, one after the other,
with each one's peak memory (os.wait4's ru_maxrss of that child alone),
throughput, and the floor measured on the same file in the same run: one
pass that only reads it and counts its line ends. The peak memory of a fit
on a run 10x shorter shows whether memory grows with the run's length.
With REPEAT above 0, the trainer's three jobs then run REPEAT more times
each and their median and range are printed: one run of each is noisy on a
shared machine.

Usage: python run.py TRAINER RUN.csv WORK_DIR SHORT_RUN.csv [REPEAT]
Called by `cargo xtask bench-large-run [--repeat N]`, which makes the runs
with `trainer simulate` and the venv with pandas and scikit-learn.
"""

import json
import os
import statistics
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


def floor_pass(run):
    """Seconds to read RUN once and count its line ends (1-MiB reads)."""
    started = time.perf_counter()
    lines = 0
    with open(run, "rb", buffering=0) as f:
        while True:
            block = f.read(1 << 20)
            if not block:
                break
            lines += block.count(b"\n")
    return time.perf_counter() - started, lines


def repeated(name, cmd, log_path, repeat):
    """Prints the median and range of wall time and peak RSS of `repeat` runs of cmd."""
    walls, peaks = [], []
    for _ in range(repeat):
        seconds, mb, _ = timed(cmd, log_path)
        walls.append(seconds)
        peaks.append(mb)
    print(
        f"{name:<28} {statistics.median(walls):>6.2f} s ({min(walls):.2f}-{max(walls):.2f})"
        f" {statistics.median(peaks):>7.1f} MB ({min(peaks):.1f}-{max(peaks):.1f})"
    )


def main(trainer, run, work, short_run, repeat="0"):
    repeat = int(repeat)
    here = os.path.dirname(os.path.abspath(__file__))
    model = os.path.join(work, "model.bin")
    report = os.path.join(work, "fit.json")
    compensated = os.path.join(work, "compensated.csv")
    rows = sum(1 for line in open(run) if line[:1].isdigit())
    size_mb = os.path.getsize(run) / 1e6
    floor_pass(run)  # into the page cache, as the jobs after it find it
    floor_s, _ = floor_pass(run)
    ours_s, ours_mb, _ = timed(
        [trainer, "fit", "-q", "--force", run, "-o", model, "--json", report],
        os.path.join(work, "trainer.log"),
    )
    fit = json.load(open(report))
    ours_pct = fit["runs"][0]["evaluation"]["cluster_std_improvement_pct"]
    comp_s, comp_mb, _ = timed(
        [trainer, "compensate", "--force", "--model", model, run, "-o", compensated],
        os.path.join(work, "compensate.log"),
    )
    _, short_mb, _ = timed(
        [trainer, "fit", "-q", "--force", short_run, "-o", os.path.join(work, "short.bin")],
        os.path.join(work, "short.log"),
    )
    theirs_s, theirs_mb, out = timed(
        [sys.executable, os.path.join(here, "pandas_pipeline.py"), run],
        os.path.join(work, "pandas.log"),
    )
    theirs_pct = float(out.strip().split("improvement ")[-1].split(" ")[0])
    pandas_comp_s, pandas_comp_mb, _ = timed(
        [sys.executable, os.path.join(here, "pandas_compensate.py"), run, os.path.join(work, "pandas_out.csv")],
        os.path.join(work, "pandas_compensate.log"),
    )
    print(f"large run: {rows} rows, {size_mb:.0f} MB ({os.path.basename(run)})")
    head = f"{'job':<28} {'wall [s]':>9} {'peak RSS [MB]':>14} {'MB/s':>7} {'Mrows/s':>8} {'x floor':>8}"
    print(head)

    def line(name, seconds, mb):
        print(
            f"{name:<28} {seconds:>9.2f} {mb:>14.0f} {size_mb / seconds:>7.0f} "
            f"{rows / seconds / 1e6:>8.2f} {seconds / floor_s:>8.1f}"
        )

    line("floor (read, count \\n)", floor_s, 0)
    line("trainer fit", ours_s, ours_mb)
    line("trainer compensate", comp_s, comp_mb)
    line("pandas + scikit-learn fit", theirs_s, theirs_mb)
    line("pandas read + write", pandas_comp_s, pandas_comp_mb)
    print(f"100-s STD improvement: trainer fit {ours_pct:.1f} %, pandas + scikit-learn {theirs_pct:.1f} %")
    print(
        f"trainer fit is {theirs_s / ours_s:.1f}x faster than pandas + scikit-learn, "
        f"compensate {pandas_comp_s / comp_s:.1f}x faster than a pandas read + write"
    )
    print(f"fit peak RSS: {ours_mb:.0f} MB on this run, {short_mb:.0f} MB on one 10x shorter (ratio {ours_mb / short_mb:.2f})")
    if repeat > 0:
        print(f"{repeat} more runs each, after the runs above: median wall (range), median peak RSS (range)")
        repeated(
            "trainer fit",
            [trainer, "fit", "-q", "--force", run, "-o", model],
            os.path.join(work, "trainer.log"),
            repeat,
        )
        repeated(
            "trainer compensate",
            [trainer, "compensate", "--force", "--model", model, run, "-o", compensated],
            os.path.join(work, "compensate.log"),
            repeat,
        )
        repeated(
            "trainer fit, run 10x shorter",
            [trainer, "fit", "-q", "--force", short_run, "-o", os.path.join(work, "short.bin")],
            os.path.join(work, "short.log"),
            repeat,
        )


if __name__ == "__main__":
    main(*sys.argv[1:6])
