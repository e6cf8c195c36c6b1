"""End-to-end jobs behind the CLI: identification (issue 4), the predictor/co-simulation comparison and close-the-loop.

Every job validates all its input before it creates its output folder, so
nothing is written when input is refused, and writes its JSON report plus
PNG figures.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .data import measurements as dataio
from .data import plots
from .data.metrics import evaluation_mask, report_metrics, speed_metrics
from .errors import IdentificationError
from .predictor.setup import PredictorSetup

TEST_ABS_LOADS = (0.05,)


def load_train_test(train_path, test_path=None, *, test_abs_loads=TEST_ABS_LOADS, slider_mass_kg=None):
    """Load and validate TRAIN (and TEST); without TEST, split TRAIN by load like the paper.

    Returns ``(train, test_or_None, split_note)`` as :class:`l1b2.data.measurements.Measurements`.
    """
    train = dataio.load_measurements(train_path, slider_mass_kg=slider_mass_kg)
    if test_path is not None:
        test = dataio.load_measurements(test_path, slider_mass_kg=slider_mass_kg)
        return train, test, f"test file {test_path}"
    loads = np.abs(train.df[dataio.LOAD].to_numpy())
    has_test = np.isclose(loads[:, None], np.array(test_abs_loads)[None, :], atol=1e-9).any(axis=1)
    if not has_test.any():
        return train, None, f"no runs with |load| in {list(test_abs_loads)} kg: no held-out test"
    if has_test.all():
        raise IdentificationError(f"{train_path}: every run has |load| in {list(test_abs_loads)} kg; "
                                  f"nothing left to train on (give --test or other --test-loads)")
    tr, te = dataio.split_by_load(train, test_abs_loads)
    return tr, te, f"paper's split: test = runs with |load| in {list(test_abs_loads)} kg"


def metrics_for(est, data: dataio.Measurements | pd.DataFrame) -> dict:
    """Data-format metrics of an identified predictor on a data set (one_step and free_run)."""
    df = data.df if isinstance(data, dataio.Measurements) else data
    return report_metrics(df, est.predict_one_step(data), est.predict_free_run(data))


def _parse_fix(text: str | None):
    if text is None or text.lower() in ("none", "paper", ""):
        return None
    if text.lower() == "recommended":
        return "recommended"
    out = {}
    for item in text.split(","):
        name, eq, value = item.partition("=")
        if not eq:
            raise IdentificationError(f"--fix: expected 'none', 'recommended' or name=value,..., got '{item}'")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise IdentificationError(f"--fix: value of '{name}' is not a number: '{value}'") from None
    return out


def run_identification(train_path, out_dir, test_path=None, *, order=8, criterion="free_run", fix=None,
                       n_starts=8, seed=0, test_abs_loads=TEST_ABS_LOADS, slider_mass_kg=None, plots_on=True,
                       verbose=False) -> dict:
    """Identify the Eq. 29 predictor on TRAIN by maximum likelihood; report on TRAIN and TEST.

    Writes ``out_dir/identification.json`` (parameters with value, stderr, 95 %
    interval and unit, the paper's monomial form, identifiability, metrics for
    train and test, convergence), ``fit_report.txt`` and, per test run, a
    Fig. 10-like PNG. Returns the report dict.
    """
    from .ident.estimator import PredictorIdentifier
    train, test, split_note = load_train_test(train_path, test_path, test_abs_loads=test_abs_loads,
                                              slider_mass_kg=slider_mass_kg)
    est = PredictorIdentifier(order=order, criterion=criterion, fixed=_parse_fix(fix), n_starts=n_starts,
                              seed=seed, verbose=verbose)
    est.fit(train)  # slider mass and evaluation mask from the validated Measurements
    sections = {
        "data": {"train": str(train_path), "test": str(test_path) if test_path else None,
                 "split": split_note, "train_runs": len(train.runs),
                 "test_runs": len(test.runs) if test is not None else 0},
        "metrics": {"train": metrics_for(est, train), "test": metrics_for(est, test) if test is not None else None},
        "predictor": PredictorSetup(est.params_, est.m_s_, est.T_s_).to_dict(),
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = []
    if plots_on and test is not None:
        free = est.predict_free_run(test)
        one = est.predict_one_step(test)
        for run, sl in dataio.run_slices(test.df[dataio.RUN]):
            g = test.df.iloc[sl].reset_index(drop=True)
            m = speed_metrics(free[sl], g[dataio.SPEED].to_numpy(), evaluation_mask(g))
            title = (f"run {run}: V0 {g[dataio.VOLTAGE].iloc[0]:g} V, load {g[dataio.LOAD].iloc[0]:+g} kg, "
                     f"dir {int(g[dataio.DIRECTION].iloc[0]):+d}; free-run p95 {m['p95_abs_rel_error']:.1%}")
            figs.append(str(plots.prediction_vs_measured(g, free[sl], out / f"fig10_test_run_{run}.png", title,
                                                         v_pred_alt=one[sl], labels=("free run", "one step"))))
    sections["figures"] = figs
    est.result_.save(out, **sections)  # identification.json (strict JSON) and fit_report.txt
    return {**est.to_dict(), **sections}


def run_comparison(out_dir, mp=None, identification: dict | None = None, *, order=8) -> dict:
    """Predictor against the co-simulation's steady states (reference motor or ``mp``).

    * derived predictor (``linearized`` and the paper's ``paper`` reduction,
      pure-slip settings) vs the co-simulation in pure-slip mode;
    * the same derived predictor vs the stick-slip co-simulation (the
      difference is reported, not hidden);
    * the identified predictor (if given) vs the stick-slip co-simulation.
    """
    from .physics.params import load_motor
    from .predictor import derive
    from .predictor.model import PredictorParams
    mp = mp or load_motor()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cases = {}
    tables = {}
    for method in ("linearized", "paper"):
        p = derive.derive_predictor(mp, method=method, mode="pure_slip", order=order)
        for mode in ("pure_slip", "stick_slip"):
            key = f"derived_{method}_vs_{mode}"
            tables[key] = derive.compare_steady(p, mp, mode=mode)
            cases[key] = derive.summarize(tables[key])
    if identification is not None:
        pid = PredictorParams.from_dict(identification["predictor"]["params"])
        tables["identified_vs_stick_slip"] = derive.compare_steady(pid, mp, mode="stick_slip")
        cases["identified_vs_stick_slip"] = derive.summarize(tables["identified_vs_stick_slip"])
    for key, df in tables.items():
        df.to_csv(out / f"{key}.csv", index=False)
    fig = plots.steady_comparison(tables, out / "predictor_vs_cosim_steady.png")
    report = {"cases": cases, "figure": str(fig),
              "note": "co-simulation steady states from l1b2.physics.steady.steady_state (the fixed point of the "
                      "time-domain co-simulation); relative error against the co-simulation's speed"}
    (out / "comparison.json").write_text(json.dumps(report, indent=1))
    return report


def run_close_loop(train_path, test_path, out_dir, *, slider_mass_kg=None, plots_on=True, progress=None,
                   **settings):
    """Close the loop on TRAIN/TEST files; write ``report.json``, ``report.md`` and the PNGs into ``out_dir``.

    Loads and validates both files (slider mass: ``slider_mass_kg`` or
    TRAIN's sidecar) before anything is written, runs
    :class:`l1b2.closeloop.loop.CloseLoop` with ``settings`` (``order``,
    ``k_folds``, ``alpha``, ``min_gain``, ``parsimony``, ``seed``,
    ``n_starts``, ``library``) and saves its result. Returns the
    :class:`~l1b2.closeloop.result.CloseLoopResult`; its ``wall_time_s``
    counts loading and the fit.
    """
    from .closeloop.loop import CloseLoop
    t_start = time.perf_counter()
    train, test, _ = load_train_test(train_path, test_path, slider_mass_kg=slider_mass_kg)
    result = CloseLoop(progress=progress, **settings).fit(train, test).result_
    result = dataclasses.replace(result, wall_time_s=round(time.perf_counter() - t_start, 2))
    if plots_on and progress is not None:
        progress("plots")
    result.save(out_dir, plots_on=plots_on)
    return result
