"""``run_level_category``: a logged run setting with a few values, each value its own run-level effect.

A logged channel that the rig holds constant within every run and that takes a few distinct values (a fixture
number, a setting from a short list) may be a *label*: each value has its own effect, not a function of the value.
Its run-level signal (:class:`RunLevelCategory`) is the vector of its centred level indicators
``x_j = 1[c = v_j] - s_j`` (:func:`category_columns`; ``v_j`` TRAIN's levels in increasing order, ``s_j`` the
share of TRAIN's runs at ``v_j``, the last level dropped), each entering as the run-level family's form
``dF = x_j (a_j V0/V_ref + b_j + c_j g d m)`` (:class:`l1b2.predictor.effects.channels.RunLevel`): ``3 (L - 1)``
parameters, ``a_j``, ``b_j`` [N] and ``c_j`` [1] per level but the last, against TRAIN's average over runs. A value
TRAIN never had gets 0 in every column, TRAIN's average (:meth:`RunLevelCategory.unseen` lists such values).

Which settings are categories (:func:`category_levels`, :meth:`RunLevelCategory.signal`): a logged channel, no
input of ``Predictor.fmu`` (an input has its own physics and signals), constant within every run, with
:data:`CATEGORY_LEVELS` distinct values over TRAIN's runs, each held by at least :data:`CATEGORY_MIN_RUNS` runs.

Every hypothesis of this family reads a logged channel: ``Predictor.fmu`` reads it through the channel's own input
(:func:`l1b2.predictor.effects.channels.channel_inputs`), its current value taken as the run's level (the
run-level contract of :func:`l1b2.predictor.effects.channels.export_problem`); a value that is none of TRAIN's
levels gets TRAIN's average over runs. The family has no per-sample kernel: its models stay Python FMUs (no
native one).
"""

from __future__ import annotations

import numpy as np

from .base import Effect, EffectSpecError, num, register, signal
from .channels import INPUT_COLUMNS, regressor_of, run_level_columns, run_spread_entry, signal_key

#: the run-level transform name of a categorical signal (beside
#: :data:`l1b2.predictor.effects.channels.TRANSFORMS`: its columns are the centred level indicators, not a
#: transformed value)
CATEGORY = "category"
#: the number of distinct TRAIN run values of a logged run setting that make it also a category: two values are a
#: line (the linear signal spans their indicator), and beyond six the categorical form's 3 (L - 1) parameters
#: outgrow the runs per value of a session of some tens of runs (and a setting that fine is more likely a quantity,
#: which the value's own forms take)
CATEGORY_LEVELS = (3, 6)
#: the fewest TRAIN runs holding each value: a value of one run is confounded with that run's own random deviation
CATEGORY_MIN_RUNS = 2
#: a sample's value matches a level within this share of the levels' largest size (a run mean of a constant is
#: the constant to rounding)
CATEGORY_RTOL = 1e-9


def category_levels(run_values) -> tuple | None:
    """``(levels, shares)`` of a logged run setting taken as a category, or None when it is not one.

    ``run_values``: one value per TRAIN run (the setting constant within every run). A category has
    :data:`CATEGORY_LEVELS` distinct values, each held by at least :data:`CATEGORY_MIN_RUNS` runs; ``levels`` are
    the values in increasing order, ``shares`` the runs' shares of every level but the last (the dropped one).
    """
    v = np.asarray(run_values, float)
    if len(v) == 0 or not np.all(np.isfinite(v)):
        return None
    levels, counts = np.unique(v, return_counts=True)
    lo, hi = CATEGORY_LEVELS
    if not lo <= len(levels) <= hi or counts.min() < CATEGORY_MIN_RUNS:
        return None
    return tuple(float(x) for x in levels), tuple(float(c) / len(v) for c in counts[:-1])


def category_spec(levels, shares) -> dict:
    """A category's scalars in a spec: ``n_levels``, ``level_0..level_{L-1}``, ``share_0..share_{L-2}``."""
    out = {"n_levels": len(levels)}
    out.update({f"level_{j}": float(v) for j, v in enumerate(levels)})
    out.update({f"share_{j}": float(s) for j, s in enumerate(shares)})
    return out


def category_of(spec) -> tuple:
    """``(levels, shares)`` of a categorical spec (:func:`category_spec`)."""
    n = int(num(spec, "n_levels"))
    if n < 2:
        raise EffectSpecError(f"categorical signal {spec.get('channel')!r}: {n} levels")
    return tuple(num(spec, f"level_{j}") for j in range(n)), tuple(num(spec, f"share_{j}") for j in range(n - 1))


def _matches(c, levels) -> np.ndarray:
    """``(n, L)``: each value against each level, within :data:`CATEGORY_RTOL`."""
    lv = np.asarray(levels, float)
    tol = CATEGORY_RTOL * max(1.0, float(np.max(np.abs(lv))))
    return np.abs(np.asarray(c, float)[:, None] - lv[None, :]) <= tol


def category_columns(c, levels, shares) -> np.ndarray:
    """The centred indicators of a category, ``(n, L - 1)``: ``1[c = v_j] - s_j`` for every level but the last;
    a value that is none of TRAIN's levels gets 0 in every column (TRAIN's average over runs, see
    :func:`unseen_levels`)."""
    hit = _matches(c, levels)
    out = hit[:, :-1].astype(float) - np.asarray(shares, float)[None, :]
    out[~hit.any(axis=1)] = 0.0
    return out


def unseen_levels(spec, c) -> list:
    """The distinct values of ``c`` that are none of a categorical spec's TRAIN levels (their runs get TRAIN's
    average over runs: the effect cannot tell them; a report flags them)."""
    c = np.asarray(c, float)
    levels, _ = category_of(spec)
    return sorted(float(x) for x in np.unique(c[~_matches(c, levels).any(axis=1)]))


def level_tag(v: float) -> str:
    """A level's value in a parameter name: ``is_3``, ``is_2p5``, ``is_m1`` (a legal FMI structured name's part)."""
    v = float(v)
    text = str(int(v)) if v == int(v) else f"{v:g}"
    return "is_" + text.replace("-", "m").replace(".", "p").replace("+", "")


@register
class RunLevelCategory(Effect):
    """``run_level_category``: a logged run setting's values, each its own run-level effect (module docstring).

    Not listed by any candidate library: the close loop's run-level analysis (:mod:`l1b2.closeloop.runlevel`)
    takes the signals :meth:`signal` makes, tests them and offers :meth:`hypotheses` of the significant ones
    (report family ``run_level_category(<column>)``).
    """

    kind = "run_level_category"
    regressor = "run"
    group = "run_level"
    signals = ("load",)
    description = ("a logged run setting's values, each scaling the drive force, adding a force and scaling the "
                   "load's force (constant along the stroke)")

    @staticmethod
    def label(column: str) -> str:
        """The report's name of a column's categorical signal, ``category(<column>)``."""
        return f"category({column})"

    @staticmethod
    def stem(column: str) -> str:
        """The stem of its parameter names, ``cat_<column>`` (a legal FMI structured name's part)."""
        return f"cat_{column}"

    def needs(self, spec):
        return super().needs(spec) | {signal_key(str(spec.get("channel")), "run")}

    def features(self, spec, x):
        """Per level ``j`` but the last, ``x_j (V0/V_ref, 1, g d m)`` with ``x_j`` its centred indicator
        (:func:`category_columns`) of the run's value, level by level."""
        levels, shares = category_of(spec)
        X = category_columns(signal(x, signal_key(str(spec.get("channel")), "run")), levels, shares)
        return run_level_columns(x, X)

    def width(self, spec):
        return 3 * (int(num(spec, "n_levels")) - 1)

    def channel_mean(self, spec):
        """TRAIN's mean over runs of the setting: ``sum_j v_j s_j`` over its levels, the last level's share
        ``1 - sum_j s_j`` (:func:`category_of`)."""
        levels, shares = category_of(spec)
        w = list(shares) + [1.0 - float(sum(shares))]
        return float(sum(v * s for v, s in zip(levels, w)))

    # -- the signal of the run-level analysis -------------------------------------------------------------------

    @staticmethod
    def takes(channel: dict) -> bool:
        """Whether a channel (:func:`l1b2.closeloop.candidates.channels_of`'s record) may be a category: logged or
        a coded text label, constant within every run and no input of ``Predictor.fmu``."""
        return (channel.get("kind") in ("logged", "label") and not channel.get("within_run", True)
                and channel["name"] not in INPUT_COLUMNS)

    def signal(self, column: str, run_values) -> dict | None:
        """The categorical signal of a setting :meth:`takes` given its value per run (run order), or None when
        the values are no category (:func:`category_levels`): ``{"channel", "transform": "category", "values",
        "levels", "shares"}``."""
        values = np.asarray(run_values, float)
        cat = category_levels(values)
        if cat is None:
            return None
        return {"channel": column, "transform": CATEGORY, "values": values, "levels": cat[0], "shares": cat[1]}

    def on_runs(self, sg: dict, keep) -> dict | None:
        """A signal of :meth:`signal` on the runs ``keep`` (indices), its levels and shares taken again on them
        (None: no longer a category)."""
        out = {**sg, "values": np.asarray(sg["values"])[keep]}
        cat = category_levels(out["values"])
        return None if cat is None else {**out, "levels": cat[0], "shares": cat[1]}

    def columns(self, sg: dict) -> np.ndarray:
        """A signal's columns in the run-level mean: its centred level indicators, ``(n_runs, L - 1)``."""
        return category_columns(np.asarray(sg["values"], float), sg["levels"], sg["shares"])

    def hypotheses(self, signals_: list) -> list:
        """One hypothesis per categorical signal ``{"channel", "levels", "shares"}`` (with ``run_spread`` when
        known): three parameters per level but the last, ``cat_<column>_is_<value>_run_{gain,offset,load}``."""
        out = []
        for sg in signals_:
            col, levels = sg["channel"], tuple(sg["levels"])
            tags = [level_tag(v) for v in levels[:-1]]
            names = [f"{self.stem(col)}_{t}_run_{p}" for t in tags for p in ("gain", "offset", "load")]
            label = self.label(col)
            out.append(self.hypothesis(
                names, ["N", "N", "1"] * len(tags),
                {"channel": col, **category_spec(levels, sg["shares"]), **run_spread_entry(sg)}, "run",
                family=f"run_level_{label}", regressor=regressor_of(col), generic=True,
                description=f"run-level {label}: each of its {len(levels)} values scaling the drive force, adding "
                            "a force and scaling the load's force (against the runs' average; constant along the "
                            "stroke)"))
        return out

    def grid(self, train):
        """The hypothesis of every channel of ``train`` whose summary records its category (``levels`` and
        ``shares``, :meth:`signal`). The loop does not list these: its run-level analysis offers
        :meth:`hypotheses` for the signals whose evidence is significant."""
        return self.hypotheses([ch | {"channel": ch["name"]} for ch in train.channels
                                if self.takes(ch) and "levels" in ch and "shares" in ch])

    def unseen(self, spec, run_values) -> dict | None:
        """``{"values", "runs"}``: the values of ``run_values`` (one per run) that TRAIN never had and how many
        runs hold them (those runs get TRAIN's average over runs, 0 in every level column); None when every run
        has one of TRAIN's levels."""
        v = np.asarray(run_values, float)
        values = unseen_levels(spec, v)
        return {"values": values, "runs": int(np.sum(np.isin(v, values)))} if values else None
