"""The peers a Python user would pick: scikit-learn SVR and KernelRidge, each
with a small grid search on contiguous folds, on exactly the block-mean
features and targets `trainer fit` uses (written by `trainer blocks`).

Run by `cargo xtask bench-accuracy`, which makes the venv. Prints JSON.
"""
import argparse
import csv
import json
import time

import numpy as np
from sklearn.kernel_ridge import KernelRidge
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVR

# SVR and kernel ridge scale as n^2 .. n^3: train on every n-th block, at most this many.
MAX_TRAIN_ROWS = 3000


def load(path):
    with open(path) as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    header, data = rows[0], np.array(rows[1:], dtype=float)
    columns = [i for i, name in enumerate(header) if name.startswith("x")]
    return data[:, columns], data[:, header.index("target_dph")]


def cluster_std(values, per_cluster):
    n = len(values) // per_cluster
    means = values[: n * per_cluster].reshape(n, per_cluster).mean(axis=1)
    return float(np.std(means, ddof=1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--train", required=True)
    ap.add_argument("--verify", action="append", required=True, help="NAME=BLOCKS.csv")
    ap.add_argument("--cluster-blocks", type=int, required=True, help="blocks per 100-s cluster")
    args = ap.parse_args()
    x, y = load(args.train)
    step = max(1, len(y) // MAX_TRAIN_ROWS)
    x, y = x[::step], y[::step]
    folds = KFold(n_splits=5, shuffle=False)  # contiguous: neighbouring blocks correlate
    peers = {
        "sklearn SVR": GridSearchCV(
            make_pipeline(StandardScaler(), SVR(kernel="rbf")),
            {"svr__C": [0.1, 1.0, 10.0], "svr__gamma": ["scale", 0.1, 1.0], "svr__epsilon": [0.001, 0.01]},
            cv=folds,
            scoring="neg_mean_squared_error",
        ),
        "sklearn KernelRidge": GridSearchCV(
            make_pipeline(StandardScaler(), KernelRidge(kernel="rbf")),
            {"kernelridge__alpha": [1e-3, 1e-2, 1e-1], "kernelridge__gamma": [0.01, 0.1, 1.0]},
            cv=folds,
            scoring="neg_mean_squared_error",
        ),
    }
    out = {}
    for name, model in peers.items():
        started = time.perf_counter()
        model.fit(x, y)
        fit_s = time.perf_counter() - started
        runs = {}
        for spec in args.verify:
            label, path = spec.split("=", 1)
            xv, yv = load(path)
            before = cluster_std(yv, args.cluster_blocks)
            after = cluster_std(yv - model.predict(xv), args.cluster_blocks)
            runs[label] = {"before_dph": before, "after_dph": after, "improvement_pct": 100 * (1 - after / before)}
        out[name] = {"fit_s": fit_s, "train_rows": len(y), "runs": runs}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
