"""The response bank's identification prior, swept: how the ridge penalty's
shape over the filters' time constants carries a chamber fit to in-use
histories (docs/methods.md, "The identification"; figures in
docs/decisions.md, "Measurements behind design choices").

A numpy replica of `trainer fit`'s response-bank regression
(trainer/src/fit/response.rs): the loop temperature T, (T - T0)^2 and
(T - T0)^3 through 12 first-order derivative filters, 10 s ... 11 h (rbf-core's
filter, in degC/min), the static cubic, the rates times u_c and u_c^2, 10-s
block means after the 30-s warm-up, one ridge regression on the standardised
channels with an offset per run and the penalty on the dynamic ones. It
evaluates in f64 where the trainer's filters run in f32: the in-use scores
agree with `trainer compensate`'s to about 0.3 points. Each variant is a
penalty per dynamic channel: lambda * n * scale(tau_k).

It is run after `cargo xtask bench-accuracy --in-use ...`, whose simulated
runs it reads (`--in-use`, default target/bench-accuracy/in-use: every
`pP_trainJ.csv` with its `pP_trainJ.fit.json` and the plant's four
`pP_useK.csv`), and on the handed-out designs (`--designs`). Per variant it
prints the in-use STD100 improvement (mean over each training's histories):
each handed-out training; over the bench trainings where the default fit
took the response bank; and over every bench training with the response
bank forced.

    target/bench-accuracy/venv/bin/python bench/accuracy/response_prior.py
"""
import argparse
import glob
import json
import os
import re
from multiprocessing import Pool

import numpy as np

FILTERS = 12
FASTEST_TAU_S = 10.0
SLOWEST_TAU_S = 11 * 3600.0
BLOCK_S = 10
WARMUP_S = 30
STATIC_DEGREE = 3

# name -> (lambda, scale of a dynamic channel from its filter's tau [s])
VARIANTS = {
    "uniform, lambda 3e-4 (before)": (3e-4, lambda tau: np.ones_like(tau)),
    "uniform, lambda 1e-4": (1e-4, lambda tau: np.ones_like(tau)),
    "uniform, lambda 1e-3": (1e-3, lambda tau: np.ones_like(tau)),
    "tau^0.5, lambda 1e-4 at 600 s": (1e-4, lambda tau: (tau / 600.0) ** 0.5),
    "tau^1, lambda 1e-4 at 600 s (kept)": (1e-4, lambda tau: tau / 600.0),
    "tau^1.5, lambda 1e-4 at 600 s": (1e-4, lambda tau: (tau / 600.0) ** 1.5),
    "tau^2, lambda 1e-4 at 600 s": (1e-4, lambda tau: (tau / 600.0) ** 2),
    "tau^1, lambda 3e-5 at 600 s": (3e-5, lambda tau: tau / 600.0),
    "tau^1, lambda 3e-4 at 600 s": (3e-4, lambda tau: tau / 600.0),
}

_RUNS = {}


def load(path):
    """time_s, rate_dph, temp_c, ref_dph of a recorded-run CSV at 1 Hz."""
    if path not in _RUNS:
        with open(path) as f:
            lines = [line for line in f if not line.startswith("#")]
        header = lines[0].strip().split(",")
        data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
        cols = [header.index(c) for c in ("time_s", "rate_dph", "temp_c", "ref_dph")]
        _RUNS[path] = tuple(data[:, c] for c in cols)
    return _RUNS[path]


def taus_s():
    return np.geomspace(FASTEST_TAU_S, SLOWEST_TAU_S, FILTERS)


def filter_rates(signals, taus, dt=1.0, chunk=64):
    """Rates, per minute, of rbf-core's derivative filter S += dt*(x - S)/(tau + dt)
    of every column of `signals` (N, C) at every tau, started settled: (N, C*K).
    The recursion S[n] = a*S[n-1] + b*x[n] is solved in closed form over
    chunks of 64 samples (a^-64 stays small for the fastest filter)."""
    n, c = signals.shape
    gain = 1.0 / (taus + dt)
    a, b = 1.0 - dt * gain, dt * gain
    smoothed = np.repeat(signals[:1], len(taus), 0).T.copy()
    out = np.zeros((n, c, len(taus)))
    powers = a[None, :] ** np.arange(1, chunk + 1)[:, None]
    for start in range(1, n, chunk):
        x = signals[start : start + chunk]
        ap = powers[: len(x)]
        cum = np.cumsum(x[:, :, None] * (b[None, :] / ap)[:, None, :], 0)
        new = ap[:, None, :] * (smoothed[None] + cum)
        previous = np.concatenate([smoothed[None], new[:-1]], 0)
        out[start : start + len(x)] = 60.0 * gain[None, None, :] * (x[:, :, None] - previous)
        smoothed = new[-1]
    return out.reshape(n, c * len(taus))


class Bank:
    """The bank's structure from a training run's loop range: T0 its middle."""

    def __init__(self, temp_c):
        self.lo, self.hi = temp_c.min(), temp_c.max()
        self.ref = 0.5 * (self.lo + self.hi)
        self.taus = taus_s()

    def channels(self, temp_c):
        u = temp_c - self.ref
        uc = np.clip(temp_c, self.lo, self.hi) - self.ref
        beyond = u - uc
        powers = [u, uc * (uc + 2 * beyond), uc * uc * (uc + 3 * beyond)]
        rates = filter_rates(np.stack([temp_c, powers[1], powers[2]], 1), self.taus)
        k = len(self.taus)
        r0, h2, h3 = rates[:, :k], rates[:, k : 2 * k], rates[:, 2 * k :]
        return np.concatenate(
            [np.stack(powers, 1), r0, uc[:, None] * r0, (uc * uc)[:, None] * r0, h2, h3], 1
        )


def block_means(x, length=BLOCK_S):
    m = len(x) // length
    return x[: m * length].reshape(m, length, *x.shape[1:]).mean(1)


def fit(train_csv, lam, scale):
    """The bank and its predictor of the bias from T, fitted on one run."""
    _, rate, temp, ref = load(train_csv)
    bank = Bank(temp)
    x = block_means(bank.channels(temp)[WARMUP_S:])
    y = block_means((rate - ref)[WARMUP_S:])
    n = len(y)
    mean, sd = x.mean(0), x.std(0)
    sd[sd == 0] = 1.0
    z = np.concatenate([np.ones((n, 1)), (x - mean) / sd], 1)
    penalty = np.zeros(z.shape[1])
    penalty[1 + STATIC_DEGREE :] = lam * n * np.tile(scale(bank.taus), 5)
    beta = np.linalg.solve(z.T @ z + np.diag(penalty), z.T @ y)
    w = beta[1:] / sd
    c = beta[0] - w @ mean
    return lambda t: bank.channels(t) @ w + c


def std100(e):
    m = len(e) // 100
    return e[: m * 100].reshape(m, 100).mean(1).std()


def improvement_pct(predict, use_csv):
    _, rate, temp, ref = load(use_csv)
    return 100.0 * (1.0 - std100(rate - predict(temp) - ref) / std100(rate - ref))


def score(job):
    variant, train, uses = job
    lam, scale = VARIANTS[variant]
    predict = fit(train, lam, scale)
    return float(np.mean([improvement_pct(predict, u) for u in uses]))


def trainings(in_use_dir, designs_dir):
    """(name, training run, in-use runs, default took the response bank)."""
    out = []
    for design in sorted(glob.glob(os.path.join(designs_dir, "*_planned.csv"))):
        stem = design[: -len("_planned.csv")]
        uses = [stem + "_random.csv", stem + "_field.csv"]
        for kind in ("planned", "cycle"):
            out.append((f"{os.path.basename(stem)} {kind}", f"{stem}_{kind}.csv", uses, None))
    names = (os.path.basename(f) for f in glob.glob(os.path.join(in_use_dir, "p*_train*.csv")))
    for name in sorted(n for n in names if re.fullmatch(r"p\d+_train\d+\.csv", n)):
        train = os.path.join(in_use_dir, name)
        plant, tag = name[: -len(".csv")].split("_")
        with open(train[: -len(".csv")] + ".fit.json") as f:
            taken = json.load(f)["structure"]["response_bank"]
        uses = sorted(glob.glob(os.path.join(in_use_dir, f"{plant}_use[0-9]*.csv")))
        uses = [u for u in uses if re.fullmatch(rf"{plant}_use\d+\.csv", os.path.basename(u))]
        out.append((f"{plant} {tag}", train, uses, taken))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--in-use", default="target/bench-accuracy/in-use")
    p.add_argument("--designs", default="../shared/data/other-designs")
    p.add_argument("--variant", action="append", choices=list(VARIANTS), help="default: every variant")
    args = p.parse_args()
    runs = trainings(args.in_use, args.designs)
    handed = [r for r in runs if r[3] is None]
    taken = [r for r in runs if r[3]]
    bench = [r for r in runs if r[3] is not None]
    print(
        "in-use STD100 improvement, mean over each training's histories [%]: "
        f"handed-out trainings ({', '.join(r[0] for r in handed)}); "
        f"bench trainings where the default took the response bank ({len(taken)}): mean, worst; "
        f"every bench training ({len(bench)}) with the response bank forced: mean"
    )
    with Pool(2) as pool:
        for variant in args.variant or list(VARIANTS):
            scores = dict(zip((r[0] for r in runs), pool.map(score, [(variant, r[1], r[2]) for r in runs])))
            h = " ".join(f"{scores[r[0]]:5.1f}" for r in handed)
            t = [scores[r[0]] for r in taken]
            b = [scores[r[0]] for r in bench]
            t_text = f"{np.mean(t):5.1f} {min(t):5.1f}" if t else "    -     -"
            print(f"{variant:38s} {h}   {t_text}   {np.mean(b):5.1f}", flush=True)


if __name__ == "__main__":
    main()
