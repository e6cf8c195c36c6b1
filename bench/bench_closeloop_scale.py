#!/usr/bin/env python
"""Benchmark: the close loop's cost per sample, former and current code side by side.

The data: rig files made once per sampling rate (realistic motor, pulley_friction injected,
injection seed 0, the paper's 72-run plan; TRAIN cut to whole runs totalling at least ``N`` samples,
as ``bench/bench_closeloop.py --train-samples N``) and cached in ``--cache``; the default compares
1 kHz / 20,000 TRAIN samples with 5 kHz / 100,000 (a fast DAQ: ``l1b2 rig --sample-rate 5000``).

Former code (the state before decision 0035, patched in for the ``former`` column):

* the free run's forcing ``h d dF/dtheta`` and the whitening of the Jacobian by their numpy forms
  (``ForceCore.compiled_dF = False``, ``NoiseModel.compiled = False``) instead of the compiled loops of
  :mod:`l1b2.ident.kernels` (the same numbers to the last bit);
* the compressed trust-region problem's R factor by one Householder QR (``CompressedObjective.block_rows = 0``)
  instead of blocks of rows (:func:`l1b2.ident.tallqr.r_factor`);
* the candidates' signals computed anew for every candidate (:func:`former_signals`) instead of once per
  frame (``Context.signal_cache``);
* the report's figures laid out by matplotlib's constrained layout instead of fixed margins
  (:func:`l1b2.data.plots.fixed_margins`).

``d0027`` (not run by default): the former code and, besides, the state before decision 0028:

* every local ``least_squares`` of the identification on the full residual vector
  (``LocalSolver.compressed = False``) instead of its (p+1)-row QR compression;
* the baseline identification's whole search on all samples instead of coarse to fine
  (:func:`l1b2.ident.coarse.coarse_to_fine`: the search at one sample per millisecond, then one
  warm local search on all samples);
* the cross-validated fold refits on all training samples instead of one per millisecond
  (:func:`l1b2.closeloop.acceptance.fold_fit_data`).

At 1 kHz the last two change nothing (no decimation).

Default (``--part scoring``): one round's collinearity screen and candidate scoring on a fixed
model (the Eq. 29 predictor identified once per file, a short search), CPU per variant.
``--part whole``: the whole close-loop job (:func:`l1b2.workflows.run_close_loop`, in this
process) per variant: CPU of each stage with its evaluations, the TEST free-run nrmse before and
after, the log-likelihoods of the baseline and final models, and whether the diagnoses agree.
``--variants current`` (or ``former``) runs one column only.

Usage: python bench/bench_closeloop_scale.py [--sizes 1000:20000,5000:100000] [--part scoring|whole]
       [--variants former,current[,d0027]] [--cache DIR]
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
from l1b2.closeloop import candidates as candidates_mod  # noqa: E402
from l1b2.closeloop import loop as closeloop_loop  # noqa: E402
from l1b2.closeloop import residuals as res  # noqa: E402
from l1b2.closeloop import selection as sel  # noqa: E402
from l1b2.closeloop.candidates import full_library  # noqa: E402
from l1b2.closeloop.loop import candidate_context  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402
from l1b2.data import plots  # noqa: E402
from l1b2.ident.noise import NoiseModel  # noqa: E402
from l1b2.ident.problem import ForceCore  # noqa: E402
from l1b2.ident.search import CompressedObjective, LocalSolver  # noqa: E402
from l1b2.predictor import effects as fx  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment  # noqa: E402
from l1b2.workflows import run_close_loop  # noqa: E402


@contextlib.contextmanager
def variant(name):
    """The former code patched in (``"former"`` or ``"d0027"``, see the module docstring) or the package's
    (``"current"``)."""
    saved = (LocalSolver.compressed, closeloop_loop.coarse_to_fine, acceptance.fold_fit_data,
             CompressedObjective.block_rows, ForceCore.compiled_dF, NoiseModel.compiled, candidates_mod.signals,
             plots.fixed_margins)
    if name in ("former", "d0027"):
        CompressedObjective.block_rows, ForceCore.compiled_dF, NoiseModel.compiled = 0, False, False
        candidates_mod.signals = former_signals
        plots.fixed_margins = lambda fig, **kw: fig.set_layout_engine("constrained") or fig
    if name == "d0027":
        LocalSolver.compressed = False
        closeloop_loop.coarse_to_fine = lambda est, data, m_s=None, mask=None: _full_fit(est, data, m_s, mask)
        acceptance.fold_fit_data = lambda df, mask: (df, mask)
    try:
        yield
    finally:
        (LocalSolver.compressed, closeloop_loop.coarse_to_fine, acceptance.fold_fit_data,
         CompressedObjective.block_rows, ForceCore.compiled_dF, NoiseModel.compiled, candidates_mod.signals,
         plots.fixed_margins) = saved


def former_signals(df, ctx, wanted) -> dict:
    """The candidates' signals as before decision 0035: computed anew at every call (the baseline's free run too)."""
    x = {"t": df[dataio.TIME].to_numpy(float), "s": df[dataio.POSITION].to_numpy(float),
         "V0": df[dataio.VOLTAGE].to_numpy(float), "load": df[dataio.LOAD].to_numpy(float),
         "d": df[dataio.DIRECTION].to_numpy(float)}
    if "T" in wanted:
        x["T"] = df[dataio.TEMPERATURE].to_numpy(float)
    for key in wanted:
        if key.startswith("col:"):
            x[key] = df[key[4:]].to_numpy(float)
        elif key.startswith("run:"):
            x[key] = df.groupby(dataio.RUN, sort=False)[key[4:]].transform("mean").to_numpy(float)
    if {"v_base", "a_base"} & set(wanted):
        x["v_base"] = np.asarray(ctx.baseline_free_run(df), float)
        starts = [sl.start for _, sl in dataio.run_slices(df[dataio.RUN])]
        x["a_base"] = fx.time_derivative(x["v_base"], x["t"], sorted(starts))
    return x


def _full_fit(est, data, m_s, mask):
    est.fit(data, m_s, mask)
    est.coarse_ = None
    return est


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


def scoring_setup(folder: Path):
    """``(m, est, v, r, pool)``: TRAIN's measurements, the Eq. 29 predictor identified on them once (a short
    search), its free run, the drive residual and the candidate library on the frame."""
    m = dataio.load_measurements(folder / "train.csv")
    df, mask = m.df, np.array(m.mask)
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=1, seed=0, max_nfev=30)
    est.fit(df, slider_mass_kg=m.slider_mass_kg, mask=mask)
    v = est.predict_free_run(df)
    r = res.drive_residual(df, v)
    pool = full_library()(candidate_context(est.predict_free_run, m.slider_mass_kg, df, mask, {}), df)
    return m, est, v, r, pool


def scoring_part(folder: Path, names) -> dict:
    """CPU [s] per variant of one round's collinearity screen and scoring (one effect added) on a fixed model."""
    m, est, v, r, pool = scoring_setup(folder)
    df, mask = m.df, np.array(m.mask)
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


def warm_up() -> None:
    """Compile the kernels once before any column is timed (a small synthetic identification)."""
    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, simulate_dataset
    df = simulate_dataset(example_params(3), design_grid(voltages=(220.0, 324.0), loads=(0.0, 0.07)), 0.1,
                          noise_std=1e-3, seed=0)
    est = PredictorIdentifier(order=3, fixed="recommended", n_starts=1, max_nfev=5).fit(df, slider_mass_kg=0.1)
    est.predict_one_step(df)


def whole_part(folder: Path, names) -> dict:
    """The whole close-loop job per variant: CPU [s], the stages' CPU, the diagnosis."""
    warm_up()
    out = {}
    for name in names:
        with variant(name), tempfile.TemporaryDirectory() as td:
            c0 = time.process_time()
            result = run_close_loop(folder / "train.csv", folder / "test.csv", Path(td) / "report", workers=0)
            cpu = time.process_time() - c0
        rounds = [r.to_dict() for r in result.rounds]
        test = [r["metrics"]["test"]["free_run"]["nrmse"] for r in rounds]
        final = result.extended_model if result.extended_model is not None else result.baseline_model
        out[name] = {"cpu": cpu, "stages": [(s["stage"], s["cpu_s"], s["nfev"]) for s in result.stages],
                     "diagnosis": result.diagnosis["message"], "added": [r["added"] for r in rounds],
                     "traced": result.diagnosis["traced_to"], "test": (test[0], test[-1]),
                     "loglik": (result.baseline_model.loglik_, final.loglik_)}
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
                p = part[nm]
                print(f"{rate:g} Hz {nm}: {p['diagnosis']} rounds {p['added']} traced {p['traced']}; TEST free-run "
                      f"nrmse {100 * p['test'][0]:.2f} -> {100 * p['test'][1]:.2f} %; log-likelihood baseline "
                      f"{p['loglik'][0]:.3f}, final {p['loglik'][1]:.3f}")
                print(f"    {'stage':76s} {'CPU [s]':>8s} {'nfev':>6s}")
                for st, c, nf in p["stages"]:
                    print(f"    {st[:76]:76s} {c:8.1f} {nf:6d}")
            print(f"  same diagnosis: {len({(part[nm]['diagnosis'], str(part[nm]['traced'])) for nm in names}) == 1}")


if __name__ == "__main__":
    main()
