"""End-to-end jobs behind the CLI: identification, the predictor/co-simulation comparison, close-the-loop, sweeps.

Every job writes through :func:`output_dir`: the target is checked and
locked before any computation (an existing file, a folder of someone else's
files or a second concurrent run are refused with one line), the job writes
into a temporary sibling folder, and only a complete result is renamed into
place, replacing the previous complete result (never mixed with it). Input
is validated inside, so nothing is left behind when input is refused. JSON
reports are strict (:func:`l1b2.jsonio.dumps`: no NaN or Infinity).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import json
import os
import shutil
import socket
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd

from .data import measurements as dataio
from .data import plots
from .data.coverage import check_same_rig, input_checks, outside_range, runs_of_two
from .jsonio import dumps
from .data.metrics import diverged_runs, evaluation_mask, level_law_check, report_metrics, speed_metrics
from .errors import IdentificationError, OutputError
from .predictor.setup import PredictorSetup
from .cosim.master import pid_alive

#: marker file in every output folder written by :func:`output_dir`
OUTPUT_MARKER = ".l1b2-output.json"


# ---------------------------------------------------------------------------
# output folders
# ---------------------------------------------------------------------------

def _acquire_lock(out: Path) -> Path:
    """Create ``.NAME.lock`` beside ``out`` exclusively; a lock of a dead process on this host is taken over."""
    lock = out.parent / f".{out.name}.lock"
    me = f"{os.getpid()} {socket.gethostname()}"
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                pid_text, _, host = lock.read_text().partition(" ")
                pid = int(pid_text)
            except (OSError, ValueError):
                pid, host = -1, ""
            if host.strip() == socket.gethostname() and pid > 0 and not pid_alive(pid):
                stale = lock.with_name(f"{lock.name}.stale-{os.getpid()}")
                try:
                    os.replace(lock, stale)
                    stale.unlink()
                except OSError:
                    pass
                continue
            who = f"pid {pid} on {host.strip()}" if pid > 0 else "another process"
            raise OutputError(f"{out}: another l1b2 run ({who}) is writing this output folder; wait for it to "
                              f"finish or choose another folder (lock file {lock})") from None
        with os.fdopen(fd, "w") as fh:
            fh.write(me)
        return lock
    raise OutputError(f"{out}: cannot take the lock {lock}")


def _foreign_files(out: Path, known: tuple[str, ...]) -> list[str]:
    """Files in ``out`` (relative, posix) that match none of the ``known`` output patterns."""
    return [rel for rel in (f.relative_to(out).as_posix() for f in out.rglob("*") if not f.is_dir())
            if not any(fnmatch.fnmatch(rel, pat) for pat in known)]


def _marker_command(folder: Path) -> str | None:
    """The command named in ``folder``'s :data:`OUTPUT_MARKER` ("?" when unreadable), None without a marker."""
    marker = folder / OUTPUT_MARKER
    if not marker.is_file():
        return None
    try:
        doc = json.loads(marker.read_text()[:10_000])
        return str(doc["command"]) if isinstance(doc, dict) and isinstance(doc.get("command"), str) else "?"
    except (OSError, ValueError):
        return "?"


def _check_target(out: Path, known: tuple[str, ...] = (), command: str = "l1b2", inputs=()) -> None:
    """Refuse a target ``out`` that a run of ``command`` must not replace.

    Refused: a file; the current folder or one of its parents (``--out .``);
    a folder holding one of the command's ``inputs``; the result of another
    command (its marker names that command); an unmarked folder holding
    files other than the command's :data:`KNOWN_OUTPUTS`.
    """
    if out.exists() or out.is_symlink():
        if not out.is_dir() or out.is_symlink():
            raise OutputError(f"{out}: exists and is not a folder; give a folder (new, empty, or an earlier "
                              "result of the same command) as output")
        real = out.resolve()
        cwd = Path.cwd().resolve()
        if real == cwd or real in cwd.parents:
            raise OutputError(f"{out}: is the current folder or one of its parents, which a result replaces as "
                              "a whole: give a new subfolder as output, e.g. --out results")
        for item in inputs:
            if item is None:
                continue
            p = Path(item).resolve()
            if p == real or real in p.parents:
                raise OutputError(f"{out}: holds this command's input {item}, which replacing the folder would "
                                  "delete: give another folder as output")
        other = _marker_command(out)
        if other is not None and other != command:
            raise OutputError(f"{out}: holds the result of 'l1b2 {other}', which 'l1b2 {command}' would delete: "
                              "give another folder as output")
        if other is None:
            foreign = _foreign_files(out, known)
            if foreign:
                raise OutputError(f"{out}: folder holds files not written by this command (e.g. {foreign[0]}) "
                                  "and would be replaced: give a new or empty folder as output")
    elif out.parent.exists() and not out.parent.is_dir():
        raise OutputError(f"{out.parent}: exists and is not a folder")


def _recover_swap(out: Path) -> None:
    """Finish or roll back a swap that a killed run left half done (call with the lock held).

    :func:`_swap_into_place` renames ``out`` to ``.NAME.old-PID`` and then the
    complete temporary folder (it holds :data:`OUTPUT_MARKER`, written last)
    to ``out``. Killed between the two: the complete new result is moved into
    place when there is one, else the old result is moved back. Killed after
    both: the left-over old result is removed.
    """
    olds = sorted(out.parent.glob(f".{out.name}.old-*"), key=lambda p: p.stat().st_mtime)
    if not olds:
        return
    if not out.exists():
        done = [t for t in out.parent.glob(f".{out.name}.tmp-*") if (t / OUTPUT_MARKER).is_file()]
        if done:
            os.replace(max(done, key=lambda p: (p / OUTPUT_MARKER).stat().st_mtime), out)
        else:
            os.replace(olds.pop(), out)
    for old in olds:
        shutil.rmtree(old, ignore_errors=True)


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; the ones created, deepest first."""
    missing = []
    p = folder
    while not p.exists():
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot create the output folder's parent: {exc.strerror or exc}") from None
    return missing


def _swap_into_place(tmp: Path, out: Path) -> None:
    """Rename the complete ``tmp`` to ``out``; a previous ``out`` is removed only after that succeeded."""
    old = None
    if out.exists():
        old = out.parent / f".{out.name}.old-{os.getpid()}"
        os.replace(out, old)
    try:
        os.replace(tmp, out)
    except OSError:
        if old is not None:
            os.replace(old, out)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


#: file patterns each command writes (an unmarked folder holding only these, e.g. from an older version,
#: may be replaced)
KNOWN_OUTPUTS: dict[str, tuple[str, ...]] = {
    "identify": ("identification.json", "fit_report.txt", "fig10_test_run_*.png"),
    "compare": ("comparison.json", "*_vs_*.csv", "predictor_vs_cosim_steady.png"),
    "rig": ("all.csv", "all.json", "train.csv", "train.json", "test.csv", "test.json", "rig_truth.json",
            "rig_summary.json", "fig9*.png"),
    "export": ("fmus/*.fmu", "*.fmu", "*.ssp", "manifest.json"),
    "close-loop": ("report.json", "report.md", "*.png"),
    "export-calibrated": ("fmus/*.fmu", "calibrated_manifest.json", "*.ssp", "calibrated_ssv/*.ssv", "*.png"),
    "sweep": ("chunks/*", "samples.parquet", "summary.csv", "sensitivity.csv", "sobol.csv", "study.json",
              "sweep_*.png"),
    "study": ("study.json", "rows.csv", "study_*.png"),
}


@contextmanager
def output_dir(out, *, command: str = "l1b2", inputs=()) -> Iterator[Path]:
    """Write a command's results into ``out`` all at once, or not at all.

    Before the body runs: ``out`` must not be a file, the current folder, a
    folder holding one of ``inputs``, the result of another command (its
    :data:`OUTPUT_MARKER` names the command), nor a non-empty folder without
    a marker holding files other than the command's own
    (:data:`KNOWN_OUTPUTS`; someone else's files are never replaced);
    a lock file ``.NAME.lock`` beside it refuses a second concurrent writer
    (a lock left by a dead process on this host is taken over), and
    temporary folders left by killed runs are removed. The body writes into
    the yielded temporary sibling folder; when it completes, the marker is
    added and the folder renamed to ``out``, replacing the previous result
    only then. When it raises (or is interrupted), the temporary folder and
    any parent folders created for it are removed and ``out`` is untouched.

    Yields
    ------
    pathlib.Path
        The temporary folder to write into. Paths recorded in reports should
        name the final folder (``out / name``).

    Raises
    ------
    OutputError
        ``out`` cannot be used (see above); nothing is computed.
    """
    out = Path(out)
    known = KNOWN_OUTPUTS.get(command, ())
    _check_target(out, known, command, inputs)
    created = _make_parents(out.parent)
    try:
        lock = _acquire_lock(out)
    except BaseException:
        _remove_empty(created)
        raise
    tmp = None
    try:
        _recover_swap(out)  # a killed run's half-done swap, completed or rolled back
        _check_target(out, known, command, inputs)
        for stale in out.parent.glob(f".{out.name}.tmp-*"):
            shutil.rmtree(stale, ignore_errors=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out.parent))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp's 0700 would make the result private
        yield tmp
        (tmp / OUTPUT_MARKER).write_text(json.dumps({"command": command, "finished": time.time(),
                                                     "pid": os.getpid()}, allow_nan=False))
        _check_target(out, known, command, inputs)  # nothing foreign appeared there meanwhile
        _swap_into_place(tmp, out)
        tmp = None
    finally:
        lock.unlink(missing_ok=True)
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
            _remove_empty(created)


def _remove_empty(folders: list[Path]) -> None:
    for f in folders:
        try:
            f.rmdir()
        except OSError:
            break


# ---------------------------------------------------------------------------
# identification
# ---------------------------------------------------------------------------

TEST_ABS_LOADS = (0.05,)
#: smallest number of runs the identification needs
MIN_TRAIN_RUNS = 2


def _check_train_runs(train: dataio.Measurements, path, split_note: str) -> None:
    """Refuse TRAIN with fewer runs than the identification needs, naming the file and the likely cause."""
    runs = train.runs
    if len(runs) >= MIN_TRAIN_RUNS:
        return
    part = "" if split_note.startswith("test file") or "no held-out" in split_note else f" after the {split_note}"
    raise IdentificationError(
        f"{path}: TRAIN has {len(runs)} run{'s' if len(runs) != 1 else ''}{part} "
        f"({', '.join(map(str, runs)) or 'none'}); the identification needs at least {MIN_TRAIN_RUNS} runs "
        "(traverses at different voltages/loads/directions): does the 'run' column number each traverse, "
        "or did the export keep only one?")


def load_train_test(train_path, test_path=None, *, test_abs_loads=TEST_ABS_LOADS, slider_mass_kg=None,
                    allow_unusual_units=False):
    """Load and validate TRAIN (and TEST); without TEST, split TRAIN by load like the paper.

    Both files get the same checks, including the unit plausibility
    (``allow_unusual_units`` overrides it for both). Returns
    ``(train, test_or_None, split_note)`` as
    :class:`l1b2.data.measurements.Measurements`.
    """
    kw = dict(slider_mass_kg=slider_mass_kg, allow_unusual_units=allow_unusual_units)
    train = runs_of_two(dataio.load_measurements(train_path, **kw), train_path)
    if test_path is not None:
        test = runs_of_two(dataio.load_measurements(test_path, **kw), test_path)
        check_same_rig(train, test, explicit={"slider_mass_kg": slider_mass_kg}, allow_unusual_units=allow_unusual_units)
        note = f"test file {test_path}"
        _check_train_runs(train, train_path, note)
        return train, test, note
    loads = np.abs(train.df[dataio.LOAD].to_numpy())
    has_test = np.isclose(loads[:, None], np.array(test_abs_loads)[None, :], atol=1e-9).any(axis=1)
    if not has_test.any():
        note = f"no runs with |load| in {list(test_abs_loads)} kg: no held-out test"
        _check_train_runs(train, train_path, note)
        return train, None, note
    if has_test.all():
        raise IdentificationError(f"{train_path}: every run has |load| in {list(test_abs_loads)} kg; "
                                  f"nothing left to train on (give --test or other --test-loads)")
    tr, te = dataio.split_by_load(train, test_abs_loads)
    note = f"paper's split: test = runs with |load| in {list(test_abs_loads)} kg"
    _check_train_runs(tr, train_path, note)
    return tr, te, note


def metrics_for(est, data: dataio.Measurements | pd.DataFrame) -> dict:
    """Data-format metrics of an identified predictor on a data set (one_step and free_run).

    Diverged runs (non-finite or absurd predictions) are excluded and
    counted (:func:`l1b2.data.metrics.report_metrics`).
    """
    df = data.df if isinstance(data, dataio.Measurements) else data
    with np.errstate(all="ignore"):
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


def _fit_naming_file(est, train: dataio.Measurements, train_path) -> None:
    """``est.fit(train)``; an IdentificationError names the TRAIN file."""
    try:
        est.fit(train)  # slider mass and evaluation mask from the validated Measurements
    except IdentificationError as exc:
        text = str(exc)
        raise IdentificationError(text if str(train_path) in text else f"{train_path}: {text}") from exc


def _test_figures(est, test: dataio.Measurements, tmp: Path, out: Path) -> list[str]:
    """Fig. 10-like PNG per TEST run (diverged predictions are drawn where finite and named in the title)."""
    with np.errstate(all="ignore"):
        free = est.predict_free_run(test)
        one = est.predict_one_step(test)
    bad = set(diverged_runs(test.df, free))
    figs = []
    for run, sl in dataio.run_slices(test.df[dataio.RUN]):
        g = test.df.iloc[sl].reset_index(drop=True)
        f, o = free[sl].copy(), one[sl].copy()
        if run in bad:
            lim = 10 * max(float(np.max(np.abs(g[dataio.SPEED]))), 5e-3)
            f[~(np.abs(f) <= lim)] = np.nan
            o[~(np.abs(o) <= lim)] = np.nan
            note = "free run DIVERGED (excluded from the metrics)"
        else:
            m = speed_metrics(f, g[dataio.SPEED].to_numpy(), evaluation_mask(g) & np.isfinite(f))
            note = f"free-run p95 {m['p95_abs_rel_error']:.1%}"
        title = (f"run {run}: V0 {g[dataio.VOLTAGE].iloc[0]:g} V, load {g[dataio.LOAD].iloc[0]:+g} kg, "
                 f"dir {int(g[dataio.DIRECTION].iloc[0]):+d}; {note}")
        name = f"fig10_test_run_{run}.png"
        plots.prediction_vs_measured(g, f, tmp / name, title, v_pred_alt=o, labels=("free run", "one step"),
                                     measured=plots.data_speed_label(bool(test.meta.get("speed_derived"))))
        figs.append(str(out / name))
    return figs


def run_identification(train_path, out_dir, test_path=None, *, order=8, criterion="free_run", fix=None,
                       n_starts=8, seed=0, test_abs_loads=TEST_ABS_LOADS, slider_mass_kg=None, plots_on=True,
                       verbose=False, allow_unusual_units=False, noise_fit="auto", noise="common",
                       model="eq29") -> dict:
    """Identify the Eq. 29 predictor on TRAIN by maximum likelihood; report on TRAIN and TEST.

    ``noise_fit``: ``"auto"`` (default), ``"alternate"`` or ``"profile"``; ``noise``: ``"common"`` (default) or
    ``"per_run"``; ``model``: the predictor family, ``"eq29"`` (default) or ``"pure_slip"``
    (:class:`l1b2.ident.estimator.PredictorIdentifier`).

    Writes (through :func:`output_dir`, so all at once or nothing)
    ``out_dir/identification.json`` (parameters with value, stderr, 95 %
    interval and unit, the paper's monomial form, identifiability, metrics for
    train and test with diverged runs excluded and counted, the input checks:
    unit findings, TRAIN's range and the TEST runs outside it),
    ``fit_report.txt`` and, per test run, a Fig. 10-like PNG. Returns the
    report dict.
    """
    from .ident.estimator import PredictorIdentifier
    out = Path(out_dir)
    with output_dir(out, command="identify", inputs=(train_path, test_path)) as tmp:
        train, test, split_note = load_train_test(train_path, test_path, test_abs_loads=test_abs_loads,
                                                  slider_mass_kg=slider_mass_kg,
                                                  allow_unusual_units=allow_unusual_units)
        est = PredictorIdentifier(order=order, criterion=criterion, fixed=_parse_fix(fix), n_starts=n_starts,
                                  seed=seed, verbose=verbose, noise_fit=noise_fit, noise=noise, model=model)
        _fit_naming_file(est, train, train_path)
        sections = {
            "data": {"train": str(train_path), "test": str(test_path) if test_path else None,
                     "split": split_note, "train_runs": len(train.runs),
                     "test_runs": len(test.runs) if test is not None else 0},
            "checks": input_checks(train, test),
            "metrics": {"train": metrics_for(est, train),
                        "test": metrics_for(est, test) if test is not None else None},
            "predictor": PredictorSetup(est.params_, est.m_s_, est.T_s_, est.result_.frequency_response).to_dict(),
        }
        sections["checks"]["level_law"] = level_law_check(train.df, train.mask,
                                                          sections["metrics"]["train"]["free_run"]["nrmse"])
        sections["figures"] = _test_figures(est, test, tmp, out) if plots_on and test is not None else []
        est.result_.save(tmp, **sections)  # identification.json (strict JSON) and fit_report.txt
    return {**est.to_dict(), **sections}


def run_comparison(out_dir, mp=None, identification: dict | None = None, *, order=8) -> dict:
    """Predictor against the co-simulation's steady states (reference motor or ``mp``).

    * derived predictor (``linearized`` and the paper's ``paper`` reduction,
      pure-slip settings) vs the co-simulation in pure-slip mode;
    * the same derived predictor vs the stick-slip co-simulation (the
      difference is reported, not hidden);
    * the identified predictor (if given) vs the stick-slip co-simulation;
      grid points outside the range the identification was trained on
      (``checks.training_range`` of its report) are counted and reported as
      extrapolation.
    """
    from .physics.params import load_motor
    from .predictor import derive
    from .predictor.model import PredictorParams
    mp = mp or load_motor()
    out = Path(out_dir)
    with output_dir(out, command="compare") as tmp:
        cases = {}
        tables = {}
        for method in ("linearized", "paper"):
            p = derive.derive_predictor(mp, method=method, mode="pure_slip", order=order)
            for mode in ("pure_slip", "stick_slip"):
                key = f"derived_{method}_vs_{mode}"
                tables[key] = derive.compare_steady(p, mp, mode=mode)
                cases[key] = derive.summarize(tables[key])
        if identification is not None:
            try:
                pid = PredictorParams.from_dict(identification["predictor"]["params"])
            except (KeyError, TypeError, ValueError) as exc:
                raise IdentificationError(f"--identification: not an identification.json of `l1b2 identify` "
                                          f"({type(exc).__name__}: {exc})") from None
            tables["identified_vs_stick_slip"] = derive.compare_steady(pid, mp, mode="stick_slip")
            cases["identified_vs_stick_slip"] = derive.summarize(tables["identified_vs_stick_slip"])
            rng = (identification.get("checks") or {}).get("training_range")
            if rng:
                grid = tables["identified_vs_stick_slip"].assign(run=0)
                flags = outside_range(grid, rng)
                cases["identified_vs_stick_slip"]["extrapolation"] = (
                    {c: v["share_outside"] for c, v in flags[0]["outside"].items()} if flags else {})
        for key, df in tables.items():
            df.to_csv(tmp / f"{key}.csv", index=False, float_format="%.12g")
        plots.steady_comparison(tables, tmp / "predictor_vs_cosim_steady.png")
        report = {"cases": cases, "figure": str(out / "predictor_vs_cosim_steady.png"),
                  "note": "co-simulation steady states from l1b2.physics.steady.steady_state (the fixed point of the "
                          "time-domain co-simulation); relative error against the co-simulation's speed"}
        (tmp / "comparison.json").write_text(dumps(report, digits=12))
    return report


def run_frequency_map(identification: dict, out_dir, mp=None, *, frequencies_Hz=None, voltages_V=(220.0, 324.0),
                      s_m: float = 0.0, load_kg: float = 0.0, direction: int = 1) -> dict:
    """:func:`l1b2.sweep.frequency_map.frequency_map_study` written to ``out_dir``; returns its JSON report.

    Writes ``frequency_map.csv``, ``frequency_map.png`` and ``frequency_map.json``
    (the figure of agreement, :func:`l1b2.sweep.frequency_map.map_agreement`) through :func:`output_dir`.
    """
    from .physics.params import load_motor
    from .sweep.frequency_map import frequency_map_study
    res = frequency_map_study(identification, mp or load_motor(), frequencies_Hz=frequencies_Hz,
                              voltages_V=voltages_V, s_m=s_m, load_kg=load_kg, direction=direction)
    out = Path(out_dir)
    with output_dir(out, command="frequency-map") as tmp:
        res.to_pandas().to_csv(tmp / "frequency_map.csv", index=False, float_format="%.12g")
        res.figure().savefig(tmp / "frequency_map.png", dpi=120)
        report = dict(res.to_dict(), figure=str(out / "frequency_map.png"), table=str(out / "frequency_map.csv"))
        (tmp / "frequency_map.json").write_text(dumps(report, digits=12))
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
              progress: bool = True, plots_on: bool = True, traverse=None, max_runs: int | None = None):
    """Run the study of ``spec_path`` into ``out_dir``; returns its :class:`l1b2.sweep.result.SweepResult`.

    Resumable: every finished chunk is written at once, atomically, to
    ``out_dir/chunks/chunk-NNNNN.parquet``; the same command run again skips
    the chunks stored (a folder holding another study's chunks is refused).
    At the end: ``samples.parquet`` (every sample's parameters and outputs,
    in sample-id order), ``summary.csv``, ``sensitivity.csv`` (+ ``sobol.csv``),
    ``study.json`` and PNGs. ``workers=0`` runs in this process, otherwise
    a local Dask cluster of ``workers`` processes or the one at ``scheduler``.
    For the FMU engine the FMUs are built (or found in the cache) once, here.
    A study of more than ``max_runs`` runs (default
    :data:`l1b2.sweep.spec.DEFAULT_MAX_RUNS`) is refused before anything is
    drawn (:func:`l1b2.sweep.spec.check_size`).
    """
    import time

    from tqdm import tqdm

    from .cluster import optional_client
    from .errors import SpecError
    from .fmi.cache import ensure_fmus
    from .physics.params import load_motor
    from .sweep import runner
    from .sweep.result import SweepResult
    from .sweep.sampling import draw_samples
    from .sweep.spec import DEFAULT_MAX_RUNS, check_size, motor_reference, parse_spec
    from .sweep.tasks import TaskContext
    spec_path, out = Path(spec_path), Path(out_dir)
    # resumable, so written in place (not through output_dir): never into another command's result,
    # the current folder or a folder holding the spec
    _check_target(out, KNOWN_OUTPUTS["sweep"], "sweep", (spec_path,))
    try:
        text = spec_path.read_text()
    except OSError as exc:
        raise SpecError(f"{spec_path}: cannot read the study ({exc.strerror})") from None
    ref = motor_reference(text, str(spec_path))
    mp = load_motor(spec_path.parent / ref if ref else None)
    spec = parse_spec(text, str(spec_path), mp)
    size = check_size(spec, DEFAULT_MAX_RUNS if max_runs is None else max_runs, str(spec_path))  # before drawing
    if progress:
        print(f"study: {size['runs']} runs ({size['samples']} samples x {size['runs'] // size['samples']} operating "
              f"points), at most {size['steps_per_run']} steps each, up to {size['cpu_hours']:.2g} CPU hours")
    samples = draw_samples(spec)
    bounds = runner.chunk_bounds(len(samples), spec.chunk_size)
    chunks_dir = out / "chunks"
    done = _stored_chunks(chunks_dir, spec.fingerprint(), len(bounds))
    ctx = TaskContext.from_spec(spec, mp, ensure_fmus() if spec.engine == "fmu" else None)
    skipped = sum(b - a for cid, (a, b) in enumerate(bounds) if cid in done)
    t0 = time.perf_counter()
    with optional_client(workers, scheduler) as client:
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
            "worker_seconds_per_traverse": round((t2 - t1) * n_workers / run, 4) if run else None,
            "estimate": size}
    res = SweepResult(table, spec, ctx, info)
    res.save(out, plots=plots_on)
    return res
def export_calibrated_model(model, out_dir, mp=None, *, test=None, test_prediction=None) -> dict:
    """Write ``Predictor.fmu`` with a calibrated extended model into ``out_dir`` (all at once); the manifest.

    With ``test`` (held-out :class:`~l1b2.data.measurements.Measurements`)
    and a calibrated SSP exported, the manifest also gets ``held_out_check``
    (:func:`held_out_check`: free-run nrmse on TEST of the extended predictor,
    given as ``test_prediction`` [m/s per sample], of the calibrated SSP and of
    the uncalibrated one) and ``held_out_ssp.png`` is drawn.
    """
    from .fmi.export import CALIBRATED_MANIFEST, export_calibrated, write_manifest
    from .physics.params import load_motor
    mp = mp or load_motor()
    with output_dir(Path(out_dir), command="export-calibrated") as tmp:
        manifest = export_calibrated(model, tmp, mp=mp)
        if test is not None and manifest["calibrated_ssp"]["included"]:
            check, fig = held_out_check(tmp, test, mp, test_prediction)
            manifest["held_out_check"] = check
            plots.save_figure(fig, tmp / "held_out_ssp.png")
            write_manifest(tmp / CALIBRATED_MANIFEST, manifest)
    return manifest


def export_close_loop(result, out_dir, mp=None, *, test=None) -> dict:
    """Write a close-loop result's final model (``result.calibrated_model``) as ``Predictor.fmu``; the manifest.

    :func:`export_calibrated_model` of the result's model (effects with a
    physical home also go into ``L1B2Motor_calibrated.ssp`` of ``mp``,
    default the reference motor; with ``test``, its held-out check against
    the result's own TEST prediction). Raises :class:`OutputError` when there
    is nothing to export (``result.calibrated_note`` says why).
    """
    if result.calibrated_model is None:
        raise OutputError(f"{out_dir}: nothing to export: {result.calibrated_note or 'no extended model'}")
    return export_calibrated_model(result.calibrated_model, out_dir, mp=mp, test=test,
                                   test_prediction=result.test_free_run_after if test is not None else None)


def held_out_check(export_dir, test, mp, test_prediction=None) -> tuple[dict, object]:
    """TEST's free-run error of the calibrated SSP in ``export_dir``, of the uncalibrated one and of the predictor.

    The uncalibrated SSP has the same FMUs with the parameter set of ``mp``
    (the motor before calibration). Every TEST run is replayed from rest at its
    first position (:func:`l1b2.rig.replay.replay_runs`, communication step:
    the data's sample period, at most 1 ms). Returns ``(check, figure)``:
    the nrmse [1] on TEST's evaluation mask of each, and a matplotlib figure
    of the first TEST run.
    """
    from .cosim import ssp
    from .fmi.build import SUBSYSTEM_FMUS
    from .fmi.export import CALIBRATED_SSP
    from .rig.replay import replay_runs
    export_dir = Path(export_dir)
    df = test.df
    v = df[dataio.SPEED].to_numpy(float)
    dt = float(np.median(np.diff(df[dataio.TIME].to_numpy(float))))
    step = min(dt, 1e-3) if dt > 0 else 1e-3
    v_cal = replay_runs(export_dir / CALIBRATED_SSP, df, mp, step_s=step)
    with tempfile.TemporaryDirectory(prefix="l1b2_uncal_") as td:
        unc = ssp.build_ssp(Path(td) / "uncalibrated.ssp",
                            {n: export_dir / "fmus" / f"{n}.fmu" for n in SUBSYSTEM_FMUS}, mp=mp)
        v_unc = replay_runs(unc, df, mp, step_s=step)
    out = {"step_s": step, "runs": int(df[dataio.RUN].nunique()), "samples": int(test.mask.sum()),
           "calibrated_ssp_nrmse": speed_metrics(v_cal, v, test.mask)["nrmse"],
           "uncalibrated_ssp_nrmse": speed_metrics(v_unc, v, test.mask)["nrmse"],
           "extended_predictor_nrmse": (speed_metrics(test_prediction, v, test.mask)["nrmse"]
                                        if test_prediction is not None else None)}
    plt = plots.pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    run0, first = dataio.run_slices(df[dataio.RUN])[0]
    t = df[dataio.TIME].to_numpy(float)[first]
    what = plots.data_speed_label(bool(test.meta.get("speed_derived")))
    ax.plot(t, 1e3 * v[first], "k.", ms=2, label=f"{what} (TEST)")
    if test_prediction is not None:
        ax.plot(t, 1e3 * np.asarray(test_prediction)[first], label="extended predictor")
    ax.plot(t, 1e3 * v_cal[first], label="calibrated SSP (4 FMUs)")
    ax.plot(t, 1e3 * v_unc[first], "--", label="uncalibrated SSP")
    g0 = df.iloc[first]
    ax.set(xlabel="time [s]", ylabel="speed [mm/s]",
           title=f"held-out run {run0} (the first of {out['runs']}): V0 {g0[dataio.VOLTAGE].iloc[0]:g} V, "
                 f"load {g0[dataio.LOAD].iloc[0]:+g} kg, dir {int(g0[dataio.DIRECTION].iloc[0]):+d}; free run")
    ax.legend()
    return out, fig


def export_from_report(report_dir, out_dir, mp=None) -> dict:
    """``l1b2 export --from-report``: the calibrated model of a close-loop ``report.json``, exported.

    The report is read through :meth:`l1b2.closeloop.result.CloseLoopResult.from_dict`
    and exported by :func:`export_close_loop`.
    """
    from .closeloop.report import ReportFormatError
    from .closeloop.result import CloseLoopResult
    from .predictor.effects import EffectSpecError
    path = Path(report_dir) / "report.json"
    if not path.is_file():
        raise OutputError(f"{path}: no close-loop report here (run 'l1b2 close-loop ... --report-dir {report_dir}')")
    try:
        rep = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise OutputError(f"{path}: not a readable report.json ({exc})") from None
    try:
        result = CloseLoopResult.from_dict(rep)
    except (ReportFormatError, EffectSpecError) as exc:
        raise OutputError(f"{path}: {exc}") from None
    if result.calibrated_model is None:
        raise OutputError(f"{path}: field 'calibrated_model' is empty"
                          + (f" ({result.calibrated_note})" if result.calibrated_note else ""))
    return export_close_loop(result, out_dir, mp=mp)


def run_close_loop(train_path, test_path, out_dir, *, slider_mass_kg=None, plots_on=True, progress=None,
                   allow_unusual_units=False, export_dir=None, motor=None, workers=0, scheduler=None,
                   test_abs_loads=TEST_ABS_LOADS, **settings):
    """Close the loop on TRAIN/TEST files; write ``report.json``, ``report.md`` and the PNGs into ``out_dir``.

    The output folder is checked and locked first (:func:`output_dir`); both
    files are loaded and validated (slider mass: ``slider_mass_kg`` or
    TRAIN's sidecar; unit plausibility unless ``allow_unusual_units``)
    before any fit. Without ``test_path``, TEST is the runs of TRAIN's file with
    ``|load|`` in ``test_abs_loads`` (the paper's split, as :func:`load_train_test`;
    none: no held-out report); the report's ``checks.split`` says which.
    :class:`l1b2.closeloop.loop.CloseLoop` runs with
    ``settings`` (``order``, ``k_folds``, ``alpha``, ``min_gain``, ``seed``,
    ``n_starts``, ``max_rounds``, ``min_cv_gain``, ``min_cv_drop``, ``screen_alpha``, ``noise_fit``, ``noise``,
    ``refit_repeats``, ``clock_folds``, ``library``, ...: the fields of
    :class:`~l1b2.closeloop.settings.LoopSettings`); the result,
    with the data checks (TEST runs outside TRAIN's range flagged), is saved
    all at once. ``export_dir``: also write ``Predictor.fmu`` carrying the
    final model there, and the calibrated SSP of ``motor`` (default: the
    reference motor) with its held-out check (:func:`export_calibrated_model`). The cross-validated
    refits run on a local Dask cluster of ``workers`` processes (0 or 1: in this process) or on the one at
    ``scheduler`` (:func:`l1b2.cluster.dask_client`). Returns the
    :class:`~l1b2.closeloop.result.CloseLoopResult`; its ``wall_time_s``
    counts loading and the fit.
    """
    from .closeloop.loop import CloseLoop
    from .cluster import optional_client
    t_start = time.perf_counter()
    with output_dir(Path(out_dir), command="close-loop", inputs=(train_path, test_path)) as tmp:
        train, test, split = load_train_test(train_path, test_path, test_abs_loads=test_abs_loads,
                                             slider_mass_kg=slider_mass_kg, allow_unusual_units=allow_unusual_units)
        with optional_client(workers or 0, scheduler, serial_up_to=1) as client:
            result = CloseLoop(progress=progress, client=client, **settings).fit(train, test).result_
        result = dataclasses.replace(result, wall_time_s=round(time.perf_counter() - t_start, 2),
                                     checks={"split": split, **input_checks(train, test)})
        if plots_on and progress is not None:
            progress("plots")
        result.save(tmp, plots_on=plots_on)
    if export_dir is not None:
        if result.calibrated_model is None:
            raise OutputError(f"--export {export_dir}: nothing to export: {result.calibrated_note}")
        if progress is not None:
            progress(f"exporting the calibrated model to {export_dir}")
        export_calibrated_model(result.calibrated_model, export_dir, mp=motor, test=test,
                                test_prediction=result.test_free_run_after)
    return result


def run_study(study: str, out_dir, seeds, *, world=None, injections=None, workers: int | None = 2,
              scheduler: str | None = None, clean_fit: bool = True, fit=None, loop_settings: dict | None = None,
              plots_on: bool = True, progress=None):
    """A multi-seed study (:mod:`l1b2.study`) into ``out_dir``; returns its :class:`l1b2.study.result.StudyResult`.

    Writes ``study.json`` (settings, engine figures, summary and rows; strict
    JSON), ``rows.csv`` (one row per seed) and ``study_<study>.png``, all at
    once (:func:`output_dir`). The seeds run on a local Dask cluster of
    ``workers`` single-thread processes, on the cluster at ``scheduler``, or in
    this process with ``workers=0``.
    """
    from .cluster import optional_client
    from .study.recovery import FitSettings
    from .study.runner import run_study as run
    from .study.runner import study_tasks
    from .study.world import World
    world = world or World()
    fit = fit or FitSettings()
    study_tasks(study, seeds, world, injections)  # refuse a bad study before any output folder or cluster
    with output_dir(out_dir, command="study") as tmp:
        with optional_client(workers, scheduler) as client:
            res = run(study, seeds, world=world, injections=injections, client=client, clean_fit=clean_fit,
                      fit=fit, loop_settings=loop_settings, progress=progress)
        (tmp / "study.json").write_text(dumps(res.to_dict()))
        res.to_pandas().to_csv(tmp / "rows.csv", index=False)
        if plots_on:
            import matplotlib.pyplot as plt
            fig = res.figure()
            fig.savefig(tmp / f"study_{study}.png", dpi=110)
            plt.close(fig)
    return res
