"""The "lag-bank reference" of `cargo xtask bench-accuracy`'s in-use section:
what a competent user writes with numpy when a thermal model is wanted fast.

Plain least squares of the bias (rate_dph - ref_dph, every sample) on the
loop temperature T (temp_c) passed through first-order derivative filters at
five log-spaced time constants, 30 s ... 2 h (the rate of change of T seen at
that time scale: (T - first-order lag of T) / tau, in degC/min), each with its
products by T and T^2, plus a cubic in T. Filters start settled at the first
sample (the run starts at power-on).

Fitted on the --train runs, it writes its bias estimate for each --verify run
(`RUN.csv=BIAS.csv`: columns time_s,bias_dph), which the bench scores exactly
as it scores `trainer compensate`'s output. Prints the fit's size as JSON.
"""
import argparse
import json

import numpy as np

TAUS_S = np.geomspace(30.0, 7200.0, 5)
# T enters as u = (T - 25 degC) / 30 degC, so that the columns are of order 1.
T_REF_C = 25.0
T_SCALE_C = 30.0


def load(path):
    with open(path) as f:
        lines = [line for line in f if not line.startswith("#")]
    header = lines[0].strip().split(",")
    data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def rate_at(time_s, temp_c, tau_s):
    """dT/dt seen through a first-order filter of time constant tau_s, degC/min."""
    alpha = 1.0 - np.exp(-np.diff(time_s, prepend=time_s[0]) / tau_s)
    lag = np.empty_like(temp_c)
    state = temp_c[0]
    for i, (a, t) in enumerate(zip(alpha, temp_c)):
        state += a * (t - state)
        lag[i] = state
    return (temp_c - lag) / tau_s * 60.0


def design(run):
    u = (run["temp_c"] - T_REF_C) / T_SCALE_C
    columns = [np.ones_like(u), u, u**2, u**3]
    for tau_s in TAUS_S:
        rate = rate_at(run["time_s"], run["temp_c"], tau_s)
        columns += [rate, rate * u, rate * u**2]
    return np.column_stack(columns)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--train", action="append", required=True, help="RUN.csv")
    ap.add_argument("--verify", action="append", required=True, help="RUN.csv=BIAS.csv")
    args = ap.parse_args()
    runs = [load(path) for path in args.train]
    x = np.vstack([design(run) for run in runs])
    y = np.concatenate([run["rate_dph"] - run["ref_dph"] for run in runs])
    weights, _, rank, _ = np.linalg.lstsq(x, y, rcond=None)
    for spec in args.verify:
        run_path, out_path = spec.split("=", 1)
        run = load(run_path)
        bias = design(run) @ weights
        np.savetxt(out_path, np.column_stack([run["time_s"], bias]), delimiter=",",
                   header="time_s,bias_dph", comments="", fmt="%.6f")
    print(json.dumps({"train_rows": len(y), "columns": x.shape[1], "rank": int(rank)}))


if __name__ == "__main__":
    main()
