#!/usr/bin/env python
"""The run-level test's size: how often a signal that acts on nothing passes, against F and against chi-square.

Each draw makes ``N`` runs' deviations (gain, offset) with a between-run spread (normal, or Student t with three
degrees of freedom scaled to unit variance: ``--tail t3``), each run's own sampling noise (a covariance drawn
per run), loads in pairs of opposite directions, and a signal per run that acts on nothing: log-uniform over two
decades (``lin``) and its logarithm (``log``). ``l1b2.closeloop.runstats.joint_test`` gives the Wald statistic's
p-value against chi-square (the package's reference); the same statistic over its degrees of freedom read against
F(dof, runs - the mean's coefficients) gives the small-sample reference (decision 0166). Prints one line per signal
form: the share of draws with p below 0.001, 0.01 and 0.05 by each reference.

Usage: python bench/runlevel_null_size.py [--runs N] [--draws R] [--tail normal|t3] [--seed S]
"""
import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
from l1b2.closeloop import runlevel as rl  # noqa: E402
from l1b2.closeloop import runstats as rs  # noqa: E402

LEVELS = (0.001, 0.01, 0.05)


def draw(rng, n: int, tail: str):
    """One draw: the runs' deviations (``RunDeviations``) and the null signal's values per run."""
    L = np.array([[0.03, 0.0], [0.2, 0.5]])
    u = rng.standard_normal((n, 2)) if tail == "normal" else rng.standard_t(3, (n, 2)) / np.sqrt(3.0)
    s = np.diag([0.01, 0.3])
    cov = np.array([s @ s.T * rng.uniform(0.5, 2.0) for _ in range(n)])
    theta = u @ L.T + np.array([rng.multivariate_normal([0.0, 0.0], c) for c in cov])
    w = np.repeat(rng.choice([0.2, 0.5, 1.0], n // 2), 2) * np.tile([1.0, -1.0], n // 2)
    return rl.RunDeviations(np.arange(n), theta, cov, np.full(n, 500), w), np.exp(rng.uniform(0.0, np.log(100.0), n))


def f_reference(p_chi2: float, dof: int, n_runs: int, n_mean: int) -> float:
    """The p-value of the Wald statistic whose chi-square p-value (``dof`` degrees of freedom) is ``p_chi2``, read
    over ``dof`` against F(``dof``, ``n_runs - n_mean``)."""
    return float(stats.f.sf(stats.chi2.isf(p_chi2, dof) / dof, dof, n_runs - n_mean))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=56)
    ap.add_argument("--draws", type=int, default=5000)
    ap.add_argument("--tail", choices=("normal", "t3"), default="normal")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    p = {"lin": ([], []), "log": ([], [])}
    for _ in range(args.draws):
        dev, z = draw(rng, args.runs, args.tail)
        for form, v in (("lin", z), ("log", np.log(z))):
            v = (v - v.mean()) / v.std()
            _, pc, dof = rs.joint_test(dev, v)
            k = len(rs.identified_columns(rs.signal_design(v, dev.load)))     # the mean's coefficients
            p[form][0].append(f_reference(pc, dof, args.runs, k))
            p[form][1].append(pc)
    for form, (pf, pc) in p.items():
        share = [" ".join(f"{np.mean(np.array(x) < a):.4f}" for a in LEVELS) for x in (pf, pc)]
        print(f"{args.tail} {form} runs {args.runs} draws {args.draws}: share below {LEVELS}: "
              f"F {share[0]} | chi-square {share[1]}")


if __name__ == "__main__":
    main()
