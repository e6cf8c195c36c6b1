"""The range a model was identified on, and the runs that lie outside it (extrapolation).

An Eq. 29 predictor is a position polynomial with voltage and load terms
fitted on TRAIN: outside TRAIN's positions the polynomials extrapolate (an
order-8 Legendre series at 2.6 x its half-width grows by ~1e5), outside its
voltages and loads the affine dependence is untested. :func:`data_range`
records TRAIN's range (it goes into ``identification.json``),
:func:`outside_range` flags, per run of any data set to be predicted, each
input that leaves it, and :func:`input_checks` is the ``checks`` section of
the identify and close-loop reports (these flags, the unit findings of
both files and the gaps filled in them). The drive frequency is a prediction input like the others
(the predictor's frequency response, :mod:`l1b2.predictor.frequency`): a
TEST run at a frequency outside TRAIN's is flagged; :func:`frequency_varies`
says whether TRAIN's frequencies spread enough to identify the response.

A run is flagged for a column when one of its samples lies further outside
the range than ``tolerance`` x the range's width (at least
:data:`MIN_TOLERANCE`, so one encoder count or rounding does not count).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..errors import DataFormatError
from .columns import file_row
from .measurements import DIRECTION, FREQUENCY, LOAD, POSITION, RUN, SPEED, TIME, VOLTAGE, Measurements, run_slices
from .gaps import gap_lines
from .metrics import level_law_lines
from .onset import onset_lines
from .plausibility import uneven_step_lines, uneven_steps

__all__ = ["RANGE_COLUMNS", "DEFAULT_TOLERANCE", "MIN_TOLERANCE", "data_range", "outside_range",
           "summarize_outside", "values_outside", "FREQUENCY_REL_SPREAD", "run_frequencies", "frequency_varies",
           "input_checks", "data_check_lines", "RIG_SETTINGS", "check_same_rig", "SHARED_SHARE", "SharedRun",
           "shared_run", "runs_of_two", "speed_source_lines", "NOISE_SDS", "channels_outside", "channel_outside_lines"]

#: The prediction inputs whose range is checked (unit in the name); a direction TRAIN never drove is outside.
RANGE_COLUMNS: tuple[str, ...] = (VOLTAGE, LOAD, POSITION, DIRECTION, FREQUENCY)
#: Share of the range's width a value may lie outside it before the run is flagged.
DEFAULT_TOLERANCE: float = 0.02
#: Spread of the runs' drive frequencies (max - min, as a share of their median) above which the frequency
#: response is identified: 0.1 % is ~50 Hz at 48.5 kHz, a fraction of the stator's resonance width, which sets
#: the force factor
FREQUENCY_REL_SPREAD: float = 1e-3
#: Smallest absolute tolerance per column (1 mV, 1 mg, 1 um, 25 Hz = half the frequency spread that counts at
#: 48.5 kHz: a TRAIN at one frequency flags TEST runs beyond it).
MIN_TOLERANCE: dict[str, float] = {VOLTAGE: 1e-3, LOAD: 1e-6, POSITION: 1e-6, DIRECTION: 1e-6, FREQUENCY: 25.0}


#: How far, in TRAIN's typical within-run standard deviation of a logged channel, a TEST run's value of it may lie
#: outside TRAIN's runs' before the run is flagged (:func:`channels_outside`): a noisy sensor's scatter is no change.
NOISE_SDS: float = 3.0


def _frame(data: pd.DataFrame | Measurements) -> pd.DataFrame:
    return data.df if isinstance(data, Measurements) else data


def data_range(data: pd.DataFrame | Measurements) -> dict[str, list[float]]:
    """``{column: [min, max]}`` of the prediction inputs (:data:`RANGE_COLUMNS`) over all samples."""
    df = _frame(data)
    return {c: [float(df[c].min()), float(df[c].max())] for c in RANGE_COLUMNS if c in df.columns}


def _outside(x: np.ndarray, lo: float, hi: float, tolerance: float, min_tolerance: float = 0.0) -> np.ndarray:
    """Which values of ``x`` lie outside ``[lo, hi]`` by more than ``tolerance`` x its width (at least
    ``min_tolerance``, in the values' unit)."""
    tol = max(tolerance * (hi - lo), min_tolerance)
    return (x < lo - tol) | (x > hi + tol)


def outside_range(data: pd.DataFrame | Measurements, train_range: Mapping[str, Any], *,
                  tolerance: float = DEFAULT_TOLERANCE) -> list[dict]:
    """Runs of ``data`` with an input outside ``train_range`` (:func:`data_range` of TRAIN).

    Returns
    -------
    list of dict
        One entry per flagged run, in file order: ``run``, and ``outside``:
        column -> ``{"min", "max"}`` (the run's extremes), ``"train"``
        ([min, max] of TRAIN) and ``"share_outside"`` (fraction of the
        run's samples outside).
    """
    df = _frame(data)
    out = []
    for rid, sl in run_slices(df[RUN]):
        flags = {}
        for col, (lo, hi) in ((c, train_range[c]) for c in RANGE_COLUMNS if c in train_range and c in df.columns):
            x = df[col].to_numpy(dtype=float)[sl]
            bad = _outside(x, float(lo), float(hi), tolerance, MIN_TOLERANCE[col])
            if bad.any():
                flags[col] = {"min": float(x.min()), "max": float(x.max()), "train": [float(lo), float(hi)],
                              "share_outside": float(bad.mean())}
        if flags:
            out.append({"run": rid, "outside": flags})
    return out


def summarize_outside(flagged: list[dict], n_runs: int) -> str:
    """One line: how many runs leave the range, in which inputs (empty when none)."""
    if not flagged:
        return ""
    per = {c: sum(c in f["outside"] for f in flagged) for c in RANGE_COLUMNS}
    cols = ", ".join(f"{c} {k}" for c, k in per.items() if k)
    return f"{len(flagged)} of {n_runs} runs outside the training range ({cols}): predictions there extrapolate"


def values_outside(train_values, test_values, test_runs, *, tolerance: float = DEFAULT_TOLERANCE) -> dict:
    """How many TEST values of one signal lie outside TRAIN's range of it (an effect of the signal extrapolates there).

    ``train_values``, ``test_values``: the signal per sample (a channel's value, or its run's value at the run
    level); ``test_runs``: each TEST sample's run id. A value is outside when it lies further outside
    ``[min, max]`` of ``train_values`` than ``tolerance`` x that range's width (the rule of
    :func:`outside_range`). Non-finite values are left out of both.

    Returns
    -------
    dict
        ``train`` and ``test`` ([min, max] of each), ``samples_outside`` (share of TEST's samples),
        ``runs_outside`` (TEST runs with a sample outside) and ``test_runs`` (TEST's runs).
    """
    tr = np.asarray(train_values, float)
    te = np.asarray(test_values, float)
    runs = np.asarray(test_runs)
    tr, ok = tr[np.isfinite(tr)], np.isfinite(te)
    te, runs = te[ok], runs[ok]
    lo, hi = float(tr.min()), float(tr.max())
    bad = _outside(te, lo, hi, tolerance)
    return {"train": [lo, hi], "test": [float(te.min()), float(te.max())] if te.size else [None, None],
            "samples_outside": float(bad.mean()) if te.size else 0.0,
            "runs_outside": int(len(np.unique(runs[bad]))), "test_runs": int(len(np.unique(runs)))}


def run_frequencies(*data: pd.DataFrame | Measurements | None) -> np.ndarray:
    """Each run's drive frequency [Hz] (median of its ``frequency_Hz``) over every data set given (empty: none).

    The loader fills ``frequency_Hz`` from the sidecar when the file has none.
    """
    return np.array([float(np.median(df[FREQUENCY].to_numpy(float)[sl]))
                     for df in (_frame(d) for d in data if d is not None)
                     if FREQUENCY in df.columns for _, sl in run_slices(df[RUN])], dtype=float)


def frequency_varies(*data: pd.DataFrame | Measurements | None) -> bool:
    """Whether the runs' drive frequencies differ by more than :data:`FREQUENCY_REL_SPREAD` of their median."""
    f = run_frequencies(*data)
    return bool(f.size and np.ptp(f) > FREQUENCY_REL_SPREAD * float(np.median(f)))


def input_checks(train: Measurements, test: Measurements | None) -> dict:
    """The report's record of the data checks: unit findings (allowed or none), the gaps of optional input columns
    filled on reading (per file and column: ``cells``, ``runs``, ``first_row``, ``first_line``), the uneven time
    steps within runs (per file, :func:`l1b2.data.plausibility.uneven_steps`, None when even), the runs at rest
    before their onset (per file, :func:`l1b2.data.onset.from_onset`'s record, None for data not read from a file),
    whether each file's speed was derived from position (``speed_derived``; TEST None without TEST), TEST runs
    outside TRAIN's range and the logged channels TEST takes outside TRAIN's (:func:`channels_outside`)."""
    rng = data_range(train)
    flagged = outside_range(test, rng) if test is not None else []
    n_test = len(test.runs) if test is not None else 0
    return {
        "allow_unusual_units": bool(train.meta.get("allow_unusual_units")),
        "unusual_units": {"train": list(train.meta.get("unusual_units", [])),
                          "test": list(test.meta.get("unusual_units", [])) if test is not None else []},
        "gaps_filled": {"train": dict(train.meta.get("gaps_filled") or {}),
                        "test": dict(test.meta.get("gaps_filled") or {}) if test is not None else {}},
        "uneven_time_steps": {"train": uneven_steps(train.df),
                              "test": uneven_steps(test.df) if test is not None else None},
        "rest_before_onset": {"train": train.meta.get("rest_before_onset"),
                              "test": test.meta.get("rest_before_onset") if test is not None else None},
        "speed_derived": {"train": bool(train.meta.get("speed_derived")),
                          "test": bool(test.meta.get("speed_derived")) if test is not None else None},
        "training_range": rng,
        "test_runs_outside_training_range": flagged,
        "channels_outside": channels_outside(train, test) if test is not None else [],
        "extrapolation": summarize_outside(flagged, n_test),
    }


def data_check_lines(checks: dict) -> list[str]:
    """The warning lines of a report's ``checks`` (:func:`input_checks`) that need the package to be worded: the
    gaps filled on reading (:func:`l1b2.data.gaps.gap_lines`), the uneven time steps
    (:func:`l1b2.data.plausibility.uneven_step_lines`), the rest before the runs' onsets
    (:func:`l1b2.data.onset.onset_lines`), the speed's source (:func:`speed_source_lines`), the logged channels
    TEST takes outside TRAIN's range (:func:`channel_outside_lines`) and an identification worse on TRAIN than the
    runs' level law (``level_law``, :func:`l1b2.data.metrics.level_law_lines`)."""
    return (gap_lines(checks.get("gaps_filled")) + uneven_step_lines(checks.get("uneven_time_steps"))
            + onset_lines(checks.get("rest_before_onset")) + speed_source_lines(checks.get("speed_derived"))
            + channel_outside_lines(checks.get("channels_outside")) + level_law_lines(checks.get("level_law")))


def speed_source_lines(derived: Mapping[str, bool | None] | None) -> list[str]:
    """A warning when TRAIN's speed is measured and TEST's derived from position, or the reverse: the TEST errors
    are then scored on another quantity (a derived speed carries no measurement noise of its own, so its one-step
    error is smaller) and do not compare with TRAIN's."""
    if not derived or derived.get("test") is None or derived["train"] == derived["test"]:
        return []
    how = {True: "derived from position_m", False: "measured (speed_m_s)"}
    return [f"TRAIN's speed is {how[derived['train']]} and TEST's {how[derived['test']]}: the TEST errors "
            "are scored on another speed than TRAIN's and do not compare with them; give both files alike"]

def channels_outside(train: pd.DataFrame | Measurements, test: pd.DataFrame | Measurements,
                     *, tolerance: float = DEFAULT_TOLERANCE) -> list[dict]:
    """The logged channels beyond the model's inputs whose values in some TEST runs TRAIN never had: no effect of
    them could be learnt there (a channel constant in TRAIN above all: the model cannot know what it does).

    Every numeric column of both frames other than the run, the clock, the speed and :data:`RANGE_COLUMNS` is read
    per run (its median). A TEST run is outside when its value lies outside ``[min, max]`` of TRAIN's runs' by more
    than the largest of ``tolerance`` x that range's width, :data:`NOISE_SDS` x TRAIN's median within-run standard
    deviation of the channel (a noisy sensor's scatter) and ``1e-9`` x the largest magnitude (rounding). Runs whose
    value is not finite are left out.

    Returns
    -------
    list of dict
        One per channel with a TEST run outside, in TEST's column order: ``channel``, ``train`` ([min, max] of
        TRAIN's run values), ``constant_in_train`` (TRAIN's run values all within the tolerance), ``test`` ([min,
        max] of the runs outside), ``runs_outside``, ``test_runs`` and ``first_run`` (the first run outside, in
        file order).
    """
    tr, te = _frame(train), _frame(test)
    skip = {RUN, TIME, SPEED, *RANGE_COLUMNS}
    out = []
    for col in te.columns:
        if col in skip or col not in tr.columns or not (pd.api.types.is_numeric_dtype(tr[col])
                                                        and pd.api.types.is_numeric_dtype(te[col])):
            continue
        a = tr.groupby(RUN, sort=False)[col].median().to_numpy(float)
        b = te.groupby(RUN, sort=False)[col].median()
        a, ok = a[np.isfinite(a)], np.isfinite(b.to_numpy(float))
        if not a.size or not ok.any():
            continue
        sd = tr.groupby(RUN, sort=False)[col].std(ddof=1).to_numpy(float)
        sd = float(np.median(sd[np.isfinite(sd)])) if np.isfinite(sd).any() else 0.0
        lo, hi = float(a.min()), float(a.max())
        scale = max(abs(lo), abs(hi), float(np.nanmax(np.abs(b.to_numpy(float)))))
        tol = max(tolerance * (hi - lo), NOISE_SDS * sd, 1e-9 * scale)
        vals = b[ok]
        bad = vals[(vals < lo - tol) | (vals > hi + tol)]
        if len(bad):
            out.append({"channel": str(col), "train": [lo, hi], "constant_in_train": bool(hi - lo <= tol),
                        "test": [float(bad.min()), float(bad.max())], "runs_outside": int(len(bad)),
                        "test_runs": int(len(vals)),
                        "first_run": getattr(bad.index[0], "item", lambda: bad.index[0])()})
    return out


def channel_outside_lines(records) -> list[str]:
    """One warning per record of :func:`channels_outside`."""
    lines = []
    for r in records or []:
        (lo, hi), (tlo, thi) = r["train"], r["test"]
        train = f"constant at {lo:.6g}" if r["constant_in_train"] else f"{lo:.6g} to {hi:.6g}"
        lines.append(f"TEST's `{r['channel']}` lies outside TRAIN's values in {r['runs_outside']} of {r['test_runs']} "
                     f"runs (TRAIN {train}, those runs {tlo:.6g} to {thi:.6g}; first run {r['first_run']}): no effect "
                     "of it could be learnt there, and the predictions assume it acts as in TRAIN")
    return lines


#: settings that describe the rig itself: TRAIN and TEST must agree on them (relative difference)
RIG_SETTINGS: dict[str, float] = {"slider_mass_kg": 1e-6, "encoder_resolution_m": 1e-6, "drive_frequency_Hz": 1e-6}


def check_same_rig(train: Measurements, test: Measurements, *, explicit: Mapping[str, Any] | None = None,
                   allow_unusual_units: bool = False) -> None:
    """Refuse TEST whose rig settings (:data:`RIG_SETTINGS`, from its sidecar) differ from TRAIN's.

    Both files are measured on one rig: a slider mass of 0.12 kg in TRAIN's
    sidecar and 0.2646 in TEST's is a unit mistake (lb) or a wrong sidecar,
    and the prediction on TEST would silently use TEST's value. Settings
    given as options (``explicit``) apply to both and are not compared.
    Raises :class:`~l1b2.errors.DataFormatError` naming TEST's sidecar and
    the field. A TEST whose load effect per kg differs from TRAIN's
    (:func:`l1b2.data.plausibility.load_effect_mismatch`: loads in another
    unit) is refused too, unless ``allow_unusual_units`` (then it is listed
    in TEST's ``unusual_units``).
    """
    explicit = explicit or {}
    shared = shared_run(train, test)
    if shared is not None:
        what = (f"is TRAIN run {shared.train_run} (the same recorded samples)" if shared.same
                else f"shares {shared.shared} of its {shared.samples} samples with TRAIN run {shared.train_run} (the "
                     "same time stamp, position and speed; the first at this row)")
        raise DataFormatError(test.meta.get("source") or "TEST", RUN, shared.row,
                              f"TEST run {shared.run} {what}: a held-out run must not be in TRAIN, or the TEST error "
                              "is a training error (the same file given twice, or TEST cut from the TRAIN file?)")
    from .plausibility import load_effect_mismatch, run_table
    found = load_effect_mismatch(run_table(train.df), run_table(test.df))
    if found is not None:
        where = test.meta.get("source") or "TEST"
        row = file_row(test.df, found.row)
        if not allow_unusual_units:
            raise DataFormatError(where, found.column, row,
                                  found.text + " (if the values are right, allow them with --allow-unusual-units)")
        test.meta.setdefault("unusual_units", []).append(str(DataFormatError(where, found.column, row, found.text)))
    for name, rel in RIG_SETTINGS.items():
        if explicit.get(name) is not None:
            continue
        a, b = train.meta.get(name), test.meta.get(name)
        if a is None or b is None:
            continue
        a, b = float(a), float(b)
        if abs(a - b) > rel * max(abs(a), abs(b)):
            where = test.meta.get("sidecar") or test.meta.get("source") or "TEST"
            ratio = b / a if a else float("inf")
            hint = " (lb?)" if name == "slider_mass_kg" and abs(ratio - 2.2046) < 0.01 else ""
            raise DataFormatError(where, name, None,
                                  f"TEST says {name} = {b:.6g} but TRAIN ({train.meta.get('sidecar') or 'defaults'}) "
                                  f"says {a:.6g}{hint}: both files must come from one rig; correct the sidecar or "
                                  "give the value as an option")


#: the share of a TEST run's samples that are TRAIN samples from which the run is refused (:func:`shared_run`)
SHARED_SHARE: float = 0.5


class SharedRun(NamedTuple):
    """A TEST run that shares samples with TRAIN (:func:`shared_run`)."""

    #: the TEST run
    run: Any
    #: the 1-based data row of its first sample that is a TRAIN sample (the file's row: the frame's index + 1)
    row: int
    #: the TRAIN run that holds most of the shared samples (the first such run in TRAIN's order on a tie)
    train_run: Any
    #: how many of the TEST run's samples are TRAIN samples
    shared: int
    #: the TEST run's samples
    samples: int
    #: whether the TEST run is that TRAIN run whole: every sample of each is a sample of the other
    same: bool


def shared_run(train: Measurements, test: Measurements, share: float = SHARED_SHARE) -> SharedRun | None:
    """The first TEST run (file order) at least ``share`` of whose samples are TRAIN samples, or ``None``.

    A sample is a TRAIN sample when a TRAIN sample has the same ``time_s``, ``position_m`` and, when both files
    log it (neither speed derived from position), ``speed_m_s``, each equal. The clock runs on over a rig's
    experiment, so two traverses never share their stamps, and a measured speed carries its own noise: two
    simulated runs of one plan may share stamps and positions, never a measured speed, and share no sample. A
    speed derived from position adds nothing to the stamp and the position, which then decide alone. A few
    samples may still repeat between two recordings by chance (a clock restarted at 0 in each file, a slider at
    rest at one encoder count), never most of a run; whereas a TEST run cut from a TRAIN run, or one whose
    export dropped or reordered rows, shares all its samples. Hence the threshold :data:`SHARED_SHARE`, half the
    run: any share from a few samples to nearly all would separate the two cases.

    Vectorised: TEST's samples whose stamp is one of TRAIN's (``numpy.isin``), then a hash join of those on all
    the columns compared.
    """
    measured = not (train.meta.get("speed_derived") or test.meta.get("speed_derived"))
    cols = ["time_s", POSITION] + ([SPEED] if measured and SPEED in train.df and SPEED in test.df else [])
    tr, te = train.df, test.df
    t_tr, t_te = tr["time_s"].to_numpy(float), te["time_s"].to_numpy(float)
    cand = np.flatnonzero(np.isin(t_te, t_tr))                     # TEST samples at one of TRAIN's stamps
    if cand.size == 0:
        return None
    keep = np.flatnonzero(np.isin(t_tr, t_te[cand]))               # and the TRAIN samples at theirs
    left = pd.DataFrame({c: te[c].to_numpy(float)[cand] for c in cols})
    right = pd.DataFrame({c: tr[c].to_numpy(float)[keep] for c in cols}).assign(_train_pos=keep)
    right = right.drop_duplicates(cols, keep="first")              # one match per sample, TRAIN's first
    hit = left.merge(right, on=cols, how="left", sort=False)["_train_pos"].to_numpy(float)   # NaN: no match
    pos, train_pos = cand[np.isfinite(hit)], hit[np.isfinite(hit)].astype(np.int64)
    slices = run_slices(te[RUN])
    starts = np.array([sl.start for _, sl in slices], dtype=np.int64)
    sizes = np.array([sl.stop - sl.start for _, sl in slices], dtype=np.int64)
    counts = np.bincount(np.searchsorted(starts, pos, side="right") - 1, minlength=len(starts))
    over = np.flatnonzero((counts > 0) & (counts >= share * sizes))
    if over.size == 0:
        return None
    i = int(over[0])
    rid, sl = slices[i]
    mine = (pos >= sl.start) & (pos < sl.stop)
    n, k, where = int(sizes[i]), int(counts[i]), train_pos[mine]
    tr_runs = tr[RUN].to_numpy()
    runs, first, per_run = np.unique(tr_runs[where], return_index=True, return_counts=True)
    best = min(range(len(runs)), key=lambda j: (-per_run[j], where[first[j]]))
    same = bool(k == n == per_run[best] == np.count_nonzero(tr_runs == runs[best]))
    return SharedRun(rid, file_row(te, pos[mine][0]), runs[best], k, n, same)


def runs_of_two(m: Measurements, path) -> Measurements:
    """``m`` when each run holds at least 2 samples (Eq. 29 predicts a sample from the one before it), else a
    :class:`~l1b2.errors.DataFormatError` naming the file, the run and its first row
    (:func:`~l1b2.data.columns.file_row`)."""
    for rid, sl in run_slices(m.df[RUN]):
        if sl.stop - sl.start < 2:
            raise DataFormatError(path, RUN, file_row(m.df, sl.start),
                                  f"run {rid} has a single sample: a run is one traverse, and the predictor needs "
                                  "at least 2 samples of it (a run cut by the export? leave it out)")
    return m
