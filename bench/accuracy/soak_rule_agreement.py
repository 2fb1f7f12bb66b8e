"""`trainer eval`'s settled spread against the chamber's clock (issue 48: "eval's
settled_spread_dph agreeing with an independent computation").

For each gyro and each soak test (ten level orders, from 5-degC to 100-degC steps; holds
of `--holds-h`; ramps of `--ramps-c-per-min`), it simulates the soak with `trainer simulate
--profile soak`, compensates it with that gyro's model (`trainer compensate`) and reads:

- eval's figure: `settled_spread_dph` of `trainer eval --json` (the plateau rule of
  trainer/src/dataset/plateaus.rs, which sees only the loop temperature);
- the chamber clock's: the compensated residual's mean over the last 30 min of each hold
  by the profile's timing (hold, then |step| / ramp rate, then hold ...), max - min.

It prints both per test, how many holds eval found, and how many tests agree within 2, 5
and 10 %. The models are the 24-h plan's of `one_unit_soak.py` (run it first with
`--hours 24` and the same `--dir`; the fast twins' parameters are read from there too).

    python3 bench/accuracy/one_unit_soak.py --hours 24 --gyros doc,unit1,design1,fast-doc,fast-design3
    python3 bench/accuracy/soak_rule_agreement.py [--gyros doc,unit1,...] [--holds-h 2,3,4]
        [--ramps-c-per-min 0.5,1,2,5] [--dir target/one-unit-soak]
"""
import argparse
import itertools
import json
import os
import subprocess
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from one_unit_soak import GYROS

ORDERS = {
    "mixed": [-30, 50, -10, 30, 10, 60, -40],
    "up": [-40, -20, 0, 20, 40, 60],
    "few": [60, -40, 25, 5],
    "alt": [60, -40, 50, -30, 40, -20, 30, -10],
    "rev": [10, -40, 20, 60, -20, 40, 0, 25],
    "close": [20, 25, 15, 30, 10, 35, 5],
    "step10": [-40, -30, -20, -10, 0, 10, 20, 30, 40, 50, 60],
    "step15": [60, 45, 30, 15, 0, -15, -30],
    "step20": [-40, -20, 0, 20, 40, 60],
    "zig10": [0, 10, -10, 20, -20, 30],
}
WINDOW_S = 1800.0


def gyro_args(name, d):
    if name.startswith("fast-"):
        return ["--params", os.path.join(d, f"{name}.json")]
    return GYROS[name]


def hold_ends_s(levels, hold_s, ramp_c_per_min):
    ends = [hold_s]
    for a, b in zip(levels, levels[1:]):
        ends.append(ends[-1] + abs(b - a) / ramp_c_per_min * 60.0 + hold_s)
    return ends


def compensated(path):
    with open(path) as f:
        lines = [line for line in f if not line.startswith("#")]
    header = lines[0].strip().split(",")
    data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    column = {name: data[:, header.index(name)] for name in ("time_s", "rate_comp_dph", "ref_dph")}
    return column["time_s"], column["rate_comp_dph"] - column["ref_dph"]


def one_test(trainer, d, gyro, order, hold_h, ramp):
    levels = ORDERS[order]
    out = os.path.join(d, "rule-agreement")
    os.makedirs(out, exist_ok=True)
    stem = os.path.join(out, f"{gyro}_{order}_{hold_h}h_{ramp}cpm")
    model = os.path.join(d, gyro, "planned24.bin")
    run = stem + ".csv"
    if not os.path.exists(run):
        subprocess.run([trainer, "simulate", "--sample-rate-hz", "1", *gyro_args(gyro, d), "--profile", "soak",
                        "--soak-levels-c", ",".join(map(str, levels)), "--soak-hold-h", str(hold_h),
                        "--ramp-c-per-min", str(ramp), "--seed", "7", "-o", run, "--force"],
                       check=True, capture_output=True)
    subprocess.run([trainer, "compensate", "--model", model, "--output", stem + ".comp.csv", run, "--force"],
                   check=True, capture_output=True)
    subprocess.run([trainer, "eval", "--model", model, run, "--json", stem + ".json", "--force"],
                   check=True, capture_output=True)
    e = json.load(open(stem + ".json"))[0]
    t, residual = compensated(stem + ".comp.csv")
    biases = [residual[(t >= end - WINDOW_S) & (t < end)].mean()
              for end in hold_ends_s(levels, hold_h * 3600.0, ramp)]
    return os.path.basename(stem), len(levels), len(e["plateaus"]), max(biases) - min(biases), e["settled_spread_dph"]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trainer", default="target/release/trainer")
    p.add_argument("--dir", default="target/one-unit-soak")
    p.add_argument("--gyros", default="doc,unit1,design1,fast-doc,fast-design3")
    p.add_argument("--holds-h", default="2,3,4")
    p.add_argument("--ramps-c-per-min", default="0.5,1,2,5")
    a = p.parse_args()
    tests = itertools.product(a.gyros.split(","), ORDERS, [float(h) for h in a.holds_h.split(",")],
                              [float(r) for r in a.ramps_c_per_min.split(",")])
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        results = list(pool.map(lambda c: one_test(a.trainer, a.dir, *c), tests))
    print("test                                holds found   chamber clock   eval [deg/h]   eval / clock")
    ratios = []
    for name, holds, found, clock, ours in results:
        ratio = ours / clock if ours is not None and clock > 0 else float("nan")
        ratios.append(ratio)
        shown = "null" if ours is None else f"{ours:.5f}"
        print(f"{name:36s} {holds:5d} {found:5d}   {clock:13.5f}   {shown:>12s}   {ratio:12.3f}")
    off = np.abs(np.log(np.array(ratios)))
    every = sum(h == f for _, h, f, _, _ in results)
    print(f"{len(results)} tests, every hold found in {every}; eval within 2 / 5 / 10 % of the chamber clock: "
          f"{(off < np.log(1.02)).sum()} / {(off < np.log(1.05)).sum()} / {(off < np.log(1.10)).sum()}")


if __name__ == "__main__":
    main()
