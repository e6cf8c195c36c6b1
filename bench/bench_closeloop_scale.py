#!/usr/bin/env python
"""Benchmark: the close loop's cost per sample, former and current per-sample code side by side.

The data: rig files made once per sampling rate (realistic motor, pulley_friction injected,
injection seed 0, the paper's 72-run plan; TRAIN cut to whole runs totalling at least ``N`` samples,
as ``bench/bench_closeloop.py --train-samples N``) and cached in ``--cache``; the default compares
1 kHz / 20,000 TRAIN samples with 5 kHz / 100,000 (a fast DAQ: ``l1b2 rig --sample-rate 5000``).

Former per-sample code (kept here as the reference, patched in for the "former" column):

* the collinearity screen (:func:`l1b2.closeloop.acceptance.collinear`) with one least-squares
  solve per added column and the added effects' features recomputed for every candidate, instead
  of one solve for all columns with the features computed once per round;
* the report's scatter panels drawing every TRAIN sample instead of at most
  :data:`l1b2.data.plots.DISPLAY_POINTS` (display only: the data and every figure computed from
  them stay whole).

Default (``--part scoring``): what these change, on a fixed model (the Eq. 29 predictor
identified once per file, a short search): the candidates' scores of a round with one effect
added (collinearity screen, then :func:`~l1b2.closeloop.selection.score_candidates`), CPU
per variant. ``--part whole``: the whole close-loop job (:func:`l1b2.workflows.run_close_loop`,
in this process) per variant, with the CPU of each stage side by side and whether the
diagnoses agree. ``--variants current`` (or ``former``) runs one column only.

Usage: python bench/bench_closeloop_scale.py [--sizes 1000:20000,5000:100000] [--part scoring|whole]
       [--variants former,current] [--cache DIR]
"""
import argparse
import contextlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_closeloop import _cut_train  # noqa: E402
from l1b2.closeloop import acceptance  # noqa: E402
from l1b2.closeloop import loop as closeloop_loop  # noqa: E402
from l1b2.closeloop import residuals as res  # noqa: E402
from l1b2.closeloop import selection as sel  # noqa: E402
from l1b2.closeloop.candidates import full_library  # noqa: E402
from l1b2.closeloop.loop import candidate_context  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.data import plots  # noqa: E402
from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment  # noqa: E402
from l1b2.workflows import run_close_loop  # noqa: E402


def former_collinear(candidate, effects, df, mask, rtol=acceptance.COLLINEAR_RTOL, added=None):
    """The former collinearity screen: one solve per added column, the added features recomputed (the reference)."""
    if not effects.candidates:
        return False
    m = np.asarray(mask, bool)
    C = np.asarray(candidate.features(df), float).reshape(len(df), -1)[m]
    for c in effects.candidates:
        F = np.asarray(c.features(df), float).reshape(len(df), -1)[m]
        for f in F.T:
            nf = float(np.linalg.norm(f))
            if nf == 0:
                continue
            coef = np.linalg.lstsq(C, f, rcond=None)[0]
            if float(np.linalg.norm(f - C @ coef)) < rtol * nf:
                return True
    return False


@contextlib.contextmanager
def variant(name):
    """The former per-sample code patched in (``"former"``) or the package's (``"current"``)."""
    saved = (acceptance.collinear, closeloop_loop.collinear, plots.display_rows)
    if name == "former":
        acceptance.collinear = closeloop_loop.collinear = former_collinear
        plots.display_rows = lambda n, limit=None: np.arange(n)
    try:
        yield
    finally:
        acceptance.collinear, closeloop_loop.collinear, plots.display_rows = saved


def rig_files(rate: float, n_train: int, cache: Path) -> Path:
    """train/test files of the benchmark's rig at ``rate`` with TRAIN cut to ``n_train`` samples (made once)."""
    out = cache / f"pulley_friction_0_{rate:g}Hz_{n_train}"
    if not (out / "train.csv").exists():
        mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
        plan = RigPlan(step_s=1e-3) if rate == 1000 else RigPlan(sample_rate_Hz=rate, step_s=min(1e-3, 1 / rate))
        df, truth = run_experiment(plan, mp, injections=["pulley_friction"], engine="inprocess", workers=2,
                                   injection_seed=0)
        tmp = out.with_name(out.name + ".partial")
        shutil.rmtree(tmp, ignore_errors=True)
        write_experiment(_cut_train(df, n_train), tmp, mp, plan, truth)
        os.replace(tmp, out)
    return out


def scoring_part(folder: Path, names) -> dict:
    """CPU [s] per variant of one round's collinearity screen and scoring (one effect added) on a fixed model."""
    m = dataio.load_measurements(folder / "train.csv")
    df, mask = m.df, np.array(m.mask)
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=1, seed=0, max_nfev=30)
    est.fit(df, slider_mass_kg=m.slider_mass_kg, mask=mask)
    v = est.predict_free_run(df)
    r = res.drive_residual(df, v)
    pool = full_library()(candidate_context(est.predict_free_run, m.slider_mass_kg, df, mask, {}), df)
    added = next(c for c in pool if c.family == "load_path_friction")
    effects = acceptance.EffectSet().add(added, np.zeros(added.n_params))
    out = {}
    for name in names:
        with variant(name):
            c0 = time.process_time()
            cols = acceptance.added_columns(effects, df, mask)
            cands = [c for c in pool if c.family not in effects.families
                     and not acceptance.collinear(c, effects, df, mask, added=cols)]
            c1 = time.process_time()
            scores = sel.score_candidates(cands, r, df, mask, est.params_, m.slider_mass_kg, v_pred=v)
            c2 = time.process_time()
        out[name] = {"collinear": c1 - c0, "scoring": c2 - c1, "n": m.n_samples,
                     "best": [(s.candidate.label, round(s.cv_gain, 6)) for s in scores[:3]]}
    return out


def whole_part(folder: Path, names) -> dict:
    """The whole close-loop job per variant: CPU [s], the stages' CPU, the diagnosis."""
    out = {}
    for name in names:
        with variant(name), tempfile.TemporaryDirectory() as td:
            c0 = time.process_time()
            result = run_close_loop(folder / "train.csv", folder / "test.csv", Path(td) / "report", workers=0)
            cpu = time.process_time() - c0
        out[name] = {"cpu": cpu, "n": result.data["n_train"] if "n_train" in (result.data or {}) else None,
                     "stages": [(s["stage"], s["cpu_s"]) for s in result.stages],
                     "diagnosis": result.diagnosis["message"], "added": [r.to_dict()["added"] for r in result.rounds]}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000:20000,5000:100000", help="RATE_HZ:TRAIN_SAMPLES,...")
    ap.add_argument("--part", choices=("scoring", "whole"), default="scoring")
    ap.add_argument("--variants", default="former,current")
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                           / "l1b2" / "bench_closeloop_scale"))
    args = ap.parse_args(argv)
    names = [v for v in args.variants.split(",") if v]
    sizes = [(float(a), int(b)) for a, b in (x.split(":") for x in args.sizes.split(","))]
    table = []
    for rate, n in sizes:
        folder = rig_files(rate, n, Path(args.cache))
        n_train = dataio.load_measurements(folder / "train.csv").n_samples
        part = scoring_part(folder, names) if args.part == "scoring" else whole_part(folder, names)
        table.append((rate, n_train, part))
        print(f"{rate:g} Hz, {n_train} TRAIN samples ({folder}): done", flush=True)
    print(f"\nCPU [s] per variant ({args.part}); per 1000 TRAIN samples in brackets")
    keys = ("collinear", "scoring") if args.part == "scoring" else ("cpu",)
    print(f"{'rate':>8s} {'TRAIN':>8s} " + " ".join(f"{n + ' ' + k:>26s}" for n in names for k in keys))
    for rate, n_train, part in table:
        cells = [f"{part[nm][k]:8.2f} ({1000 * part[nm][k] / n_train:6.3f})" for nm in names for k in keys]
        print(f"{rate:8g} {n_train:8d} " + " ".join(f"{c:>26s}" for c in cells))
    if len(table) > 1:
        (_, n0, p0), (_, n1, p1) = table[0], table[-1]
        for nm in names:
            for k in keys:
                print(f"{nm} {k}: {p1[nm][k] / p0[nm][k]:.2f} x the CPU for {n1 / n0:.2f} x the samples "
                      f"(cost per sample x {p1[nm][k] / p0[nm][k] * n0 / n1:.2f})")
    for rate, n_train, part in table:
        if args.part == "scoring":
            print(f"{rate:g} Hz best three (label, CV gain): " + "; ".join(f"{nm}: {part[nm]['best']}" for nm in names))
            print(f"  same scores: {len({str(part[nm]['best']) for nm in names}) == 1}")
        else:
            for nm in names:
                print(f"{rate:g} Hz {nm}: {part[nm]['diagnosis']} rounds {part[nm]['added']}")
                for st, c in part[nm]["stages"]:
                    print(f"    {st[:76]:76s} {c:7.1f}")
            print(f"  same diagnosis: {len({part[nm]['diagnosis'] for nm in names}) == 1}")


if __name__ == "__main__":
    main()
