"""The soak test against the response bank's identification: which training
runs give a model whose settled bias is flat across the range, and whether
one model can fit a gyro's long-hold and its dynamic runs at once
(issue 48; findings in docs/decisions.md, "The settled curve after a planned run").

A numpy replica of `trainer fit`'s response-bank regression (imported from
response_prior.py beside this file: same filters, blocks, standardisation and
prior), fitted on one or several of a handed-out design's runs with an offset
per run, then scored as `cargo xtask bench-designs` scores:

- in use: the 100-s cluster STD improvement on `<design>_random.csv` and
  `<design>_field.csv`, %;
- soak: the settled spread on `<design>_soak.csv`, °/h, by trainer's plateau
  rule (trainer/src/dataset/plateaus.rs and docs/workflow.md, "The soak
  test": 60-s means of the loop temperature, steady where it moved at most
  1.5 °C over 10 min, the hold's end 1 min before the loop begins departing
  from its line; the residual's mean over the last 30 min of each; spread = max - min);
- the training residual's STD of 100-s means per run, °/h: each run alone
  fits to its noise (about 0.006 °/h); a combination that cannot is one the
  model class cannot represent.

    python3 bench/accuracy/soak_identification.py [--designs DIR] [--combo planned+planned24 ...]
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import response_prior as rp  # noqa: E402

STEADY_SPAN_MIN = 10
STEADY_MOVE_C = 1.5
DEPARTURE_C = 0.015
ONSET_C = 0.003
DEPARTURE_GROWTH = 2.0
DEPARTURE_GROWTH_MIN = 5
DEPARTURE_MARGIN_MIN = 1
UNSEEN_DEPARTURE_MIN = 15
MIN_STEADY_MIN = 30
WINDOW_MIN = 30


def settled_biases(time_s, temp_c, residual_dph):
    """(loop temperature degC, settled bias deg/h) per plateau, by trainer's rule
    (trainer/src/dataset/plateaus.rs; one run at 1 Hz or faster, no gaps)."""
    block = ((time_s - time_s[0]) // 60.0).astype(int)
    temp = np.bincount(block, temp_c) / np.maximum(np.bincount(block), 1)
    n, span = len(temp), STEADY_SPAN_MIN
    steady = np.zeros(n, bool)
    steady[span:] = np.abs(temp[span:] - temp[:-span]) <= STEADY_MOVE_C
    off = np.full(n, np.nan)
    for k in range(span + 1, n):
        off[k] = abs(temp[k] - (temp[k - 1] + (temp[k - 1] - temp[k - 1 - span]) / span))
    out, i = [], 0
    while i < n:
        if not steady[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and steady[j + 1]:
            j += 1
        departure = None
        for k in range(i + span + 1 + DEPARTURE_GROWTH_MIN, min(j + span, n - 1) + 1):
            least = off[k - DEPARTURE_GROWTH_MIN : k].min()
            if off[k] > DEPARTURE_C and off[k] > DEPARTURE_GROWTH * least:
                departure = k
                break
        if departure is not None:
            onset = departure
            while (onset - 1 > i and onset > departure - span and off[onset - 1] > ONSET_C
                   and off[onset - 1] < off[onset]):
                onset -= 1
            end = onset - 1 - DEPARTURE_MARGIN_MIN
        else:
            end = j - UNSEEN_DEPARTURE_MIN if j + 1 < n else j
        if end - i + 1 >= MIN_STEADY_MIN:
            window = (block > end - WINDOW_MIN) & (block <= end)
            out.append((temp_c[window].mean(), residual_dph[window].mean()))
        i = (departure if departure is not None else j) + 1
    return out


def fit(paths, lam=rp.VARIANTS["tau^1, lambda 1e-4 at 600 s (kept)"][0]):
    """The bank fitted on `paths` together (an offset per run); its predictor and per-run training STD100."""
    runs = [rp.load(p) for p in paths]
    bank = rp.Bank(np.concatenate([r[2] for r in runs]))
    xs, ys, which = [], [], []
    for i, (_, rate, temp, ref) in enumerate(runs):
        xs.append(rp.block_means(bank.channels(temp)[rp.WARMUP_S :]))
        ys.append(rp.block_means((rate - ref)[rp.WARMUP_S :]))
        which.append(np.full(len(ys[-1]), i))
    x, y, run = np.concatenate(xs), np.concatenate(ys), np.concatenate(which)
    n, k = len(y), len(runs)
    mean, sd = x.mean(0), x.std(0)
    sd[sd == 0] = 1.0
    offsets = np.zeros((n, k))
    offsets[np.arange(n), run] = 1.0
    z = np.concatenate([offsets, (x - mean) / sd], 1)
    penalty = np.zeros(z.shape[1])
    penalty[k + rp.STATIC_DEGREE :] = lam * n * np.tile(bank.taus / 600.0, 5)
    beta = np.linalg.solve(z.T @ z + np.diag(penalty), z.T @ y)
    w = beta[k:] / sd
    c = beta[0] - w @ mean
    residual = y - z @ beta
    per_100_s = 100 // rp.BLOCK_S
    train_std100 = [np.std(rp.block_means(residual[run == i], per_100_s)) for i in range(k)]
    return (lambda temp: bank.channels(temp) @ w + c), train_std100


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--designs", default="../shared/data/other-designs")
    p.add_argument("--design", action="append", help="default: design4, design5")
    p.add_argument(
        "--combo",
        action="append",
        help="runs fitted together, '+'-joined (default: planned, planned24, cycle, planned+planned24, planned+random, soak+random)",
    )
    args = p.parse_args()
    combos = args.combo or ["planned", "planned24", "cycle", "planned+planned24", "planned+random", "soak+random"]
    print("design   trained on               random  field   soak °/h   training STD100 per run °/h")
    for design in args.design or ["design4", "design5"]:
        run = lambda kind: os.path.join(args.designs, f"{design}_{kind}.csv")  # noqa: E731
        for combo in combos:
            predict, train_std100 = fit([run(k) for k in combo.split("+")])
            use = [rp.improvement_pct(predict, run(k)) for k in ("random", "field")]
            t, rate, temp, ref = rp.load(run("soak"))
            settled = [b for _, b in settled_biases(t, temp, rate - ref - predict(temp))]
            spread = max(settled) - min(settled)
            stds = " ".join(f"{s:.4f}" for s in train_std100)
            print(f"{design}  {combo:22s}  {use[0]:5.1f}  {use[1]:5.1f}   {spread:.4f}     {stds}", flush=True)


if __name__ == "__main__":
    main()
