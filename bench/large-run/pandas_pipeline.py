"""The job `trainer fit` does on a large recorded run, as a Python user would
write it with pandas and scikit-learn: read the CSV, 1-s means, the IFOG
features (T, ΔT, T×ΔT), then kernel ridge regression with a small grid
search (3 widths × 3 ridge strengths, 3 contiguous folds), and the
before/after 100-s cluster STD.

Kernel ridge needs an n × n kernel matrix: on the 72,000 1-s means of a 20-h
run that is 41 GB, so, as any user would, it is fitted on every 10th 1-s
mean (7,200 points; 415 MB per kernel matrix). Prints one line:
`pandas+sklearn: rows R, seconds S, improvement P %`.

Usage: python pandas_pipeline.py RUN.csv
"""

import sys
import time

import numpy as np
import pandas as pd
from sklearn.kernel_ridge import KernelRidge
from sklearn.model_selection import GridSearchCV, TimeSeriesSplit
from sklearn.preprocessing import StandardScaler


def main(path):
    started = time.perf_counter()
    df = pd.read_csv(path, comment="#")
    rows = len(df)
    # 1-s means.
    df["second"] = np.floor(df["time_s"]).astype(np.int64)
    means = df.groupby("second", sort=True).mean()
    temp = means["temp_c"]
    # ΔT over 60 s, °C/min, and the IFOG paper's product.
    rate = temp.diff(60) / 60.0 * 60.0
    x = pd.DataFrame({"t": temp, "dt": rate, "t_dt": temp * rate}).iloc[60:]
    y = (means["rate_dph"] - means["ref_dph"]).iloc[60:]
    scaler = StandardScaler().fit(x)
    z = scaler.transform(x)
    thin = slice(None, None, 10)
    search = GridSearchCV(
        KernelRidge(kernel="rbf"),
        {"alpha": [1e-3, 1e-2, 1e-1], "gamma": [0.1, 0.5, 2.0]},
        cv=TimeSeriesSplit(n_splits=3),
        scoring="neg_mean_squared_error",
    )
    search.fit(z[thin], y.values[thin])
    bias = search.best_estimator_.predict(z)
    residual = y.values - bias
    clusters = lambda v: pd.Series(v).groupby(np.arange(len(v)) // 100).mean().std()
    improvement = (1.0 - clusters(residual) / clusters(y.values)) * 100.0
    elapsed = time.perf_counter() - started
    print(f"pandas+sklearn: rows {rows}, seconds {elapsed:.2f}, improvement {improvement:.1f} %")


if __name__ == "__main__":
    main(sys.argv[1])
