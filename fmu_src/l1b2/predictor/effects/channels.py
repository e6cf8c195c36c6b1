"""``channel`` (an open set of regressors): a logged channel or a signal of the recording protocol, in generic
physical forms.

Any numeric column of the measurements beyond the required ones (the data format's optional ``frequency_Hz`` and
``temperature_C`` included, and whatever else the rig logs, but the measured responses of
:data:`RESPONSE_COLUMNS`) is a candidate channel; so is the recording protocol's own clock, the session time
``time_s`` (which also orders the runs). Nothing about a channel's physics is assumed: its standardised value
``z = (c - mean) / sd`` (TRAIN's mean and standard deviation of the samples) enters in one of four generic forms,
each linear in one parameter ``a`` [N per standard deviation]:

* ``friction``: it scales the friction level, ``dF = -a z`` (drive
  coordinates: a force opposing the motion, whichever the direction);
* ``force_factor``: it scales the drive's force factor, ``dF = a (V0/V_ref) z``;
* ``force``: it adds a force fixed in the lab frame, ``dF = a d z`` (``d`` the direction);
* ``inertia``: it scales the moving mass, ``dF = -m_s d a_base (a z + a_0)`` (``a_base`` the baseline's predicted
  acceleration, ``m_s`` the slider's mass: ``a`` [1 per standard deviation] is the relative change of the moving
  mass per standard deviation of the channel, ``a_0`` [1] the relative mass change at the channel's TRAIN mean,
  :class:`l1b2.predictor.effects.motion.InertiaMismatch`'s constant error; in every shape, the shape's columns
  then the constant one). The constant is the form's own: the model's mass is the slider's stated one, never
  re-identified, so the mass change at the channel's mean is in no re-identification direction of the baseline,
  whereas every other form's constant is (the friction offset, the force factor, the damping). A logged channel
  only (a payload, a tool, a fluid that changes the moving mass between runs or along the stroke), listed without
  the load interaction (:data:`FORCE_FORMS`). The force is the first-order change of the free run when the slider's
  mass is ``m_s (1 + a z + a_0)``; the same parameters with that mass inside the recursion are
  :func:`slider_mass` (the mass per sample, for :func:`l1b2.predictor.simulate.free_run`), their sensitivities
  :func:`l1b2.predictor.simulate.mass_sensitivity` and their physical range a positive slider mass over TRAIN's
  range (:func:`mass_floor`); the loop's screen, refit and export use the force,
* ``damping``: it scales the viscous damping, ``dF = -a d v_base / SPEED_REF z`` (``v_base`` the baseline's
  predicted speed, signed; ``d v_base`` the speed in drive coordinates, so the force opposes the motion;
  ``SPEED_REF`` = 0.2 m/s, the base module's speed scale, the order of the slider's top speed: ``a`` [N per
  standard deviation] is the change of the damping force at that speed); a logged channel only (a field that
  brakes the moving carriage, a fluid's or a film's viscosity that a logged condition sets), in the linear and
  quadratic shapes (:data:`DAMPING_SHAPES`), without the load interaction,

in one of three shapes, Hermite polynomials of ``zc`` (``z`` clipped to TRAIN's range of the channel, flat
beyond it): ``linear`` (the factor times ``a z``, one parameter, unclipped), ``quadratic`` (``a zc + b (zc^2 -
1)``: an even part, a response that peaks inside the range) or ``odd`` (``a zc + c (zc^3 - 3 zc)``: an odd part, a
response that saturates, which the even square cannot take), and, at the run level for a logged channel with at
least :data:`PEAK_MIN_RUN_VALUES` distinct run values that is no derived history of a setting (:func:`peaked`),
``peak`` (:func:`peak_column`: ``a (1 / (1 + ((zc - z0) /
w)^2) - its mean over TRAIN's range)``, a response confined to a band of the channel, a resonance; ``z0`` and ``w``
chosen on :func:`peak_grid`, one hypothesis per grid point, each recording the grid's size ``grid_points``); a
logged channel only: the session clock keeps
the linear shape, its curvature is the generic time spline's, :mod:`l1b2.predictor.effects.generic`; and at one of
two levels: ``run`` (``c`` is the run's mean of the channel: an effect that differs between runs, not along the
stroke) or ``sample`` (``c`` is the sample's value: along the stroke; listed only for a channel that varies within
runs). The run's own clock :data:`RUN_CLOCK` and travel :data:`RUN_TRAVEL` (:data:`SAMPLE_ONLY_KINDS`) are listed
at the ``sample`` level only (:func:`levels_of`), with no run-level signal: a run's mean of them is half its duration
or way, a response of the motor, not a cause. An effect of them growing with V0 is their ``force_factor`` form.

A channel's effect may also grow with an input of the model (``by``, :data:`INTERACTIONS`): the form's force times
``(1 + u)``-like, two sets of columns, ``factor shape(z)`` and ``factor shape(z) u``, ``u = |m| / m_max`` (the
load's size over TRAIN's largest, ``load_abs``). The load is the one input a form lacks: V0 already scales the
``force_factor`` form and the direction the ``force`` form (a channel effect growing with V0 or differing between
the directions is one of those forms), whereas the load enters the physics as its weight along the motion (gravity:
no channel changes it) and as the friction that weight causes in the load path and the contact, ``g |m|``, whose
coefficient a logged channel can change. Listed for the linear and quadratic shapes (at most four parameters).
Every form, shape, level and interaction of one channel is one family for the significance correction
(``channel_<column>``).

Signals: ``col:<column>`` (the sample values) and ``run:<column>`` (each
run's mean, per sample), taken from the data frame by
:func:`l1b2.closeloop.candidates.signals`.

What ``Predictor.fmu`` evaluates (:func:`fmu_signal`, :func:`export_problem`): a
signal of a column that is an input of the FMU (:data:`INPUT_COLUMNS`:
``voltage_V`` -> ``V0``, ``load_kg`` -> ``load``, ``direction`` -> ``d``,
``temperature_C`` -> ``T``) is that input's **current value**, at both levels;
so is a signal of any other logged column, whose input the FMU declares when an
effect reads it (:func:`channel_inputs`: the input named after the column, its
signal ``col:<column>``). For ``col:`` that is the signal itself; for ``run:``
(the run's mean) it is exact only when the input is constant within a run,
which the rig's protocol does for V0, the load and the direction, and a rig
may do for a logged setting: the run-level contract. Each run-level hypothesis
records how far TRAIN's runs were from it (``run_spread``: the largest
deviation of a sample's value from its run's mean, in the signal's units) and
the export refuses one whose spread exceeds :data:`RUN_CONSTANT_TOL` standard
deviations of the signal. The session clock ``time_s`` has no input (the FMU's
own time is the session clock; its run mean changes along the run): a model
reading it as a channel is not exported. The run clock :data:`RUN_CLOCK` and travel :data:`RUN_TRAVEL` are
inputs named after them, at the sample level only: the host computes them from its own clock (the time since the
run's drive started) and position reading (the way gone in the run's direction since then).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ...units import is_setting_history
from .base import SIGNALS, SPEED_REF, V_REF, Effect, EffectSpecError, family, needs, num, register, signal

FORMS = ("friction", "force_factor", "force", "inertia", "damping")
#: the forms of every channel, the session clock's included, and of the load interaction: all but ``inertia``
#: (a logged channel's moving mass; the load's own mass is the model's, a load interaction of it no cause's form)
#: and ``damping`` (a logged channel's viscous damping; the session clock's is the generic time x speed pair's, the
#: load's weight pulls along the motion and changes no viscosity)
FORCE_FORMS = ("friction", "force_factor", "force")
#: the shapes of the damping form: a damping coefficient that a condition changes monotonically (the slope) or
#: convexly (a viscosity's exponential law over a range, a brake's force growing with the square of its field:
#: the curvature); a saturation (the odd shape's third-order term) of a force that is itself a small share of the
#: drive's is not listed
DAMPING_SHAPES = ("linear", "quadratic")
LEVELS = ("run", "sample")
#: a channel's shapes: linear in ``z``, or ``z`` clipped to TRAIN's range and its second or third Hermite
#: polynomial (:func:`shape_basis`)
SHAPES = ("linear", "quadratic", "odd")
#: a channel's peaked shape (:func:`peak_column`): a Lorentzian bump of ``zc`` centred at ``z0`` with half width ``w``
#: (both in standard deviations of the channel, chosen on :func:`peak_grid`), minus its mean over TRAIN's range of
#: ``zc``; one parameter. Not one of :data:`SHAPES` (the Hermite shapes, whose kernels the native FMU has): listed at
#: the run level only (:data:`PEAK_LEVELS`), in :data:`PEAK_FORMS`, for a logged channel with at least
#: :data:`PEAK_MIN_RUN_VALUES` distinct run values that is no derived history of a setting (:func:`peaked`)
PEAK = "peak"
#: the half widths of the peak's grid [standard deviations of the channel]: a factor 2 apart, from a quarter of one
#: to one (two Lorentzians of half widths a factor 2 apart correlate at 0.94 at most, so the grid loses little)
PEAK_WIDTHS = (0.25, 0.5, 1.0)
#: the fewest distinct run values of a channel for its peak to be listed: a centre and a width need runs on both
#: sides of the bump and beyond it
PEAK_MIN_RUN_VALUES = 8
#: the levels the peak is listed at: the run mean only. A run's value is one point of the bump, judged by the runs
#: it separates (the screen's p-value counts runs); along the stroke a channel that drifts within a run would give a
#: bump of the run's clock, which the generic time terms already offer
PEAK_LEVELS = ("run",)
#: the forms the peak is listed in: a resonance or a band of a logged setting changes a dissipation or a drive gain
#: (the friction, the force factor, a force, the viscous damping); a moving mass that peaks in a setting is no
#: generic physics, so the inertia form is left out, as is the load interaction
PEAK_FORMS = FORCE_FORMS + ("damping",)
#: the inputs a channel's effect may grow with (``by``): the load's size ``|m|/load_abs`` (:func:`interaction_basis`)
INTERACTIONS = ("load",)
#: the shapes listed with an interaction (:meth:`Channel.grid`)
INTERACTION_SHAPES = ("linear", "quadratic")
#: the session clock's column: the recording protocol's signal, always a candidate
SESSION_TIME = "time_s"
#: the run's own clock, the time since the run's first sample [s] (derived by :mod:`l1b2.closeloop.runclock`): a
#: channel of kind ``"run_clock"``, a kind of :data:`SAMPLE_ONLY_KINDS`
RUN_CLOCK = "time_in_run_s"
#: the run's own travel, the way gone in the run's direction since its first sample [m] (derived by
#: :mod:`l1b2.closeloop.runclock`): a channel of kind ``"run_travel"``, a kind of :data:`SAMPLE_ONLY_KINDS`
RUN_TRAVEL = "travel_in_run_m"
#: the channel kinds offered at the ``sample`` level only: no run-level form, no run-level signal. A run's mean of
#: its own clock (travel) is half its duration (way), set by the motor's speed over the stroke: a response
SAMPLE_ONLY_KINDS = ("run_clock", "run_travel")
#: the channels of :data:`SAMPLE_ONLY_KINDS`, whose run means no input carries
RUN_OWN = (RUN_CLOCK, RUN_TRAVEL)
#: the channel kinds that are never candidates: a measured response of the motor and a reading that relabels the
#: plan's inputs run by run (:mod:`l1b2.closeloop.relabels`): listed, no hypothesis
NOT_CAUSE_KINDS = ("response", "relabel")
#: the channel kinds with no run-level hypothesis and no run-level signal: those that are never candidates, a label
#: (its codes have no order: its categorical family only) and the sample-only kinds
NO_RUN_LEVEL_KINDS = NOT_CAUSE_KINDS + ("label",) + SAMPLE_ONLY_KINDS
#: logged columns that are measured *responses* of the motor, not causes: listed, never candidates. A regressor
#: that is the motor's own response (the vibrometer's tip-velocity amplitude follows the drive force the model
#: predicts) would stand in for the model instead of explaining it, and a predictor needing it could not predict
RESPONSE_COLUMNS = ("tip_velocity_amp_m_s",)
#: report regressor of the channels that have a name in the rest of the loop (others: the column itself)
REGRESSOR_NAMES = {"time_s": "time", "temperature_C": "temperature", "frequency_Hz": "frequency"}


def regressor_of(column: str) -> str:
    """The regressor name a channel is traced to (``diagnosis.traced_to``)."""
    return REGRESSOR_NAMES.get(column, column)


#: the columns whose signals ``Predictor.fmu`` gives from its inputs: column -> the input's signal (:data:`SIGNALS`)
INPUT_COLUMNS = {"voltage_V": "V0", "load_kg": "load", "direction": "d", "temperature_C": "T"}
#: the largest deviation of an input from its run's value within a TRAIN run, in standard deviations of the
#: run-level signal, that the export accepts for a run-level effect (the FMU's force then differs from the
#: identified one by at most 1 % of one standard deviation's force)
RUN_CONSTANT_TOL = 0.01
#: the largest change of the final model's free run on TRAIN, as a share of its rms, that feeding a logged setting's
#: samples instead of its run means may make for the export to accept a run-level effect of a logged channel beyond
#: :data:`RUN_CONSTANT_TOL` (the spec's ``run_feed``, :mod:`l1b2.closeloop.calibrated`): 1 % of the speed, a third
#: of the model's own free-run error on the paper's data
RUN_FEED_TOL = 0.01


def fmu_signal(key: str) -> str | None:
    """The signal that ``Predictor.fmu`` gives for a signal key (None: it has no input for it).

    A signal of :data:`SIGNALS` is itself; ``col:<column>`` and ``run:<column>`` of a column of
    :data:`INPUT_COLUMNS` are that input; of the session clock :data:`SESSION_TIME`, None; of any other column,
    ``col:<column>``, the signal of the column's own input (:func:`channel_inputs`). Either level is the input's
    current value: for ``run:`` exact when the input is constant within a run. The run clock :data:`RUN_CLOCK`
    and travel :data:`RUN_TRAVEL` are inputs at the sample level only: their run means (half the run's duration,
    half its way) are known only when the run ends, so ``run:`` of them is None.
    """
    if key in SIGNALS:
        return key
    run_own = key[:4] == "run:" and key[4:] in RUN_OWN
    if key[:4] in ("col:", "run:") and key[4:] and key[4:] != SESSION_TIME and not run_own:
        return INPUT_COLUMNS.get(key[4:], "col:" + key[4:])
    return None


def channel_inputs(specs) -> dict:
    """The logged channels that effect specs read through inputs of their own, ``{column: start}`` in column
    order: every column of a ``col:``/``run:`` signal (:func:`fmu_signal`) that is no input of
    :data:`INPUT_COLUMNS`, with TRAIN's mean of it as the first spec naming it as its ``channel`` records it
    (:meth:`~l1b2.predictor.effects.base.Effect.channel_mean`; 0 when none does)."""
    out: dict = {}
    for spec in specs:
        for key in sorted(needs(spec)):
            sig = fmu_signal(key)
            if sig is None or not sig.startswith("col:"):
                continue
            col = sig[4:]
            mean = family(spec.get("kind")).channel_mean(spec) if spec.get("channel") == col else None
            if out.get(col) is None:
                out[col] = mean
    return {col: (0.0 if out[col] is None else float(out[col])) for col in sorted(out)}


def with_input_signals(x, keys) -> dict:
    """``x`` with every ``col:``/``run:`` key of ``keys`` that an input gives (:func:`fmu_signal`) and ``x`` lacks,
    set to that input's values: the FMU's reading of a run-level signal (the current value, not the run's mean)."""
    out = dict(x)
    for key in keys:
        sig = fmu_signal(key)
        if key not in out and sig is not None and sig != key and sig in out:
            out[key] = out[sig]
    return out


def run_spread(values, run) -> float:
    """The largest deviation of a sample's value from its run's mean [the values' unit] (``run``: each sample's run
    id): 0 when every run holds it constant, the run-level contract that :func:`export_problem` checks."""
    c = np.asarray(values, float)
    if len(c) == 0:
        return 0.0
    means = pd.Series(c).groupby(np.asarray(run), sort=False).transform("mean").to_numpy(float)
    return float(np.max(np.abs(c - means)))


def run_spread_excess(spec) -> list[tuple[str, float, float]]:
    """The run-level signals (``run:<column>``) a spec reads that TRAIN's runs did not hold constant, in column order.

    ``(column, run_spread, sd)`` for each whose recorded ``run_spread`` exceeds :data:`RUN_CONSTANT_TOL` standard
    deviations ``sd`` of the run-level signal; ``run_spread`` is ``inf`` when the spec does not record it.
    """
    out = []
    for key in sorted(k for k in family(spec.get("kind")).needs(spec) if k.startswith("run:")):
        spread = float(spec.get("run_spread", float("inf")))
        sd = float(spec.get("sd", 0.0))
        if not spread <= RUN_CONSTANT_TOL * sd:
            out.append((key[4:], spread, sd))
    return out


def export_problem(spec) -> str | None:
    """Why ``Predictor.fmu`` cannot evaluate an effect spec as identified (None: it can).

    ``"the family ... is not exportable"`` for a family that says so (``exportable`` False); ``"no input: <keys>"``
    when a signal has no FMU input (:func:`fmu_signal`); for a run-level signal of an input,
    ``"not constant within runs: ..."`` when the spec does not record TRAIN's ``run_spread`` or it exceeds
    :data:`RUN_CONSTANT_TOL` standard deviations (``sd``) of the signal, unless the signal is a logged channel's
    (no input of :data:`INPUT_COLUMNS`) and the spec's ``run_feed`` (the free run's change when the samples are fed
    instead of the run means, :mod:`l1b2.closeloop.calibrated`) is at most :data:`RUN_FEED_TOL`.
    """
    fam = family(spec.get("kind"))
    if not fam.exportable:
        return f"the family {fam.kind!r} is not exportable"
    keys = fam.needs(spec)
    missing = sorted(k for k in keys if fmu_signal(k) is None)
    if missing:
        return "no input: " + ", ".join(missing)
    for col, spread, sd in run_spread_excess(spec):
        if not np.isfinite(spread):
            return (f"not constant within runs: the spec does not record how far TRAIN's runs held {col} constant "
                    "(run_spread)")
        logged = col not in INPUT_COLUMNS
        feed = float(spec.get("run_feed", float("inf"))) if logged else float("inf")
        if feed <= RUN_FEED_TOL:
            continue   # a logged setting fed as the run's value: its samples move the free run by at most this
        return (f"not constant within runs: {col} deviates from its run's mean by up to {spread:.4g} within a "
                f"TRAIN run ({spread / sd if sd > 0 else float('inf'):.3g} standard deviations of the run-level "
                f"signal, more than {RUN_CONSTANT_TOL}); the FMU reads the input's current value"
                + (f" (feeding its samples instead of the run means moves the free run on TRAIN by up to "
                   f"{feed:.2%} of its rms, more than {RUN_FEED_TOL:.0%})" if logged and np.isfinite(feed) else ""))
    return None


def signal_key(column: str, level: str) -> str:
    """The signal of a channel at a level: ``col:<column>`` (samples) or ``run:<column>`` (run means)."""
    if level not in LEVELS:
        raise EffectSpecError(f"channel level {level!r} is not one of {', '.join(LEVELS)}")
    return ("col:" if level == "sample" else "run:") + column


def form_factor(form: str, x, m_s: float | None = None) -> np.ndarray:
    """The generic physical form's factor per sample: ``-1`` (friction), ``V0/V_ref`` (force factor), ``d`` (force),
    ``-m_s d a_base`` (inertia: ``m_s`` the slider's mass [kg], ``a_base`` the baseline's acceleration; the
    form's features add this factor itself as a last column, the mass change at the channel's mean),
    ``-d v_base / SPEED_REF`` (damping: ``v_base`` the baseline's speed)."""
    if form == "inertia":
        if m_s is None or not m_s > 0:
            raise EffectSpecError(f"channel form 'inertia': the slider mass m_s {m_s} is not positive")
        return -m_s * signal(x, "d") * signal(x, "a_base")
    if form == "damping":
        return -signal(x, "d") * signal(x, "v_base") / SPEED_REF
    if form == "friction":
        return -np.ones(len(signal(x, "d")))
    if form == "force_factor":
        return signal(x, "V0") / V_REF
    if form == "force":
        return signal(x, "d")
    raise EffectSpecError(f"channel form {form!r} is not one of {', '.join(FORMS)}")


@register
class Channel(Effect):
    kind = "channel"
    regressor = "channel"
    group = "generic"
    description = "a logged channel or protocol signal in a generic physical form"

    def needs(self, spec):
        by = {"load"} if spec.get("by") else set()
        motion = {"inertia": {"a_base"}, "damping": {"v_base"}}.get(str(spec.get("form")), set())
        return super().needs(spec) | {signal_key(str(spec.get("channel")), str(spec.get("level")))} | by | motion

    def features(self, spec, x):
        z = _channel_z(spec, x)
        form = str(spec.get("form"))
        factor = form_factor(form, x, num(spec, "m_s") if form == "inertia" else None)
        if form == "inertia":   # the mass form's linearisation: the force of each relative mass column
            return factor[:, None] * _mass_basis(spec, z)
        return interaction_basis(spec, x, factor[:, None] * shape_basis(spec, z))

    def width(self, spec):
        n = 1 if spec.get("shape", "linear") in ("linear", PEAK) else 2
        return 2 * n if spec.get("by") else n + (spec.get("form") == "inertia")

    def grid(self, train):
        chans = list(train.channels)
        if not any(ch["name"] == SESSION_TIME for ch in chans):   # the protocol's clock, from TRAIN's time range
            t0, t1 = train.time_range
            chans.append({"name": SESSION_TIME, "kind": "protocol", "mean": 0.5 * (t0 + t1),
                          "sd": (t1 - t0) / np.sqrt(12.0), "within_run": True, "lo": t0, "hi": t1})
        out = []
        for ch in chans:
            if not ch.get("sd", 0) > 0 or ch.get("kind") in NOT_CAUSE_KINDS + ("label",):
                continue   # constant on TRAIN (no evidence possible), a measured response or a relabel of the
                # plan's inputs (not a cause) or a label's unordered codes (categorical run-level family only):
                # considered, no value form
            reg = regressor_of(ch["name"])
            logged = "lo" in ch and "hi" in ch and ch["name"] != SESSION_TIME
            load_abs = float(train.ranges.get("load_abs", 0.0)) if logged else 0.0
            damping = np.nan if train.damping_N_s_per_m is None else float(train.damping_N_s_per_m)
            m_s = float(getattr(train, "m_s", 0.0) or 0.0) if logged else 0.0
            for level in levels_of(ch):
                for shape in SHAPES if logged else SHAPES[:1]:
                    for by in ("",) + (INTERACTIONS if load_abs > 0 and shape in INTERACTION_SHAPES else ()):
                        for form in _forms(logged and not by, m_s, shape):
                            out.append(self._hypothesis(ch, reg, form, level, shape, by, load_abs, m_s, damping))
                if logged and level in PEAK_LEVELS and peaked(ch):
                    out += self._peaks(ch, reg, level, damping)
        return out

    def _peaks(self, ch, reg, level, damping=np.nan) -> list:
        """The peak's hypotheses of a channel at a level: one per form of :data:`PEAK_FORMS` and point ``(z0, w)``
        of :func:`peak_grid` over TRAIN's range of the channel, each recording the grid's size (``grid_points``:
        the screen's p-value of each is multiplied by it, :func:`l1b2.closeloop.selection.search_count`)."""
        grid = peak_grid(*_z_range(ch, ch["lo"], ch["hi"]))
        return [self._hypothesis(ch, reg, form, level, PEAK, damping=damping, peak=(z0, w, len(grid)))
                for form in PEAK_FORMS for z0, w in grid]

    def _hypothesis(self, ch, reg, form, level, shape, by="", load_abs=0.0, m_s=0.0, damping=np.nan, peak=None):
        name = ch["name"]
        spec = {"channel": name, "form": form, "level": level, "mean": float(ch["mean"]), "sd": float(ch["sd"]),
                **run_spread_entry(ch, level), **({"m_s": float(m_s)} if form == "inertia" else {})}
        names = [f"{name}_{form}_{level}"]
        if shape == PEAK:
            return self._peak_hypothesis(ch, reg, spec, peak, damping)
        if shape != "linear":
            spec.update(shape=shape, lo=float(ch["lo"]), hi=float(ch["hi"]))
            names = ([f"{name}_{form}_{level}_lin", f"{name}_{form}_{level}_sq"] if shape == "quadratic" else
                     [f"{name}_{form}_{level}_odd_lin", f"{name}_{form}_{level}_odd_cub"])
        if by:     # the channel's own part and its part growing with the input, named apart from every other shape
            spec.update(by=by, load_abs=float(load_abs))
            names = [f"{n}_by_{by}" for n in names] + [f"{n}_x_{by}" for n in names]
        if form == "inertia":   # the mass change at the channel's mean, named apart in every shape
            names = names + [f"{name}_{form}_{level}{dict(linear='', quadratic='_quad', odd='_odd')[shape]}_mean"]
        extra = (f", {shape}" if shape != "linear" else "") + (f", x {by}" if by else "")
        bounds = damping_bounds(spec, ch["lo"], ch["hi"], damping) if form == "damping" and shape == "linear" else ()
        return self.hypothesis(
            names, ["1" if form == "inertia" else "N"] * len(names), spec, f"{form}, {level}{extra}", bounds=bounds,
            family=f"channel_{name}", regressor=reg, generic=True, also=(regressor_of(_BY_COLUMN[by]),) if by else (),
            description=f"{ch.get('kind', 'logged')} channel {name} ({'run mean' if level == 'run' else 'per sample'}"
                        f"{extra}) {_FORM_TEXT[form]}{', growing with the load' if by else ''}")


    def _peak_hypothesis(self, ch, reg, spec, peak, damping):
        """A peak hypothesis (``peak``: its grid point ``z0``, ``w`` and the grid's size): the shape's text names the
        point and the grid it was chosen on; the damping form keeps the total damping non-negative (bounds over
        TRAIN's range: the centred bump's column lies between its values at the range's ends and at ``z0``)."""
        z0, w, n = peak
        name, form, level = ch["name"], spec["form"], spec["level"]
        spec.update(shape=PEAK, lo=float(ch["lo"]), hi=float(ch["hi"]), z0=float(z0), w=float(w), grid_points=int(n))
        shape = f"{form}, {level}, peak z0 {z0:+.2f} w {w:.2f} of {n}"
        bounds = peak_damping_bounds(spec, damping) if form == "damping" else ()
        return self.hypothesis(
            [f"{name}_{form}_{level}_peak"], ["N"], spec, shape, bounds=bounds, family=f"channel_{name}",
            regressor=reg, generic=True,
            description=f"{ch.get('kind', 'logged')} channel {name} ({'run mean' if level == 'run' else 'per sample'}"
                        f", a Lorentzian peak centred {z0:+.3g} sd from TRAIN's mean, half width {w:.3g} sd, both "
                        f"chosen on a grid of {n} points) {_FORM_TEXT[form]}")


def peak_damping_bounds(spec, damping: float) -> tuple:
    """The range of the peak damping form's ``a`` [N] that keeps the total viscous damping ``damping + a p(zc) /
    SPEED_REF`` non-negative over TRAIN's range, ``p`` the centred bump (:func:`peak_column`): ``p`` lies in
    ``[p_min, p_max]`` (``p_max`` at ``z0``, ``p_min`` at an end of the range; ``p_min < 0 < p_max``), so
    ``-damping SPEED_REF / p_max <= a <= damping SPEED_REF / (-p_min)``: ``((lower, upper),)``; ``()`` when
    ``damping`` is not a positive number."""
    if not damping > 0:
        return ()
    z_lo, z_hi = _z_range(spec, spec["lo"], spec["hi"])
    z0, w = float(spec["z0"]), float(spec["w"])
    p = peak_column(np.array([z_lo, z_hi, z0]), z0, w, z_lo, z_hi)
    p_min, p_max = float(np.min(p)), float(np.max(p))
    if not p_min < 0 < p_max:
        return ()
    return ((-damping * SPEED_REF / p_max, damping * SPEED_REF / -p_min),)


def peaked(ch) -> bool:
    """Whether a logged channel's record (:func:`l1b2.closeloop.candidates.channels_of`) lists the peak: at least
    :data:`PEAK_MIN_RUN_VALUES` distinct run values, and not a setting's history the loop derives (a low-pass over
    run periods or a step from the previous setting, :func:`l1b2.units.is_setting_history`): a band of response
    belongs to the setting itself, which carries its own peak, while its history stands for a memory (a heating, an
    ageing) whose law the Hermite shapes take."""
    return int(ch.get("run_values", 0)) >= PEAK_MIN_RUN_VALUES and not is_setting_history(str(ch["name"]))


def sample_only_reason(ch) -> str | None:
    """Why a logged channel's record (:func:`l1b2.closeloop.candidates.channels_of`) is offered per sample only,
    its run mean following how the run went, the motor's response: read along the stroke (``along_stroke``: a
    function of the position, whose run mean follows how the run moved), or a reading that accumulates over each
    run (``run_length``: its run means follow the runs' lengths); None for neither."""
    if ch.get("run_length"):
        return "its run means follow the runs' lengths"
    return "read along the stroke" if ch.get("along_stroke") else None


def levels_of(ch) -> tuple:
    """The levels a channel record (:func:`l1b2.closeloop.candidates.channels_of`) is offered at: ``sample`` only
    for a kind of :data:`SAMPLE_ONLY_KINDS` (the run's clock and travel) and for a channel with a
    :func:`sample_only_reason`, both :data:`LEVELS` for a channel that varies within runs, ``run`` only for one
    constant within every run."""
    if ch.get("kind") in SAMPLE_ONLY_KINDS or sample_only_reason(ch):
        return ("sample",)
    return LEVELS if ch.get("within_run", True) else ("run",)


def _forms(own: bool, m_s: float, shape: str) -> tuple:
    """The forms a channel lists in a shape: the force forms; a logged channel's own (no interaction) adds the
    inertia form (given the slider's mass) and, in :data:`DAMPING_SHAPES`, the damping form."""
    return (FORCE_FORMS + (("inertia",) if own and m_s > 0 else ())
            + (("damping",) if own and shape in DAMPING_SHAPES else ()))


def _channel_z(spec, x) -> np.ndarray:
    """A channel spec's standardised values per sample, ``(c - mean) / sd`` (``sd`` must be positive)."""
    c = signal(x, signal_key(str(spec.get("channel")), str(spec.get("level"))))
    sd = num(spec, "sd")
    if not sd > 0:
        raise EffectSpecError(f"channel {spec.get('channel')!r}: standard deviation {sd} is not positive")
    return (c - num(spec, "mean")) / sd


def _z_range(spec, lo: float, hi: float) -> tuple[float, float]:
    """A channel's range ``[lo, hi]`` in its spec's standard deviations about its mean."""
    mean, sd = num(spec, "mean"), num(spec, "sd")
    return (float(lo) - mean) / sd, (float(hi) - mean) / sd


def damping_bounds(spec, lo: float, hi: float, damping: float) -> tuple:
    """The range of the linear damping form's ``a`` [N] that keeps the total viscous damping non-negative.

    The form's damping coefficient is ``a z / SPEED_REF`` [N s/m]; with the baseline's own viscous damping
    ``damping`` [N s/m] (its smallest value over TRAIN, :func:`l1b2.predictor.model.viscous_damping`),
    ``damping + a z / SPEED_REF >= 0`` for every ``z`` of TRAIN's range of the channel, ``[(lo - mean)/sd,
    (hi - mean)/sd]`` (``lo < mean < hi``), is ``-damping SPEED_REF / z_hi <= a <= damping SPEED_REF / (-z_lo)``:
    ``((lower, upper),)``; ``()`` (unbounded) when ``damping`` is not a positive number (no baseline damping known,
    or the baseline's own damping is negative somewhere: no ``a`` restores it everywhere).
    """
    if not damping > 0:
        return ()
    z_lo, z_hi = _z_range(spec, lo, hi)
    if not z_lo < 0 < z_hi:
        return ()
    return ((-damping * SPEED_REF / z_hi, damping * SPEED_REF / -z_lo),)


def damping_floor(spec, phi, lo: float, hi: float, damping: float) -> float:
    """The smallest total viscous damping [N s/m] of a damping-form spec with parameters ``phi`` over TRAIN's
    range ``[lo, hi]`` of its channel: ``damping + min_z shape(z) @ phi / SPEED_REF``.

    ``damping`` [N s/m]: the baseline's own (smallest) viscous damping. The minimum over the range is exact: the
    linear shape's at an end of the range, the quadratic shape's ``a zc + b (zc^2 - 1)`` at an end or, when
    ``b > 0``, at its vertex ``zc = -a / (2 b)`` inside the range.
    """
    if spec.get("form") != "damping":
        raise EffectSpecError(f"damping_floor: the spec's form {spec.get('form')!r} is not 'damping'")
    phi = np.asarray(phi, float).ravel()
    z = _shape_extremes(spec, phi, *_z_range(spec, lo, hi))
    cols = shape_basis({**spec, "lo": lo, "hi": hi}, z)
    return float(damping + np.min(cols @ phi) / SPEED_REF)


def _mass_basis(spec, z) -> np.ndarray:
    """The inertia form's relative mass columns for standardised values ``z``: the shape's, then a column of ones."""
    F = shape_basis(spec, z)
    return np.column_stack([F, np.ones(len(F))])


def mass_columns(spec, x) -> np.ndarray:
    """The relative mass columns of an inertia-form spec per sample [1 per unit parameter]: the shape's columns of
    the channel's ``z`` (:func:`shape_basis`), then a column of ones (the mass change at the channel's mean).

    With parameters ``phi`` the slider's mass is ``m_s (1 + mass_columns(spec, x) @ phi)`` [kg]
    (:func:`slider_mass`). The form's force features (:meth:`Channel.features`) are these columns times
    ``-m_s d a_base``: the first-order change of the free run's force when that mass moves the baseline's
    acceleration ``a_base``.
    """
    if spec.get("form") != "inertia":
        raise EffectSpecError(f"mass_columns: the spec's form {spec.get('form')!r} is not 'inertia'")
    if spec.get("by"):
        raise EffectSpecError("mass_columns: the inertia form has no interaction")
    return _mass_basis(spec, _channel_z(spec, x))


def slider_mass(spec, x, phi) -> np.ndarray:
    """The slider's mass per sample [kg] of an inertia-form spec with parameters ``phi`` (shape's, then the
    constant ``a_0``): ``m_s (1 + mass_columns(spec, x) @ phi)``, ``m_s`` the spec's slider mass [kg]. The free run
    with this mass inside its recursion (:func:`l1b2.predictor.simulate.free_run` with ``m_s`` per sample) is the
    form's exact effect: ``(m_s (1 + g) + |m|) dv/dt = F``, the slider's weight on the guide included."""
    m_s = num(spec, "m_s")
    if not m_s > 0:
        raise EffectSpecError(f"channel form 'inertia': the slider mass m_s {m_s} is not positive")
    return m_s * (1.0 + mass_columns(spec, x) @ np.asarray(phi, float).ravel())


def _shape_extremes(spec, phi, z_lo: float, z_hi: float) -> np.ndarray:
    """The standardised values where a shape's value ``shape_basis(z) @ phi[:2]`` can be smallest over
    ``[z_lo, z_hi]``: the ends and the interior stationary points (the quadratic's vertex ``-a / (2 b)``; the odd
    shape's ``zc^2 = 1 - a / (3 c)``, from ``a + c (3 zc^2 - 3) = 0``)."""
    shape, z = spec.get("shape", "linear"), [z_lo, z_hi]
    if shape == "quadratic" and phi[1] != 0:
        z.append(-phi[0] / (2.0 * phi[1]))
    elif shape == "odd" and phi[1] != 0 and 1.0 - phi[0] / (3.0 * phi[1]) > 0:
        r = np.sqrt(1.0 - phi[0] / (3.0 * phi[1]))
        z += [-r, r]
    elif shape == PEAK:
        z.append(num(spec, "z0"))
    return np.array([v for v in z if z_lo <= v <= z_hi], float)


def mass_floor(spec, phi, lo: float, hi: float) -> float:
    """The smallest slider mass [kg] of an inertia-form spec with parameters ``phi`` over TRAIN's range ``[lo, hi]``
    of its channel: ``m_s (1 + a_0 + min_z shape(z) @ a)``, exact (the shape's minimum lies at an end of the range
    or at an interior stationary point). The physical range of the form is a positive floor: the slider with its
    change keeps a positive mass wherever TRAIN's channel was (the shaped forms are flat beyond the range)."""
    if spec.get("form") != "inertia":
        raise EffectSpecError(f"mass_floor: the spec's form {spec.get('form')!r} is not 'inertia'")
    phi = np.asarray(phi, float).ravel()
    z = _shape_extremes(spec, phi, *_z_range(spec, lo, hi))
    cols = _mass_basis({**spec, "lo": lo, "hi": hi}, z)
    return float(num(spec, "m_s") * (1.0 + np.min(cols @ phi)))


def peak_grid(z_lo: float, z_hi: float) -> list[tuple[float, float]]:
    """The peak's grid of ``(z0, w)`` over TRAIN's range ``[z_lo, z_hi]`` of a channel's standardised value: for
    each half width ``w`` of :data:`PEAK_WIDTHS`, the centres evenly spaced from ``z_lo`` to ``z_hi``, both ends
    included, at most ``w`` apart (``ceil((z_hi - z_lo) / w) + 1`` of them). Empty for an empty range."""
    if not z_hi > z_lo:
        return []
    out = []
    for w in PEAK_WIDTHS:
        n = int(np.ceil((z_hi - z_lo) / w - 1e-9)) + 1
        out += [(float(z0), float(w)) for z0 in np.linspace(z_lo, z_hi, n)]
    return out


def peak_mean(z0: float, w: float, z_lo: float, z_hi: float) -> float:
    """The mean of the bump ``1 / (1 + ((z - z0) / w)^2)`` over ``z`` uniform in ``[z_lo, z_hi]``:
    ``w (atan((z_hi - z0) / w) - atan((z_lo - z0) / w)) / (z_hi - z_lo)`` (the peak's centring)."""
    return float(w * (np.arctan((z_hi - z0) / w) - np.arctan((z_lo - z0) / w)) / (z_hi - z_lo))


def peak_column(zc, z0: float, w: float, z_lo: float, z_hi: float) -> np.ndarray:
    """The peak shape's column for clipped standardised values ``zc``: ``1 / (1 + ((zc - z0) / w)^2)`` minus
    :func:`peak_mean` (its mean over TRAIN's range ``[z_lo, z_hi]``, so that its constant is not the baseline's)."""
    if not w > 0:
        raise EffectSpecError(f"channel shape 'peak': the half width w {w} is not positive")
    u = (np.asarray(zc, float) - z0) / w
    return 1.0 / (1.0 + u * u) - peak_mean(z0, w, z_lo, z_hi)


def shape_basis(spec, z) -> np.ndarray:
    """The columns of a channel's shape for its standardised values ``z``: ``z`` (``linear``), or ``zc`` and
    ``zc^2 - 1`` (``quadratic``) or ``zc`` and ``zc^3 - 3 zc`` (``odd``), or the one column of :func:`peak_column`
    with the spec's ``z0`` and ``w`` (``peak``), ``zc`` = ``z`` clipped to TRAIN's range
    ``[(lo - mean)/sd, (hi - mean)/sd]``."""
    shape = spec.get("shape", "linear")
    if shape == "linear":
        return np.asarray(z, float)[:, None]
    if shape == PEAK:
        z_lo, z_hi = _z_range(spec, num(spec, "lo"), num(spec, "hi"))
        return peak_column(np.clip(z, z_lo, z_hi), num(spec, "z0"), num(spec, "w"), z_lo, z_hi)[:, None]
    if shape not in SHAPES:
        raise EffectSpecError(f"channel shape {shape!r} is not one of {', '.join(SHAPES)}")
    mean, sd = num(spec, "mean"), num(spec, "sd")
    zc = np.clip(z, (num(spec, "lo") - mean) / sd, (num(spec, "hi") - mean) / sd)
    return np.column_stack([zc, zc ** 2 - 1.0 if shape == "quadratic" else zc ** 3 - 3.0 * zc])


def interaction_basis(spec, x, F) -> np.ndarray:
    """A channel's columns ``F`` (form factor times shape) with, when the spec has an interaction ``by`` (the
    load), the same columns times ``u = |m| / load_abs`` appended: ``[F, F u]``."""
    by = spec.get("by")
    if not by:
        return F
    if by not in INTERACTIONS:
        raise EffectSpecError(f"channel interaction {by!r} is not one of {', '.join(INTERACTIONS)}")
    load_abs = num(spec, "load_abs")
    if not load_abs > 0:
        raise EffectSpecError(f"channel {spec.get('channel')!r}: load_abs {load_abs} is not positive")
    u = np.abs(signal(x, "load")) / load_abs
    return np.hstack([F, F * u[:, None]])


def run_spread_entry(sg, level: str = "run") -> dict:
    """``{"run_spread": ...}`` of a run-level signal that records it (:func:`export_problem` reads it), else ``{}``."""
    return {"run_spread": float(sg["run_spread"])} if level == "run" and "run_spread" in sg else {}


#: the column of each interaction's input (the report's traced regressor)
_BY_COLUMN = {"load": "load_kg"}
_FORM_TEXT = {"friction": "scaling the friction level", "force_factor": "scaling the drive's force factor",
              "force": "adding a force", "inertia": "scaling the moving mass",
              "damping": "scaling the viscous damping"}


#: standard gravity [m/s^2]: the load's weight per kg in the run-level family's load column
G_N_PER_KG = 9.81
#: the required inputs that are run-level signals of the recording protocol: ``(column, transform)``; ``drive``
#: multiplies the run's value by the direction (the load in drive coordinates, opposing > 0), ``abs`` takes its size
INPUT_SIGNALS = (("voltage_V", "none"), ("load_kg", "drive"), ("load_kg", "abs"), ("direction", "none"))
TRANSFORMS = ("none", "drive", "abs", "square")
#: the columns of a run-level form (:func:`run_level_columns`): a drive gain, a force, a load term; a reduced form
#: (spec ``drop``) leaves one of them out
RUN_LEVEL_COLUMNS = ("gain", "offset", "load")
REGRESSOR_NAMES.update({"voltage_V": "voltage", "load_kg": "load", "direction": "direction"})


def signal_label(column: str, transform: str = "none") -> str:
    """The report's name of a run-level signal: the column, ``d*<column>``, ``|<column>|`` or ``<column>^2``."""
    return {"none": column, "drive": f"d*{column}", "abs": f"|{column}|", "square": f"{column}^2"}[transform]


def parameter_stem(column: str, transform: str = "none") -> str:
    """The stem of a run-level signal's parameter names: the column, ``d_``, ``abs_`` or ``sq_<column>`` (a legal FMI
    structured name, unlike the report's :func:`signal_label`: the parameters are FMU variables)."""
    return {"none": column, "drive": f"d_{column}", "abs": f"abs_{column}", "square": f"sq_{column}"}[transform]


def run_level_columns(x, Z) -> np.ndarray:
    """The run-level form of every column ``z_j`` of ``Z`` (n, m): ``(V0/V_ref z_j, z_j, g d m z_j)`` (a drive gain, a
    force [N] and a load term), the columns of ``z_1`` first (``3 m`` columns)."""
    Z = np.asarray(Z, float)
    gain, load = signal(x, "V0") / V_REF, G_N_PER_KG * signal(x, "d") * signal(x, "load")
    return np.column_stack([col for j in range(Z.shape[1]) for col in (gain * Z[:, j], Z[:, j], load * Z[:, j])])


def dropped_column(spec) -> int:
    """The index in :data:`RUN_LEVEL_COLUMNS` of the column a run-level spec's ``drop`` leaves out, -1 for none
    (:class:`EffectSpecError` for a ``drop`` that is not one of them)."""
    drop = spec.get("drop")
    if drop is None:
        return -1
    if drop not in RUN_LEVEL_COLUMNS:
        raise EffectSpecError(f"run-level spec of {spec.get('channel')!r}: drop {drop!r} is not one of "
                              f"{', '.join(RUN_LEVEL_COLUMNS)}")
    return RUN_LEVEL_COLUMNS.index(drop)


def kept_columns(spec) -> list[int]:
    """The indices of :data:`RUN_LEVEL_COLUMNS` a run-level spec keeps: all but its :func:`dropped_column`."""
    return [j for j in range(len(RUN_LEVEL_COLUMNS)) if j != dropped_column(spec)]


def transformed(c, d, transform: str) -> np.ndarray:
    """A signal's values ``c`` under a run-level transform (:data:`TRANSFORMS`): as they are (``none``), times the
    direction ``d`` (``drive``), their size (``abs``) or their square (``square``)."""
    if transform == "drive":
        return np.asarray(c, float) * np.asarray(d, float)
    if transform in ("abs", "square"):
        return np.abs(c) if transform == "abs" else np.square(np.asarray(c, float))
    if transform == "none":
        return c
    raise EffectSpecError(f"run-level transform {transform!r} is not one of {', '.join(TRANSFORMS)}")


def run_signal(x, column: str, transform: str, centre: float = 0.0, slope: float = 0.0) -> np.ndarray:
    """Each sample's run-level value of a signal: the run's mean of ``column`` less ``centre``, ``u``, times ``d``
    (``drive``), its size (``abs``) or ``u^2 - slope u`` (``square``)."""
    u = signal(x, signal_key(column, "run")) - centre
    out = transformed(u, signal(x, "d") if transform == "drive" else None, transform)
    return out - slope * u if transform == "square" else out


@register
class RunLevel(Effect):
    """``run_level``: a run's deviation from the model, a force gain and an offset, explained by a run-level signal.

    Each run's own deviation from the current model is estimated as a gain of the drive force and an offset
    (:mod:`l1b2.closeloop.runlevel`); a run-level signal ``c`` (a channel's run mean, a logged one's centred run mean
    times the direction or its curvature, the square less its line, the session clock's run mean, V0, the
    drive-coordinate load, its size, the direction) that explains them enters as
    ``dF = z (a V0/V_ref + b + c g d m)`` with ``z = (c - mean) / sd`` (TRAIN's run values), ``g d m`` the load's
    weight in drive coordinates: it scales the drive force, adds a force and scales the load's force (a signal
    that changes the contact changes the load's slope too); constant along the stroke, three parameters
    (``a``, ``b`` [N per standard deviation], ``c`` [1 per standard deviation]); a reduced form (spec ``drop``:
    ``gain``, ``offset`` or ``load``) has the other two, the full form with that parameter 0. Not listed by any
    candidate library: the loop offers the hypotheses of this family whose run-level evidence is significant
    (report family ``run_level_<signal>``).

    In ``Predictor.fmu`` (and :meth:`~l1b2.predictor.effects.model.ExtendedPredictor.free_run`) the run-level
    value of an input's signal (V0, the load, the direction, the temperature: :data:`INPUT_COLUMNS`, or a logged
    channel's own input, :func:`channel_inputs`) is the input's current value: exact when the input is constant
    within a run, as the rig's protocol holds V0, the load and the direction (:func:`export_problem` checks the
    spec's ``run_spread``). A run mean of the session clock is not exported.

    A logged run setting that is a category, each of its values its own effect, is its own family,
    :class:`l1b2.predictor.effects.category.RunLevelCategory` (``run_level_category``), in the same form.
    """

    kind = "run_level"
    regressor = "run"
    group = "run_level"
    description = "a run-level signal scaling the drive force and adding a force (constant along the stroke)"

    signals = ("load",)

    def needs(self, spec):
        return super().needs(spec) | {signal_key(str(spec.get("channel")), "run")}

    def features(self, spec, x):
        c = run_signal(x, str(spec.get("channel")), str(spec.get("transform", "none")),
                       *(float(spec.get(k, 0.0)) for k in ("centre", "slope")))
        sd = num(spec, "sd")
        if not sd > 0:
            raise EffectSpecError(f"run-level signal {spec.get('channel')!r}: standard deviation {sd} is not positive")
        z = (c - num(spec, "mean")) / sd
        return run_level_columns(x, z[:, None])[:, kept_columns(spec)]

    def width(self, spec):
        return len(kept_columns(spec))

    def hypotheses(self, signals_: list) -> list:
        """One hypothesis per run-level signal ``{"channel", "transform", "mean", "sd"}`` (``sd`` > 0; with ``centre``
        and ``slope``, a logged channel's ``d (c - centre)`` or ``(c - centre)^2 - slope (c - centre)``:
        :func:`run_signal`; with ``run_spread``, TRAIN's largest deviation from the run's value: the export checks
        it; with ``drop``, one of :data:`RUN_LEVEL_COLUMNS`, the reduced form without it, shape ``run, no <drop>``)."""
        out = []
        for sg in signals_:
            col, tr = sg["channel"], sg.get("transform", "none")
            label, stem = signal_label(col, tr), parameter_stem(col, tr)
            spec = {"channel": col, "transform": tr, "mean": float(sg["mean"]), "sd": float(sg["sd"]),
                    **({"centre": float(sg["centre"])} if sg.get("centre") else {}),
                    **({"slope": float(sg["slope"])} if sg.get("slope") else {}),
                    **run_spread_entry(sg), **({"drop": sg["drop"]} if sg.get("drop") else {})}
            keep = kept_columns(spec)
            names = [f"{stem}_run_{n}" for n in RUN_LEVEL_COLUMNS]
            out.append(self.hypothesis(
                [names[j] for j in keep], [("N", "N", "1")[j] for j in keep], spec,
                f"run, no {spec['drop']}" if "drop" in spec else "run",
                family=f"run_level_{label}", regressor=regressor_of(col), generic=True,
                description=f"run-level {label} scaling the drive force, adding a force and scaling the "
                            "load's force (run mean, constant along the stroke)"
                            + (f"; without the {spec['drop']} column" if "drop" in spec else "")))
        return out

    def grid(self, train):
        """The run-level hypothesis of every candidate channel (standardised by TRAIN's sample mean and sd; not a
        kind of :data:`NO_RUN_LEVEL_KINDS`, not one read along the stroke or whose run means follow the runs'
        lengths: :func:`levels_of`) and of the session clock. The loop does not list
        these: its run-level analysis offers :meth:`hypotheses` standardised by the runs' own values, for the signals
        whose evidence is significant."""
        chans = [ch for ch in train.channels if ch.get("sd", 0) > 0
                 and ch.get("kind") not in NO_RUN_LEVEL_KINDS and "run" in levels_of(ch)]
        if not any(ch["name"] == SESSION_TIME for ch in chans):
            t0, t1 = train.time_range
            chans.append({"name": SESSION_TIME, "mean": 0.5 * (t0 + t1), "sd": (t1 - t0) / np.sqrt(12.0)})
        return self.hypotheses([{"channel": ch["name"], "transform": "none", "mean": ch["mean"], "sd": ch["sd"],
                                 **run_spread_entry(ch)} for ch in chans])
