"""What `trainer compensate` does to a large recorded run, as a Python user
would write the I/O with pandas: read the CSV, add the three output columns
(bias_dph, rate_comp_dph, flags; the model itself left out, so this is the
I/O alone), write the CSV. Prints one line: `pandas: rows R, seconds S`.

Usage: python pandas_compensate.py RUN.csv OUT.csv
"""

import sys
import time

import pandas as pd


def main(path, out):
    started = time.perf_counter()
    df = pd.read_csv(path, comment="#")
    df["bias_dph"] = 0.0
    df["rate_comp_dph"] = df["rate_dph"] - df["bias_dph"]
    df["flags"] = 0
    df.to_csv(out, index=False)
    print(f"pandas: rows {len(df)}, seconds {time.perf_counter() - started:.2f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
