"""Whole-file physical plausibility of measured data: what no single column shows.

Each check compares the runs of one file with the physics of a linear
ultrasonic motor on a pulley rig (docs/data-format.md, the load convention):

* **gravity's sign** (:func:`load_sign_finding`): a positive ``load_kg``
  pulls toward -position, so along a run's drive direction it adds the
  force ``-load_kg * g * direction``. Among runs at the same voltage and
  direction, the steady speed along the direction must therefore fall as
  ``load_kg * direction`` grows. A significant rise (t > 3) means the load's
  sign convention is reversed.
* **runs whose inputs contradict their own speed** (:func:`contradiction_finding`):
  a run moving against its direction although its load does not pull that
  way (direction flipped?); a run driven below the lowest plausible voltage
  that still traverses in its drive direction without a load pulling it
  there (a zeroed voltage?).
* **clock jumps** (:func:`clock_jump_finding`): within a run (one continuous
  traverse) a time step of more than :data:`CLOCK_JUMP_FACTOR` times the
  run's median step and at least :data:`MIN_CLOCK_JUMP_S`.
* **uneven time steps** (:func:`uneven_steps`, a note, not a refusal): a
  DAQ samples on its own clock, so within a run every step of ``time_s`` is
  the same up to the column's written resolution. Steps that differ from
  the run's median by more than :data:`UNEVEN_STEP_SHARE` of it come from
  stamps given on arrival (a USB or network host) or a logger that drops
  samples; a speed derived over such stamps is off by the same share. A
  speed sample far from its neighbours beside such steps is not refused as
  a glitch when the stamps explain it (:func:`speed_glitch`).
* **temperature scale** (:func:`temperature_finding`): a stator that never
  comes near room temperature (coolest sample above
  :data:`MAX_COOLEST_TEMPERATURE_C`) is more likely recorded in degF.
* **load scale** (:func:`load_scale_finding`): a load heavier than the
  slider itself is more likely in N, lb or scaled by 10.

They are likely mistakes, not impossibilities: the reader refuses them
unless unusual values are allowed (``--allow-unusual-units``), like the
per-column plausibility ranges.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from .columns import DIRECTION, LOAD, PLAUSIBLE, RUN, SPEED, TEMPERATURE, TIME, VOLTAGE
from .stamps import regular_clock_derivative

#: standard gravity [m/s^2]
GRAVITY_M_S2 = 9.80665
#: a run's steady speed along its direction at least this is a traverse [m/s] (the metrics' threshold)
MIN_TRAVERSE_SPEED_M_S = 5e-3
#: a time step within a run more than this many times the run's median step is a clock jump ...
CLOCK_JUMP_FACTOR = 100.0
#: ... when it is also at least this long [s]
MIN_CLOCK_JUMP_S = 1.0
#: a time step within a run further than this share of the run's median step from it is uneven: a speed derived
#: over it is off by about that share, which the model's errors of a few percent would show
UNEVEN_STEP_SHARE = 0.05
#: the coolest stator temperature of a file above this suggests degF [degC]
MAX_COOLEST_TEMPERATURE_C = 45.0
#: t statistic above which the load's effect is taken to have the wrong sign
SIGN_T_LIMIT = 3.0


class Finding(NamedTuple):
    """A whole-file plausibility problem: 0-based ``row``, ``column`` and the text."""

    row: int
    column: str
    text: str


def _fmt(x: Any) -> str:
    return f"{x:.4g}" if isinstance(x, (float, np.floating)) else str(x)


def run_table(df: pd.DataFrame) -> pd.DataFrame:
    """One row per run: ``run``, ``row`` (first sample), ``direction``, ``load``, ``voltage`` (median),
    ``u`` (median speed along the direction over the middle half of the run) and ``n`` (samples)."""
    run = df[RUN].to_numpy()
    n = run.size
    if n == 0:
        return pd.DataFrame(columns=["run", "row", "direction", "load", "voltage", "u", "n"])
    change = np.ones(n, dtype=bool)
    change[1:] = run[1:] != run[:-1]
    starts = np.flatnonzero(change)
    stops = np.append(starts[1:], n)
    d = df[DIRECTION].to_numpy(dtype=float)
    load = df[LOAD].to_numpy(dtype=float)
    volt = df[VOLTAGE].to_numpy(dtype=float)
    v = df[SPEED].to_numpy(dtype=float)
    rows = []
    for a, b in zip(starts, stops):
        q = (b - a) // 4
        mid = slice(a + q, b - q) if b - a >= 8 else slice(a, b)
        rows.append((run[a], int(a), float(d[a]), float(load[a]), float(np.median(volt[a:b])),
                     float(np.median(d[a] * v[mid])), int(b - a)))
    return pd.DataFrame(rows, columns=["run", "row", "direction", "load", "voltage", "u", "n"])


def load_effect(runs: pd.DataFrame) -> tuple[float, float, pd.DataFrame, pd.Series, int] | None:
    """Pooled slope [m/s per kg] of the steady speed along the direction on ``load * direction``, within
    groups of equal direction and voltage, its t statistic, the moving runs, their ``z`` and the residual
    degrees of freedom; None when the runs cannot tell (fewer than two loads in any group)."""
    moving = runs[runs["u"] >= MIN_TRAVERSE_SPEED_M_S]
    if moving.empty:
        return None
    z = moving["load"] * moving["direction"]            # the load's pull against the drive direction [kg]
    key = moving["direction"].astype(str) + "|" + moving["voltage"].map(lambda x: f"{x:.3g}")
    zc = z - z.groupby(key).transform("mean")
    uc = moving["u"] - moving["u"].groupby(key).transform("mean")
    sxx = float(np.sum(zc * zc))
    n_groups = key.nunique()
    dof = len(moving) - n_groups - 1
    if sxx <= 0 or dof < 1:
        return None
    slope = float(np.sum(zc * uc)) / sxx
    resid = uc - slope * zc
    se = math.sqrt(float(np.sum(resid * resid)) / dof / sxx)
    t = slope / se if se > 0 else math.copysign(math.inf, slope) if slope else 0.0
    return slope, t, moving, z, dof


#: TEST's load effect per kg may differ from TRAIN's by at most this factor (the same rig, the same gravity)
MAX_LOAD_EFFECT_RATIO = 1.5


def load_effect_mismatch(train_runs: pd.DataFrame, test_runs: pd.DataFrame) -> Finding | None:
    """TEST's load effect per kg (:func:`load_effect`) off TRAIN's by more than :data:`MAX_LOAD_EFFECT_RATIO`.

    On one rig a kilogram on the pulley changes the steady speed by the same
    amount in both files (gravity does not change between them); a TEST file
    whose loads are in lb shows 1/2.2 of TRAIN's effect per "kg", in N 1/9.8.
    Judged only when both effects are clear (|t| > :data:`SIGN_T_LIMIT`).
    """
    a, b = load_effect(train_runs), load_effect(test_runs)
    if a is None or b is None or abs(a[1]) <= SIGN_T_LIMIT or abs(b[1]) <= SIGN_T_LIMIT or a[0] >= 0 or b[0] >= 0:
        return None
    ratio = b[0] / a[0]
    if 1 / MAX_LOAD_EFFECT_RATIO <= ratio <= MAX_LOAD_EFFECT_RATIO:
        return None
    moving, z = b[2], b[3]
    heavy = moving.loc[z.abs().idxmax()]
    return Finding(int(heavy["row"]), LOAD,
                   f"a kilogram of load changes TEST's steady speed {ratio:.3g} x as much as TRAIN's "
                   f"({b[0] * 0.01:+.3g} vs {a[0] * 0.01:+.3g} m/s per 10 g): on one rig gravity gives both the "
                   "same effect; is TEST's load_kg in another unit (lb: 0.45, N: 0.10, x10: 0.10)?")


def load_sign_finding(runs: pd.DataFrame) -> Finding | None:
    """The steady speed along the direction rises with ``load * direction`` (t > :data:`SIGN_T_LIMIT`)."""
    effect = load_effect(runs)
    if effect is None:
        return None
    slope, t, moving, z, dof = effect
    if dof < 2 or slope <= 0 or t <= SIGN_T_LIMIT:
        return None
    heavy = moving.loc[z.abs().idxmax()]
    return Finding(int(heavy["row"]), LOAD,
                   f"the load's effect has the wrong sign: runs whose load pulls against their drive direction are "
                   f"faster ({slope * 0.01:+.3g} m/s per 10 g, t = {t:.1f}, over {len(moving)} runs at equal voltage "
                   "and direction), but gravity slows a slider lifting a load; is load_kg's sign reversed? "
                   "(positive load_kg pulls toward -position)")


def contradiction_finding(runs: pd.DataFrame) -> Finding | None:
    """The first run whose drive inputs contradict its own steady speed (see the module docstring)."""
    v_low = PLAUSIBLE[VOLTAGE].low
    for r in runs.itertuples(index=False):
        pull = r.load * r.direction   # > 0: the load pulls against the drive direction
        if r.u <= -MIN_TRAVERSE_SPEED_M_S and pull <= 0:
            return Finding(r.row, DIRECTION,
                           f"run {_fmt(r.run)}: moves at {_fmt(-r.u)} m/s against its direction {r.direction:+.0f} "
                           f"although its load ({_fmt(r.load)} kg) does not pull that way: direction flipped "
                           "(+1 = toward +position)?")
        if abs(r.voltage) < v_low and r.u >= MIN_TRAVERSE_SPEED_M_S and pull >= 0:
            return Finding(r.row, VOLTAGE,
                           f"run {_fmt(r.run)}: voltage_V = {_fmt(r.voltage)} V, below any drive, yet the slider "
                           f"traverses at {_fmt(r.u)} m/s in its drive direction with no load pulling it there: "
                           "a zeroed or missing voltage?")
    return None


def clock_jump_finding(df: pd.DataFrame) -> Finding | None:
    """The first time step within a run above ``CLOCK_JUMP_FACTOR`` x the run's median and ``MIN_CLOCK_JUMP_S``."""
    t = df[TIME].to_numpy(dtype=float)
    run = df[RUN].to_numpy()
    if t.size < 3:
        return None
    dt = np.diff(t)
    same = run[1:] == run[:-1]
    change = np.flatnonzero(~same) + 1
    for a, b in zip(np.r_[0, change], np.r_[change, t.size]):
        steps = dt[a:b - 1]
        if steps.size < 2:
            continue
        med = float(np.median(steps))
        limit = max(CLOCK_JUMP_FACTOR * med, MIN_CLOCK_JUMP_S)
        bad = np.flatnonzero(steps > limit)
        if bad.size:
            i = int(a + bad[0] + 1)
            return Finding(i, TIME,
                           f"run {_fmt(run[i])}: time_s jumps by {_fmt(float(steps[bad[0]]))} s within the run "
                           f"(its median step is {_fmt(med)} s): a clock jump? (a run is one continuous traverse)")
    return None


def uneven_steps(df: pd.DataFrame) -> dict | None:
    """How uneven the time steps within runs are, or ``None`` when every step is within :data:`UNEVEN_STEP_SHARE`
    of its run's median step.

    Returns ``{"steps", "uneven", "runs", "first_row", "smallest_s", "largest_s", "median_s"}``: the number of
    steps within runs, how many of them are uneven, in how many runs, the 1-based data row after the first uneven
    step, and the smallest, largest and median (over runs) of the runs' median steps [s]. A clock jump
    (:func:`clock_jump_finding`) counts as an uneven step too.
    """
    t = df[TIME].to_numpy(dtype=float)
    run = df[RUN].to_numpy()
    if t.size < 3:
        return None
    dt = np.diff(t)
    change = np.flatnonzero(run[1:] != run[:-1]) + 1
    n = uneven = runs = 0
    first, lo, hi, meds = None, math.inf, -math.inf, []
    for a, b in zip(np.r_[0, change], np.r_[change, t.size]):
        steps = dt[a:b - 1]
        if steps.size < 2:
            continue
        med = float(np.median(steps))
        meds.append(med)
        bad = np.flatnonzero(np.abs(steps - med) > UNEVEN_STEP_SHARE * med)
        n += steps.size
        lo, hi = min(lo, float(steps.min())), max(hi, float(steps.max()))
        if bad.size:
            uneven += int(bad.size)
            runs += 1
            first = int(a + bad[0] + 2) if first is None else first
    if not uneven:
        return None
    return {"steps": int(n), "uneven": int(uneven), "runs": int(runs), "first_row": first, "smallest_s": lo,
            "largest_s": hi, "median_s": float(np.median(meds))}


def step_hint(t_s: np.ndarray, i: int) -> str:
    """A hint when the time steps beside sample ``i`` of a run (times ``t_s``) differ from the run's median step by
    more than :data:`UNEVEN_STEP_SHARE`: a speed derived over uneven stamps."""
    steps = np.diff(t_s)
    med = float(np.median(steps))
    near = steps[max(i - 2, 0):i + 2]
    if not near.size or np.all(np.abs(near - med) <= UNEVEN_STEP_SHARE * med):
        return ""
    shown = ", ".join(f"{x * 1e3:.3g}" for x in near)
    return (f" The time steps beside it are {shown} ms where the run's median step is {med * 1e3:.3g} ms: a speed "
            "derived over uneven time stamps (stamped on arrival, not by the DAQ's clock) is off there")


def _median5(x: np.ndarray) -> np.ndarray:
    """Each sample's median with its two neighbours on each side (the run's ends repeated)."""
    return np.median(np.lib.stride_tricks.sliding_window_view(np.pad(x, 2, mode="edge"), 5), axis=1)


def speed_glitch(v_m_s, s_m, t_s, share: float) -> tuple[int, float] | None:
    """The first glitch of one run's speed column ``v_m_s`` [m/s], ``(i, median of its neighbours)``, or None (also
    for a run of fewer than five samples).

    A sample is far from its neighbours when it differs from the median of its five by more than ``share`` of the
    run's peak (of those medians) + 10 mm/s + 6 x the robust noise level (1.4826 x the median absolute difference).
    Such a sample is not a glitch when the time stamps explain it: a step beside it is uneven (:func:`step_hint`),
    the sample is the position's derivative over the stamps (``numpy.gradient`` of ``s_m`` [m] over ``t_s`` [s])
    within 10 mm/s + 6 x the noise level, and the position's derivative over the run's regular clock
    (:func:`~l1b2.data.stamps.regular_clock_derivative`) is not far from its neighbours by the same rule: the
    position moved smoothly on the DAQ's clock and the speed was derived over stamps that are not its times.
    """
    v = np.asarray(v_m_s, float)
    if v.size < 5:
        return None
    t, s = np.asarray(t_s, float), np.asarray(s_m, float)
    med = _median5(v)
    tol = 0.01 + 6.0 * 1.4826 * float(np.median(np.abs(v - med)))   # a glitch does not move the noise level
    limit = share * float(np.max(np.abs(med))) + tol
    far = np.flatnonzero(np.abs(v - med) > limit)
    if far.size and step_hint(t, int(far[0])):
        u_reg = regular_clock_derivative(s, t)
        with np.errstate(divide="ignore", invalid="ignore"):
            near = (np.abs(v - np.gradient(s, t)) <= tol) & (np.abs(u_reg - _median5(u_reg)) <= limit)
        far = far[~np.array([bool(step_hint(t, int(i))) and near[i] for i in far])]
    return (int(far[0]), float(med[far[0]])) if far.size else None


def uneven_step_lines(records: dict) -> list[str]:
    """One line per file part of a report's ``checks["uneven_time_steps"]`` (``{"train": record or None, "test":
    ...}``, records of :func:`uneven_steps`)."""
    out = []
    for part, r in (records or {}).items():
        if r:
            out.append(f"{part.upper()} time_s: {r['uneven']} of {r['steps']} steps within runs ({r['runs']} run(s), "
                       f"first at row {r['first_row']}) differ from their run's median step by more than "
                       f"{UNEVEN_STEP_SHARE:.0%} (steps {_fmt(r['smallest_s'] * 1e3)} to {_fmt(r['largest_s'] * 1e3)}"
                       f" ms, median {_fmt(r['median_s'] * 1e3)} ms): stamps given on arrival rather than by the "
                       "DAQ's clock? A speed derived over them is off by as much")
    return out


def temperature_finding(df: pd.DataFrame) -> Finding | None:
    """The coolest temperature of the file above :data:`MAX_COOLEST_TEMPERATURE_C` (degF?)."""
    if TEMPERATURE not in df.columns or not len(df):
        return None
    temp = df[TEMPERATURE].to_numpy(dtype=float)
    i = int(np.argmin(temp))
    if temp[i] <= MAX_COOLEST_TEMPERATURE_C:
        return None
    return Finding(i, TEMPERATURE,
                   f"the coolest stator temperature of the file is {_fmt(float(temp[i]))} degC: a stator that never "
                   f"comes near room temperature (all above {_fmt(MAX_COOLEST_TEMPERATURE_C)} degC)? temperature "
                   "in degF?")


def load_scale_finding(df: pd.DataFrame, slider_mass_kg: float | None) -> Finding | None:
    """The first load heavier than the slider (``slider_mass_kg``; no check without it)."""
    if not slider_mass_kg or not len(df):
        return None
    load = np.abs(df[LOAD].to_numpy(dtype=float))
    bad = np.flatnonzero(load > slider_mass_kg)
    if not bad.size:
        return None
    i = int(bad[0])
    return Finding(i, LOAD,
                   f"|load_kg| = {_fmt(float(load[i]))} kg is heavier than the slider itself (slider_mass_kg = "
                   f"{_fmt(float(slider_mass_kg))} kg): load in N (x {GRAVITY_M_S2}), in lb (x 2.2) or x 10?")


def physics_findings(df: pd.DataFrame, *, slider_mass_kg: float | None = None) -> list[Finding]:
    """Every whole-file finding of a validated table (speed present or derived), in row order."""
    found = [clock_jump_finding(df), temperature_finding(df), load_scale_finding(df, slider_mass_kg)]
    if SPEED in df.columns:
        runs = run_table(df)
        found += [load_sign_finding(runs), contradiction_finding(runs)]
    return sorted((f for f in found if f is not None), key=lambda f: f.row)
