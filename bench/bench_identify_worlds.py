#!/usr/bin/env python
"""Benchmark: ``identify`` on ~20 000 samples of several worlds, the default, the offset searches and a long reference.

Worlds (the virtual rig, in-process engine, 11 loads -0.09 ... 0.09 kg, TRAIN = |load| != 0.05 kg,
about 19.7k samples; made once and cached):

* ``realistic/s0``: the realistic motor (Eq. 29 wrong by a few percent), noise-free (the data of
  ``bench_identify_realistic.py``);
* ``realistic/s1``, ``realistic/s2``: the realistic motor with 1 mm/s speed noise and a 2 % run-to-run
  contact scatter (the realistic world of the test suite), rig seeds 1 and 2;
* ``reference/s0``: the reference motor (Eq. 29 nearly exact), noise-free.

For each world, side by side in one run (same process, same data), with CPU time (``time.process_time``),
evaluations and log-likelihood: the default (``solver="joint"``, 8 starts), the variable-projection
search from one start (``solver="varpro"``), the drive-offset search on the grid profile (``solver="offset"``,
decision 0023), the drive-offset search on the bracketed profile (``solver="offset_bracket"``, both
:mod:`l1b2.ident.offset`) with its final search in the paper's coordinates (decision 0036) and in the identifiable
coordinates (decision 0039, :mod:`l1b2.ident.identifiable`) and the long reference: the best of the variable-projection search from 8
starts (stat_tol 1e-4) and the offset profile on a fine grid (made once per world and cached; ``--reference``
makes them again). Targets: CPU <= 2 s, log-likelihood within 0.1 of the reference (and >= 1000 units
above the default where that falls short). ``--fits`` picks the compared fits by name (separated by ;).

Usage: python bench/bench_identify_worlds.py [--worlds realistic/s0,...] [--reference] [--cache DIR] [--skip-old]
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402
from l1b2.ident.offset import BRACKET  # noqa: E402
from l1b2.workflows import load_train_test  # noqa: E402

LOADS = "-0.09,-0.07,-0.05,-0.03,-0.01,0,0.01,0.03,0.05,0.07,0.09"
TARGET_S = 2.0
TARGET_DLL = 0.1
#: world name -> rig options
WORLDS = {
    "realistic/s0": ["--motor", "realistic_motor", "--seed", "0"],
    "realistic/s1": ["--motor", "realistic_motor", "--seed", "1", "--speed-noise", "0.001", "--run-scatter", "0.02"],
    "realistic/s2": ["--motor", "realistic_motor", "--seed", "2", "--speed-noise", "0.001", "--run-scatter", "0.02"],
    "reference/s0": ["--motor", "reference_motor", "--seed", "0"],
}
#: the long reference fits: the better of these is the world's reference
REFERENCES = {"varpro, 8 starts": {"solver": "varpro", "n_starts": 8, "stat_tol": 1e-4, "tol": 1e-12,
                                   "max_nfev": 600, "max_outer": 10, "n_refine": 3},
              "offset, fine grid": {"solver": "offset", "n_starts": 24, "stat_tol": 1e-4, "tol": 1e-12}}
#: the fits compared
FITS = {"joint (default)": {"solver": "joint"},
        "varpro, 1 start": {"solver": "varpro", "n_starts": 1},
        "offset, grid profile": {"solver": "offset"},
        "offset, bracketed (0036)": {"solver": "offset_bracket", "final": "paper"},
        "offset, bracketed, y final": {"solver": "offset_bracket", "final": "identifiable"},
        "offset, bracketed (0039)": {"solver": "offset_bracket", "final": "paper+identifiable"}}


def dataset(cache: Path, world: str) -> Path:
    """The rig's data of ``world`` (made once)."""
    out = cache / ("realistic_motor_11_loads" if world == "realistic/s0" else "worlds_" + world.replace("/", "_"))
    if not (out / "train.csv").exists():
        cmd = [sys.executable, "-m", "l1b2.cli", "rig", *WORLDS[world], "--engine", "inprocess", "--workers", "1",
               "--no-plots", "--quiet", f"--loads={LOADS}", "--out", str(out)]
        env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "fmu_src"))
        subprocess.run(cmd, check=True, env=env)
    return out


def fit(train, settings: dict) -> dict:
    """One fit; ``settings["final"]`` (offset_bracket only) picks the final search's coordinates (BRACKET)."""
    settings = dict(settings)
    final = settings.pop("final", None)
    est = PredictorIdentifier(**settings)
    former = BRACKET["final"]
    BRACKET["final"] = final or former
    c0 = time.process_time()
    try:
        est.fit(train)
    finally:
        BRACKET["final"] = former
    return {"cpu_s": time.process_time() - c0, "loglik": float(est.loglik_),
            "nfev": int(est.convergence_["nfev_total"]), "stages": est.convergence_.get("stages", [])}


def reference(cache: Path, world: str, data: Path, train, again: bool, names=tuple(REFERENCES)) -> dict:
    """The long reference fits of ``world`` (cached by data and settings)."""
    path = cache / f"reference_{world.replace('/', '_')}.json"
    stamp = (data / "train.csv").stat().st_mtime_ns
    ref = json.loads(path.read_text()) if path.exists() and not again else {}
    if ref.get("data_mtime_ns") != stamp:
        ref = {"data_mtime_ns": stamp}
    for name, settings in REFERENCES.items():
        if name in names and ref.get(name, {}).get("settings") != settings:
            print(f"{world}: making the reference fit '{name}' once (cached in {path})", flush=True)
            ref[name] = {**fit(train, settings), "settings": settings}
            path.write_text(json.dumps(ref, indent=1))
    return ref


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--worlds", default=",".join(WORLDS))
    ap.add_argument("--reference", action="store_true", help="make the reference fits again")
    ap.add_argument("--data-only", action="store_true", help="only make the worlds' data")
    ap.add_argument("--references-only", help="only make these reference fits (names separated by ;)")
    ap.add_argument("--skip-old", action="store_true", help="leave out the default joint search (slow)")
    ap.add_argument("--fits", help="only these compared fits (names separated by ;)")
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                         / "l1b2" / "bench"))
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    worlds = args.worlds.split(",")
    fits = {k: v for k, v in FITS.items() if not (args.skip_old and v["solver"] == "joint")
            and (args.fits is None or k in args.fits.split(";"))}
    rows = []
    for world in worlds:
        data = dataset(cache, world)
        if args.data_only:
            continue
        train, _, _ = load_train_test(data / "train.csv", data / "test.csv")
        if args.references_only:
            reference(cache, world, data, train, args.reference, args.references_only.split(";"))
            continue
        refs = reference(cache, world, data, train, args.reference)
        best = max(v["loglik"] for k, v in refs.items() if k in REFERENCES)
        for name, settings in fits.items():
            r = fit(train, settings)
            rows.append((world, len(train.df), name, r, best))
            print(f"{world}: {name}: {r['cpu_s']:.2f} s CPU, {r['nfev']} evaluations, loglik {r['loglik']:.3f} "
                  f"({r['loglik'] - best:+.3f} to the reference)", flush=True)
            if settings["solver"].startswith("offset"):
                print("    stages (CPU s): " + ", ".join(f"{st['stage']} {st.get('cpu_s', float('nan')):.2f}"
                                                    for st in r["stages"]), flush=True)
                prof = next((st["profile"] for st in r["stages"] if "profile" in st), [])
                print("    profile: " + ", ".join(f"{p['omega']:+.2f}: {p['loglik']:.1f}" for p in prof), flush=True)
        for name in REFERENCES:
            rows.append((world, len(train.df), "reference: " + name, refs[name], best))
    if args.data_only or args.references_only:
        return
    print(f"\n{'world':>13} {'samples':>7} {'fit':>28} {'CPU [s]':>8} {'nfev':>5} {'loglik':>12} {'- ref':>9} "
          f"{'target':>7}")
    for world, n, name, r, best in rows:
        d = r["loglik"] - best
        ok = "" if name.startswith("reference") else (
            "ok" if d >= -TARGET_DLL and r["cpu_s"] <= TARGET_S else
            ("ll ok" if d >= -TARGET_DLL else "MISSED"))
        print(f"{world:>13} {n:7d} {name:>28} {r['cpu_s']:8.2f} {r['nfev']:5d} {r['loglik']:12.3f} {d:9.3f} {ok:>7}")


if __name__ == "__main__":
    main()
