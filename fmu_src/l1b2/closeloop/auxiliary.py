"""Auxiliary columns made usable as candidate channels: booleans, text labels and gaps.

A rig's log carries, beside the required columns, whatever its engineers chose: numbers, but also flags written as
``True``/``False``, labels written as text (an operator, a fixture, a batch) and sensors sampled more slowly than
the DAQ, whose column is empty between their readings. The candidate channels
(:func:`l1b2.closeloop.candidates.channels_of`) are numeric and finite; this module derives that form from the
others, on copies of the frames, before the loop looks at them, and records what it did with every column it
touched, so that nothing is dropped silently:

- **flag** (boolean column): read as 0/1.
- **label** (text column, or numbers mixed with more than :data:`MAX_TOKEN_SHARE` unparsable entries): each TRAIN
  run must hold one value (a label that varies within a run has no run-level reading and is left out). Its
  ``L`` distinct values in TRAIN are coded ``0 .. L-1`` in sorted order. Two values are a binary channel (kind
  ``"logged"``: every form of a 0/1 indicator is meaningful); a value TEST holds that TRAIN never had is then coded
  as TRAIN's run average of the codes (strictly between 0 and 1: the average run). More values are kind
  ``"label"``: the codes have no order, so only the categorical run-level family
  (:mod:`l1b2.predictor.effects.category`) and the event clock read them; an unseen value is coded -1, which the
  categorical family reads as TRAIN's average (no level).
- **filled** (numbers with gaps: empty cells, ``NaN``, ``inf`` or a minority of unparsable tokens): within each run
  the missing samples are interpolated linearly in ``time_s`` between the run's finite readings and held
  constant before the first and after the last, as a sensor read at a lower rate than the DAQ is. A TRAIN run with
  no finite reading makes the column unusable (no value can be assumed where the model is fitted); a TEST run with
  none takes TRAIN's mean and is counted.
- **unusable**: every other column beyond the required ones (all empty, a label that varies within a run, more
  distinct labels than :data:`MAX_LABELS`): left out of the candidates and listed with the reason.

Columns that are already numeric and finite are not touched (no copy is made when no column needs a change).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..data.gaps import fill_gaps
from ..errors import DataFormatError
from ..units import SETTING_SUFFIX

__all__ = ["MAX_LABELS", "MAX_TOKEN_SHARE", "LABELS_ATTR", "DERIVED_ATTR", "derived_columns", "with_usable_channels",
           "label_codes", "label_columns", "check_test_columns"]

#: the most distinct text values a label column may have over TRAIN's runs to be coded
MAX_LABELS = 12
#: the largest share of a column's non-empty entries that may fail to parse as numbers for it to be read as
#: numbers with gaps (above it: text)
MAX_TOKEN_SHARE = 0.5
#: the frames' ``attrs`` key naming the coded label columns of more than two values (kind ``"label"``)
LABELS_ATTR = "l1b2_label_columns"


def label_columns(df: pd.DataFrame) -> tuple:
    """The columns of ``df`` that :func:`with_usable_channels` coded as labels of more than two values."""
    return tuple(df.attrs.get(LABELS_ATTR, ()))


#: the frames' ``attrs`` key naming the channels the loop derived from the log
#: (:func:`l1b2.closeloop.derived.with_protocol_channels`)
DERIVED_ATTR = "l1b2_derived_columns"


def derived_columns(df: pd.DataFrame, settings: bool = True) -> tuple:
    """The columns of ``df`` that :func:`l1b2.closeloop.derived.with_protocol_channels` derived from the log;
    without the run settings when ``settings`` is False (``X_setting``, :mod:`l1b2.closeloop.runsetting`: a setting
    read through a reading the motion makes in part, read as a logged setting is)."""
    cols = tuple(df.attrs.get(DERIVED_ATTR, ()))
    return cols if settings else tuple(c for c in cols if not str(c).endswith(SETTING_SUFFIX))


#: The columns that are never auxiliary (candidate) channels: the required ones (the plan, the run id and the
#: clock; the clock is the session's own signal) and the measured speed (the output).
NOT_CANDIDATES: frozenset = frozenset(dataio.REQUIRED_COLUMNS) | {dataio.SPEED}


def varies_within_runs(df: pd.DataFrame, name: str) -> bool:
    """Whether the numeric column ``name`` takes more than one value inside some run of ``df``."""
    return bool((df.groupby(dataio.RUN, sort=False)[name].agg(np.ptp) > 0).any())


def _first_row(bad: np.ndarray) -> int | None:
    """The first flagged sample as a 1-based data row of the file (header excluded, as in
    :class:`l1b2.errors.DataFormatError`), or None."""
    idx = np.flatnonzero(bad)
    return int(idx[0]) + 1 if idx.size else None


def label_codes(train_runs: pd.Series, test_values: pd.Series | None = None) -> tuple[dict, float]:
    """``(codes, unseen)``: the code of each TRAIN label (``0 .. L-1`` in sorted order of the labels' text) and the
    code of any label TRAIN never had: with two labels TRAIN's run average of the codes, with more -1 (no level).
    ``train_runs``: one label per TRAIN run."""
    labels = sorted(set(train_runs.astype(str)))
    codes = {lab: float(j) for j, lab in enumerate(labels)}
    unseen = float(np.mean([codes[str(x)] for x in train_runs])) if len(codes) <= 2 else -1.0
    return codes, unseen


def _as_numbers(col: pd.Series) -> tuple[pd.Series | None, int]:
    """The column as floats (unparsable entries NaN) and the count of unparsable non-empty entries, or
    ``(None, n)`` when more than :data:`MAX_TOKEN_SHARE` of the non-empty entries fail to parse (a text column)."""
    if pd.api.types.is_bool_dtype(col):
        return col.astype(float), 0
    if pd.api.types.is_numeric_dtype(col):
        return col.astype(float), 0
    present = col.notna() & (col.astype(str).str.strip() != "")
    num = pd.to_numeric(col.where(present), errors="coerce")
    tokens = int((present & num.isna()).sum())
    n = int(present.sum())
    if n == 0 or tokens > MAX_TOKEN_SHARE * n:
        return None, tokens
    return num.astype(float), tokens


def _label(train: pd.DataFrame, test, name: str) -> tuple[dict, np.ndarray | None, np.ndarray | None]:
    """A text column's record and coded columns (None when unusable)."""
    text = train[name].where(train[name].notna(), "").astype(str).str.strip()
    per_run = text.groupby(train[dataio.RUN], sort=False)
    varies = per_run.nunique() > 1
    if varies.any():
        run = varies.index[np.flatnonzero(varies.to_numpy())[0]]
        return ({"channel": name, "action": "unusable", "first_row": _first_row((train[dataio.RUN] == run).to_numpy()),
                 "note": f"text that varies within a run (first: run {run}): no run-level value"}, None, None)
    run_labels = per_run.first()
    codes, unseen = label_codes(run_labels)
    if len(codes) > MAX_LABELS:
        return ({"channel": name, "action": "unusable", "first_row": None,
                 "note": f"text with {len(codes)} distinct values over TRAIN's runs (more than {MAX_LABELS}): "
                         "free text, not a setting"}, None, None)
    tr = np.array(text.map(codes), dtype=float)
    te = None
    n_unseen = 0
    if test is not None and name in test.columns:
        tt = test[name].where(test[name].notna(), "").astype(str).str.strip()
        te = np.array(tt.map(codes), dtype=float)
        miss = ~np.isfinite(te)
        n_unseen = int(tt[miss].nunique())
        te[miss] = unseen
    rec = {"channel": name, "action": "label", "first_row": None, "codes": codes, "unseen_code": unseen,
           "kind": "logged" if len(codes) <= 2 else "label",
           "note": (f"text read as {len(codes)} coded values ({', '.join(f'{k}={int(v)}' for k, v in codes.items())})"
                    + (f"; {n_unseen} value(s) of TEST not in TRAIN coded as TRAIN's average {unseen:.3g}"
                       if n_unseen else ""))}
    return rec, tr, te


def _numbers(train, test, name, num_tr: pd.Series, tokens: int) -> tuple[dict, np.ndarray | None, np.ndarray | None]:
    """A numeric column with gaps, or a flag: its record and filled columns (None when unusable)."""
    flag = pd.api.types.is_bool_dtype(train[name])
    raw = num_tr.to_numpy(float)
    bad = ~np.isfinite(raw)
    tr, empty = fill_gaps(raw, train[dataio.TIME], train[dataio.RUN])
    if empty:
        return ({"channel": name, "action": "unusable", "first_row": _first_row(bad),
                 "note": f"no finite value in {len(empty)} TRAIN run(s) (first: run {empty[0]})"}, None, None)
    te, n_te_empty, te_bad = None, 0, 0
    if test is not None and name in test.columns:
        num_te, _ = _as_numbers(test[name])
        if num_te is None:
            num_te = pd.Series(np.nan, index=test.index)
        te_raw = num_te.to_numpy(float)
        te_bad = int((~np.isfinite(te_raw)).sum())
        te, empty_te = fill_gaps(te_raw, test[dataio.TIME], test[dataio.RUN])
        n_te_empty = len(empty_te)
        te[~np.isfinite(te)] = float(np.mean(tr))
    parts = ["true/false read as 1/0"] if flag else []
    if bad.any():
        parts.append(f"{int(bad.sum())} of {len(raw)} TRAIN samples not finite (first row {_first_row(bad)})"
                     + (f", {tokens} of them text" if tokens else "")
                     + ": interpolated in time within their run")
    if te_bad:
        parts.append(f"{te_bad} TEST samples filled the same way"
                     + (f", {n_te_empty} TEST run(s) with none given TRAIN's mean" if n_te_empty else ""))
    rec = {"channel": name, "action": "flag" if flag else "filled", "first_row": _first_row(bad),
           "kind": "logged", "filled_samples": int(bad.sum()), "note": "; ".join(parts)}
    return rec, tr, te


def with_usable_channels(train: pd.DataFrame, test: pd.DataFrame | None = None, response_columns=()):
    """``(train, test, record)``: copies of the frames in which every auxiliary column (beyond the required ones,
    the speed and the measured responses ``response_columns``) is numeric and finite, or dropped, by the rules of
    the module docstring; ``record``: one dict per column touched ``{"channel", "action" ("flag", "filled",
    "label", "unusable"), "kind" (for usable ones), "note", "first_row" (1-based data row of TRAIN's file),
    ...}``. The frames are returned unchanged (not copied) when no column needs a change."""
    skip = NOT_CANDIDATES | set(response_columns)

    def usable(df, name):
        col = df[name]
        return (pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col)
                and bool(np.all(np.isfinite(col.to_numpy(float)))))
    todo = [name for name in train.columns if name not in skip
            and not (usable(train, name) and (test is None or name not in test.columns or usable(test, name)))]
    if not todo:
        return train, test, []
    train = train.copy()
    test = test.copy() if test is not None else None
    record = []
    for name in todo:
        num, tokens = _as_numbers(train[name])
        rec, tr, te = (_label(train, test, name) if num is None else _numbers(train, test, name, num, tokens))
        record.append(rec)
        if tr is None:
            train = train.drop(columns=[name])
            if test is not None and name in test.columns:
                test = test.drop(columns=[name])
            continue
        train[name] = tr
        if te is not None:
            test[name] = te
    labels = tuple(r["channel"] for r in record if r.get("kind") == "label")
    for df in (train, test):
        if df is not None and labels:
            df.attrs[LABELS_ATTR] = labels
    return train, test, record


def check_test_columns(train, test, response_columns=()) -> None:
    """Refuse, before any fit, a TEST file that lacks an auxiliary column TRAIN logs.

    ``train``/``test``: :class:`l1b2.data.measurements.Measurements`. Every column of TRAIN beyond the required ones,
    the speed and the measured responses ``response_columns`` is a candidate channel, and an effect found in it
    can only be evaluated on TEST when TEST logs it too. Raises :class:`l1b2.errors.DataFormatError` naming TEST's
    file and the first missing column (and how many are missing)."""
    skip = NOT_CANDIDATES | set(response_columns)
    missing = [c for c in train.df.columns if c not in skip and c not in test.df.columns]
    if missing:
        more = f" (and {len(missing) - 1} more: {', '.join(missing[1:])})" if len(missing) > 1 else ""
        raise DataFormatError(test.path, missing[0], None,
                              f"missing{more}: TRAIN ({train.path}) logs it, and an effect found in it could not "
                              "be evaluated on TEST; log it in TEST too, or remove it from TRAIN")
