#!/usr/bin/env python
"""Benchmark: the cost of ``identify`` per evaluation, an older tree of the package and this one side by side.

For every world of ``bench_identify_worlds.py`` (about 19.7k TRAIN samples, the same cached data) and each
solver (``joint``, the default and the close loop's, and ``offset_bracket``), the fit is run by the code of a
git revision (``--old``, default ``main``; its package unpacked by ``git archive`` into a temporary folder) and
by this tree (or the revision ``--new``), each in a fresh subprocess, alternately (``--repeat`` times). Each
subprocess loads the data and compiles the numba kernels by a short fit first, then times one fit with
``time.process_time`` (CPU of that process). Printed per world and solver: CPU per identification (median of
the repeats and the spread), evaluations, log-likelihood and its gap to the world's strict reference (decision
0045, read from the cache of ``bench_identify_worlds.py``; ``nan`` when it has not been made), for the old and
the new code, and the ratio of the CPU medians. Faster evaluations that keep the path must not change it: the
evaluations and the log-likelihood of old and new are printed next to each other (``same``: equal evaluations
and log-likelihood within 1e-6 relative); a change of path is judged by the two gaps.

Usage: python bench/bench_identify_cost.py [--old main] [--new REV] [--worlds realistic/s0,...]
                                           [--solvers joint,offset_bracket] [--repeat 1] [--cache DIR]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
SOLVERS = ("joint", "offset_bracket")


def child(src: str, data: str, solver: str) -> None:
    """One timed fit by the package under ``src`` (run in its own process): prints a JSON line."""
    sys.path.insert(0, src)
    import time

    from l1b2.ident.estimator import PredictorIdentifier
    from l1b2.workflows import load_train_test

    train, _, _ = load_train_test(Path(data) / "train.csv", Path(data) / "test.csv")
    PredictorIdentifier(solver=solver, max_nfev=3).fit(train)  # the kernels compiled (or loaded) first
    est = PredictorIdentifier(solver=solver)
    c0 = time.process_time()
    est.fit(train)
    cpu = time.process_time() - c0
    import l1b2

    print(json.dumps({"cpu_s": cpu, "nfev": int(est.convergence_["nfev_total"]), "loglik": float(est.loglik_),
                      "n": len(train.df), "package": str(Path(l1b2.__file__).parent),
                      "stages": {st["stage"]: st.get("cpu_s") for st in est.convergence_.get("stages", [])},
                      "pieces": pieces(train, est)}))


def pieces(train, est, repeat=15) -> dict:
    """CPU [ms] of one call of the evaluation's pieces at the fitted vector (the minimum over ``repeat`` calls,
    the cache of the last evaluation emptied before each): the whitened residual, the whole Jacobian (row-major),
    the Jacobian of the linear parameters (column-major, as the variable projection takes it)."""
    import time

    import numpy as np

    from l1b2.ident.noise import NoiseModel
    from l1b2.ident.problem import ParameterSpace, SampleData, ScaledObjective, param_scale
    from l1b2.ident.slipproblem import make_problem
    from l1b2.ident.varpro import linear_positions

    sample = SampleData(train)
    space = ParameterSpace(est.order, None, est.fixed)
    s_center, s_half = sample.position_scaling()
    theta = np.asarray(est.result_.values, float)
    problem = make_problem("eq29", sample, est.order, est.kappa, est.include_load_inertia, "free_run", s_center,
                           s_half, 0.1 if train.slider_mass_kg is None else train.slider_mass_kg)
    obj = ScaledObjective(problem, NoiseModel(problem.run_sel, sample.layout.R, "common"), theta, space.varied,
                          param_scale(theta, est.order), space.lo, space.hi, True)
    z = obj.z_of(theta)
    obj.update_noise(obj.theta_of(z))
    lin = linear_positions(obj, space.p_theta, est.order + 1)
    if "order" in ScaledObjective.jac_columns.__code__.co_varnames:  # (the old tree: a Fortran copy)
        def jac_f():
            return obj.jac_columns(z, lin, order="F")
    else:
        def jac_f():
            return np.asfortranarray(obj.jac_columns(z, lin))
    out = {}
    for name, f in (("residual", lambda: obj.fun(z)), ("jacobian", lambda: obj.jac(z)), ("linear columns", jac_f)):
        best = float("inf")
        for _ in range(repeat):
            problem.reset_cache()
            c0 = time.process_time()
            f()
            best = min(best, time.process_time() - c0)
        out[name] = 1e3 * best
    return out


def run(src: Path, data: Path, solver: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--child", str(src), str(data), solver], env=env, check=True,
                         capture_output=True, text=True).stdout
    res = json.loads(out.strip().splitlines()[-1])
    if Path(res["package"]).resolve() != (src / "l1b2").resolve():
        raise RuntimeError(f"the subprocess imported {res['package']}, not the package under {src}")
    return res


def unpack(rev: str, into: Path) -> Path:
    """The package of git revision ``rev`` unpacked under ``into``; returns its ``fmu_src``."""
    into.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "fmu_src"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into / "fmu_src"


def best_reference(cache: Path, world: str) -> float:
    from bench_identify_worlds import reference_names
    path = cache / f"reference_{world.replace('/', '_')}.json"
    if not path.exists():
        return float("nan")
    ref = json.loads(path.read_text())
    return max(ref[k]["loglik"] for k in reference_names(ref))


def main(argv=None):
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        return child(*sys.argv[2:5])
    sys.path.insert(0, str(ROOT / "bench"))  # (the worlds' bench puts this tree's package first: not in a child)
    from bench_identify_worlds import WORLDS, dataset
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", default="main", help="git revision of the old code")
    ap.add_argument("--new", default="", help="git revision of the new code (default: this working tree)")
    ap.add_argument("--worlds", default=",".join(WORLDS))
    ap.add_argument("--solvers", default=",".join(SOLVERS))
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                         / "l1b2" / "bench"))
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        srcs = {"old": unpack(args.old, Path(tmp) / "old"),
                "new": unpack(args.new, Path(tmp) / "new") if args.new else ROOT / "fmu_src"}
        for world in args.worlds.split(","):
            data = dataset(cache, world)
            best = best_reference(cache, world)
            for solver in args.solvers.split(","):
                res = {"old": [], "new": []}
                for _ in range(args.repeat):
                    for which in ("old", "new"):
                        r = run(srcs[which], data, solver)
                        res[which].append(r)
                        print(f"{world} {solver} {which}: {r['cpu_s']:.2f} s CPU, {r['nfev']} evaluations, "
                              f"loglik {r['loglik']:.6f}; stages (CPU s): "
                              + ", ".join(f"{k} {v:.2f}" for k, v in r["stages"].items() if v is not None)
                              + "; one call (CPU ms): " + ", ".join(f"{k} {v:.2f}" for k, v in r["pieces"].items()),
                              flush=True)
                rows.append((world, solver, res, best))
    print(f"\nold = {args.old}, new = {args.new or 'this tree'}; CPU [s]: median (min-max) of {args.repeat} "
          "run(s) each\n")
    print(f"{'world':>13} {'samples':>7} {'solver':>15} {'CPU old':>16} {'CPU new':>16} {'new/old':>7} "
          f"{'nfev old/new':>12} {'loglik old':>13} {'loglik new':>13} {'- ref (old)':>11} {'- ref (new)':>11} "
          f"{'path':>5}")
    for world, solver, res, best in rows:
        o, n = res["old"][-1], res["new"][-1]

        def cpu(rs):
            c = [r["cpu_s"] for r in rs]
            return statistics.median(c), f"{statistics.median(c):.2f} ({min(c):.2f}-{max(c):.2f})"
        (mo, so), (mn, sn) = cpu(res["old"]), cpu(res["new"])
        same = all(a["nfev"] == b["nfev"] and abs(a["loglik"] - b["loglik"]) <= 1e-6 * abs(a["loglik"])
                   for a, b in zip(res["old"], res["new"]))
        print(f"{world:>13} {n['n']:7d} {solver:>15} {so:>16} {sn:>16} {mn / mo:7.2f} "
              f"{o['nfev']:>5d}/{n['nfev']:<6d} {o['loglik']:13.3f} {n['loglik']:13.3f} "
              f"{o['loglik'] - best:11.3f} {n['loglik'] - best:11.3f} "
              f"{'same' if same else 'DIFF':>5}")


if __name__ == "__main__":
    main()
