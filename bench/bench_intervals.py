"""How well ``fit(intervals=True)``'s chi-square intervals describe the spread of refits.

    PYTHONPATH=python python bench/bench_intervals.py [--fits 20] [--runs-per-trial 2]
        [--budget 40] [--workers 2]

The problem is the tests' recovery scene (``tests/python/test_tune.py``'s
``recovery_scenario``: 48 x 36 px, 0.4 s, hidden theta_on 0.3 and theta_off 0.2). Each fit
gets its own "real" recording (engine seed 100 + i) and its own simulation seeds
(1000 (i + 1) ...), starts at theta_on 0.31, theta_off 0.21 and fits both with the default
``ls`` sampler and --budget trials of --runs-per-trial seeds. Prints each fit's values and
intervals, then per parameter: the standard deviation of the fitted values over the fits,
their mean, the root mean square of the reported half-widths (one standard error each), and
how many intervals hold the hidden value.

Beside each fit it also takes the estimator the standard errors describe: the least-squares
estimate of the chi-square's linear model at the hidden values, with that fit's recording and
seeds (one Gauss-Newton step, slopes from +- ``CHI2_INTERVAL_STEP`` of each bound: 4 + 1 points of
--runs-per-trial runs, in this process), and prints the spread of those too: what separates
it from the fits' spread is the search's own error (where a budgeted search on a seed-noisy
distance stops) and the model's curvature. No asserts.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from evstwin import tune
from evstwin.simulate import simulate
from evstwin.tune.counts import chi2_gauss_newton_step
from evstwin.tune.intervals import CHI2_INTERVAL_STEP
from evstwin.tune.search import _Scaler

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "python"))
from test_tune import recovery_scenario  # noqa: E402  (the tests' problem, defined once)

HIDDEN = {"pixel.theta_on": 0.3, "pixel.theta_off": 0.2}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fits", type=int, default=20)
    ap.add_argument("--runs-per-trial", type=int, default=2)
    ap.add_argument("--budget", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    keys = list(HIDDEN)
    scaler = _Scaler(keys, tune.FIT_BOUNDS)
    u_hidden = scaler.to_unit(HIDDEN)
    values, halves, held, linear = [], [], np.zeros(len(keys), int), []
    t0 = time.perf_counter()
    for i in range(args.fits):
        real = simulate(recovery_scenario(0.3, 0.2, 2000.0), seed=100 + i, num_threads=1)
        # The counts' chi-square (what this bench calibrated; its slopes below are the counts').
        opts = tune.FitOptions(params=["theta_on", "theta_off"], budget=args.budget, runs_per_trial=args.runs_per_trial,
                               seed=1000 * (i + 1), intervals=True, statistics="counts")
        r = tune.fit(real.events, real.meta, recovery_scenario(0.31, 0.21, 2000.0), opts, workers=args.workers)
        values.append([r.best_params[k] for k in keys])
        halves.append([(r.intervals[k][1] - r.intervals[k][0]) / 2.0 for k in keys])
        held += [r.intervals[k][0] <= HIDDEN[k] <= r.intervals[k][1] for k in keys]
        counts = tune.CountsObjective(real.events, real.meta, recovery_scenario(0.3, 0.2, 2000.0))
        base = recovery_scenario(0.3, 0.2, 2000.0)

        def mean_stats(u: np.ndarray) -> np.ndarray:
            return np.mean([tune.evaluate(base, scaler.from_unit(u), s, counts)["stats"] for s in r.sim_seeds], axis=0)

        h = CHI2_INTERVAL_STEP
        slopes = np.column_stack([(mean_stats(u_hidden + h * e) - mean_stats(u_hidden - h * e)) / (2.0 * h)
                                  for e in np.eye(len(keys))])
        step = chi2_gauss_newton_step(counts.real_stats, mean_stats(u_hidden), slopes, args.runs_per_trial)
        linear.append([scaler.from_unit(u_hidden + step)[k] for k in keys])
        print(f"fit {i}: " + ", ".join(f"{k} {r.best_params[k]:.5f} in {r.intervals[k][0]:.5f}..{r.intervals[k][1]:.5f}"
                                       for k in keys) + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    v, h, lin = np.array(values), np.array(halves), np.array(linear)
    for j, k in enumerate(keys):
        print(f"{k}: hidden {HIDDEN[k]}, fits' mean {v[:, j].mean():.5f}, fits' sd {v[:, j].std(ddof=1):.5f}, "
              f"rms half-width {np.sqrt(np.mean(h[:, j] ** 2)):.5f} "
              f"(ratio {v[:, j].std(ddof=1) / np.sqrt(np.mean(h[:, j] ** 2)):.2f}), "
              f"{held[j]} of {args.fits} intervals hold the hidden value; least-squares estimates' sd "
              f"{lin[:, j].std(ddof=1):.5f}, mean {lin[:, j].mean():.5f}")


if __name__ == "__main__":
    main()
