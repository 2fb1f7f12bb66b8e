"""A soak test as training data: the default fit on the planned run alone against the
planned run and a soak test of the same unit together, and against the floor: every run of
the unit, the judged soak among them (issue 48; findings in docs/workflow.md, "The soak
test", and docs/decisions.md, "Two soak tests on the bench" and "What a fit can reach on a
soak at all").

For each plant of `cargo xtask bench-accuracy --in-use --designs 16` (the documented gyro,
`--unit 1`, `--unit 2`, the other design of bench/accuracy/other-design.json,
`--design 1` ... `--design 16`) and each plan length (`trainer plan --min-c -40 --max-c 60
--max-rate-c-per-min 5 --hours H --seed 1`), it simulates the planned run, soak test A
(issue 48's: 3-h holds at 25, 0, 40, -20, 60, 20, -40, 10 degC) and soak test B (10, -40,
50, -10, 30, 60, -30, 0 degC), a random and a field history, and fits `trainer fit` on
the planned run alone, on the planned run with soak A, and on every run (the planned run,
both soaks and both histories). Each model is judged on soak B (`trainer eval --json`'s
`settled_spread_dph`) and on the mean 100-s cluster STD improvement of the two histories.
The first two never saw soak B or the histories; the third saw them all, so its figures
are the floor: what the default model leaves on runs it was fitted on, their noise
included. A plant whose floor misses a target misses it by the model's structure, not by
what a plan could identify.

    python3 bench/accuracy/soak_as_training.py [--trainer target/release/trainer]
        [--dir target/soak-as-training] [--hours 12,24] [--plants doc,unit1,design6]

Runs are simulated once per directory and reused (a planned run per set of set points);
fits and evaluations are redone.
"""
import argparse
import json
import math
import os
import subprocess
from concurrent.futures import ThreadPoolExecutor

from one_unit_soak import FIELD_HISTORY, RANDOM_HISTORY, plan_run, set_points_digest

PLANTS = {"doc": [], "unit1": ["--unit", "1"], "unit2": ["--unit", "2"],
          "other": ["--params", os.path.join(os.path.dirname(os.path.abspath(__file__)), "other-design.json")]}
PLANTS.update({f"design{d}": ["--design", str(d)] for d in range(1, 17)})
# name: (trainer simulate arguments, seed)
RUNS = {
    "soakA": (["--profile", "soak"], 515),
    "soakB": (["--profile", "soak", "--soak-levels-c", "10,-40,50,-10,30,60,-30,0"], 516),
    "random": (RANDOM_HISTORY, 511),
    "field": (FIELD_HISTORY, 513),
}


# Each fit's label and the runs it is fitted on beside the planned run.
BESIDE = {"alone": [], "with soak A": ["soakA"], "every run": ["soakA", "soakB", "random", "field"]}


def run(cmd):
    subprocess.run(cmd, check=True, capture_output=True, text=True)


def simulated(args, plant, name, sim_args, seed):
    out = os.path.join(args.dir, f"{plant}_{name}.csv")
    if not os.path.exists(out):
        run([args.trainer, "simulate", *PLANTS[plant], *sim_args, "--seed", str(seed), "-o", out, "--force"])
    return out


def evaluated(args, model, data):
    out = f"{model}.{os.path.basename(data)}.json"
    run([args.trainer, "eval", "--model", model, data, "--json", out, "--force"])
    return json.load(open(out))[0]


def one(args, plant, hours):
    plan = os.path.join(args.dir, f"plan{hours}.csv")
    train = simulated(args, plant, f"planned{hours}_{set_points_digest(plan)}", ["--chamber-profile", plan], 503)
    runs = {name: simulated(args, plant, name, a, s) for name, (a, s) in RUNS.items()}
    scores = {}
    for label, beside in BESIDE.items():
        extra = [runs[name] for name in beside]
        model = os.path.join(args.dir, f"{plant}_{hours}h_{label.replace(' ', '_')}.bin")
        run([args.trainer, "fit", train, *extra, "-o", model, "--force", "--json", model + ".fit.json"])
        forecast = json.load(open(model + ".fit.json"))["predicted_settled_spread_dph"]
        soak = evaluated(args, model, runs["soakB"])["settled_spread_dph"]
        use = [evaluated(args, model, runs[h])["cluster_std_improvement_pct"] for h in ("random", "field")]
        scores[label] = (soak, sum(use) / len(use), forecast)
    return plant, hours, scores


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trainer", default="target/release/trainer")
    p.add_argument("--dir", default="target/soak-as-training")
    p.add_argument("--hours", default="12,24")
    p.add_argument("--plants", default=",".join(PLANTS))
    args = p.parse_args()
    os.makedirs(args.dir, exist_ok=True)
    hours = [int(h) for h in args.hours.split(",")]
    plants = args.plants.split(",")
    for h in hours:
        plan_run(args.trainer, h, os.path.join(args.dir, f"plan{h}.csv"), ["--seed", "1"])
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda job: one(args, *job), [(pl, h) for h in hours for pl in plants]))
    labels = list(BESIDE)
    print("soak B settled spread [deg/h] / in-use mean [%], trained on the planned run " + " | ".join(labels))
    for plant, h, s in results:
        print(f"{plant:9s} {h:2d} h  " + "  |  ".join(f"{s[label][0]:.4f} / {s[label][1]:.1f}" for label in labels))
    for h in hours:
        for label in labels:
            v = [s[label] for plant, hh, s in results if hh == h]
            spreads = [x[0] if x[0] is not None else float("inf") for x in v]
            geo = math.exp(sum(math.log(x) for x in spreads) / len(spreads))
            print(f"{h} h plan {label:11s}: soak B geometric mean {geo:.4f} deg/h, "
                  f"within 0.01 / 0.03: {sum(x <= 0.01 for x in spreads)} / {sum(x <= 0.03 for x in spreads)} "
                  f"of {len(v)}; in use mean {sum(x[1] for x in v) / len(v):.2f} %, worst {min(x[1] for x in v):.1f} %")
    # The fit's predicted_settled_spread_dph (where its runs settle in every 20-degC band) against soak B,
    # on the fits that did not see soak B.
    unseen = [label for label, beside in BESIDE.items() if "soakB" not in beside]
    forecasts = [s[label] for _, _, s in results for label in unseen if s[label][2] is not None]
    within = sum(1 for soak, _, f in forecasts if soak is not None and soak / 1.5 <= f <= soak * 1.5)
    print(f"predicted_settled_spread_dph given on {len(forecasts)} of {len(unseen) * len(results)} fits, "
          f"within 1.5x of soak B on {within}")


if __name__ == "__main__":
    main()
