"""End-to-end jobs behind the CLI: identification (issue 4) and the predictor/co-simulation comparison.

Every job validates all its input before it creates its output folder, so
nothing is written when input is refused, and writes its JSON report plus
PNG figures.
"""

from __future__ import annotations

import json
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


# ---------------------------------------------------------------------------
# Design studies (issue 13): `l1b2 sweep`
# ---------------------------------------------------------------------------

def _stored_chunks(chunks_dir: Path, fingerprint: str, n_chunks: int) -> set[int]:
    """Chunk ids already stored for this study; refuses a folder that holds another study's chunks."""
    manifest = chunks_dir / "study.json"
    if not manifest.is_file():
        return set()
    from .errors import SpecError
    stored = json.loads(manifest.read_text()).get("fingerprint")
    if stored != fingerprint:
        raise SpecError(f"{chunks_dir}: holds the chunks of another study (fingerprint {stored}, this spec "
                        f"{fingerprint}); use another --out or remove {chunks_dir}")
    ids = {int(p.stem.split("-")[1]) for p in chunks_dir.glob("chunk-*.parquet")}
    return {i for i in ids if i < n_chunks}


def _write_parquet_atomically(df: pd.DataFrame, path: Path) -> None:
    import os
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    df.to_parquet(tmp, index=False)
    os.replace(tmp, path)


def run_sweep(spec_path, out_dir, *, workers: int | None = None, scheduler: str | None = None,
              progress: bool = True, plots_on: bool = True, traverse=None):
    """Run the study of ``spec_path`` into ``out_dir``; returns its :class:`l1b2.sweep.result.SweepResult`.

    Resumable: every finished chunk is written at once, atomically, to
    ``out_dir/chunks/chunk-NNNNN.parquet``; the same command run again skips
    the chunks stored (a folder holding another study's chunks is refused).
    At the end: ``samples.parquet`` (every sample's parameters and outputs,
    in sample-id order), ``summary.csv``, ``sensitivity.csv`` (+ ``sobol.csv``),
    ``study.json`` and PNGs. ``workers=0`` runs in this process, otherwise
    a local Dask cluster of ``workers`` processes or the one at ``scheduler``.
    For the FMU engine the FMUs are built (or found in the cache) once, here.
    """
    import contextlib
    import time

    from tqdm import tqdm

    from .cluster import dask_client
    from .errors import SpecError
    from .fmi.cache import ensure_fmus
    from .physics.params import load_motor
    from .sweep import runner
    from .sweep.result import SweepResult
    from .sweep.sampling import draw_samples
    from .sweep.spec import motor_reference, parse_spec
    from .sweep.tasks import TaskContext
    spec_path, out = Path(spec_path), Path(out_dir)
    try:
        text = spec_path.read_text()
    except OSError as exc:
        raise SpecError(f"{spec_path}: cannot read the study ({exc.strerror})") from None
    ref = motor_reference(text, str(spec_path))
    mp = load_motor(spec_path.parent / ref if ref else None)
    spec = parse_spec(text, str(spec_path), mp)
    samples = draw_samples(spec)
    bounds = runner.chunk_bounds(len(samples), spec.chunk_size)
    chunks_dir = out / "chunks"
    done = _stored_chunks(chunks_dir, spec.fingerprint(), len(bounds))
    ctx = TaskContext.from_spec(spec, mp, ensure_fmus() if spec.engine == "fmu" else None)
    skipped = sum(b - a for cid, (a, b) in enumerate(bounds) if cid in done)
    parallel = scheduler is not None or workers != 0
    t0 = time.perf_counter()
    with (dask_client(workers, scheduler) if parallel else contextlib.nullcontext()) as client:
        n_workers = len(client.nthreads()) if client is not None else 1
        chunks_dir.mkdir(parents=True, exist_ok=True)
        (chunks_dir / "study.json").write_text(json.dumps(
            {"fingerprint": spec.fingerprint(), "samples": len(samples), "chunk_size": spec.chunk_size}, indent=1))
        t1 = time.perf_counter()
        with tqdm(total=len(samples), initial=skipped, desc=f"sweep ({spec.engine})", unit="traverse",
                  disable=not progress) as bar:
            for cid, frame in runner.execute(samples, ctx, spec.chunk_size, done=done, client=client,
                                             traverse=traverse):
                _write_parquet_atomically(frame, chunks_dir / f"chunk-{cid:05d}.parquet")
                bar.update(len(frame))
        t2 = time.perf_counter()
    table = runner.assemble((pd.read_parquet(chunks_dir / f"chunk-{cid:05d}.parquet") for cid in range(len(bounds))),
                            len(samples))
    run = len(samples) - skipped
    info = {"engine_workers": n_workers, "scheduler": scheduler, "executed_samples": run,
            "skipped_samples": skipped, "wall_time_s": round(t2 - t0, 3), "startup_s": round(t1 - t0, 3),
            "worker_seconds_per_traverse": round((t2 - t1) * n_workers / run, 4) if run else None}
    res = SweepResult(table, spec, ctx, info)
    res.save(out, plots=plots_on)
    return res
