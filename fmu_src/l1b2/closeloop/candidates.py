"""The candidate library: extensions of the paper's Eq. 29 predictor, each a hypothesis of a missing effect.

Every candidate adds a force to the slider's force balance (drive
coordinates: positive pushes the slider the way it is driven), linear in its
own parameters, ``dF = features(df) @ phi``; shape parameters (a wavelength, a
time constant, a defect position) are not identified but searched on a grid.
The features depend on the data's columns and, for state-dependent
candidates, on the *baseline model's* predicted speed (never on the measured
speed, so a free-run prediction on new data needs no measurement).

Candidates come from a :class:`CandidateLibrary`, a callable
``(ctx, df_train) -> list[CandidateForce]`` that the close-the-loop estimator
takes as an argument; libraries combine with ``+`` or :func:`combine`. The
default, :func:`default_library`, is ``named_library() + generic_library()``; the estimator uses
:func:`full_library`, which adds the two-regressor candidates (:func:`interaction_candidates`).

Named families (:func:`named_library`; physics, regressor):

* ``thermal_drift`` (time): self-heating of the stator moves its resonances
  (about -10 Hz/K, docs/explanation/physics.md), which changes the force factor of the
  drive; ``dF = V0 * f(t)``, f smooth in the experiment clock.
* ``thermal_drift_T`` (temperature): the same, driven by a measured stator
  temperature: ``dF = V0 (a (T-T0) + b (T-T0)^2)``.
* ``direction_asymmetry`` (direction): CH1 and CH2 excite B2 unequally
  (electrode area, polarisation): ``dF = d (a V0/V_ref + b)``.
* ``bar_waviness`` (position): periodic non-uniformity of the friction bar
  (grinding marks) modulates preload and friction:
  the thrust, the force factor and the damping are modulated:
  ``dF = (a + c V0/V_ref + e v/v_ref) cos(2 pi s/L) + (same) sin(2 pi s/L)`` plus the second
  harmonic, L searched around the residual's spectral peak.
* ``local_defect`` (position): a local bump or contamination of the bar:
  ``dF = a exp(-(s-c)^2 / (2 w^2))``, c and w on a grid.
* ``load_path_friction`` (load): Coulomb friction in the pulley, proportional
  to the hanging weight and opposing the motion: ``dF = -a g |m_load|``.
* ``drive_saturation`` (voltage): the drive's output limits or has a
  threshold: the force factor is not proportional to V0:
  ``dF = a (V0/V_ref)^2 + b (V0/V_ref)^3``.
* ``speed_dependent_friction`` (speed): non-Newtonian film or air drag:
  ``dF = -(a v + b v |v|)`` at the baseline's predicted drive speed.
* ``inertia_mismatch`` (acceleration): moving mass other than assumed
  (load inertia, coupling): ``dF = -a m_s dv/dt`` of the baseline prediction.

Generic fallback (:func:`generic_library`): a smooth term (splines, or the
regressor's own basis for run-level regressors) in one implicated regressor,
for residual structure that no named family explains.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..predictor import effects as fx
from ..predictor.effects import SPEED_REF, V_REF  # noqa: F401  (re-exported: the features' scales)
from .residuals import REGRESSORS

#: the approximation of Eq. 29 that the structural interaction candidates relax
EQ29_LINEARISATION = ("Eq. 29 holds the drive force's slope over speed constant; by Eq. 25 it changes with "
                      "omega U_w, i.e. with V0 (load slope and damping depend on the voltage)")
_LINEARISATION_PAIRS = ({"load", "voltage"}, {"voltage", "speed"})


@dataclass(frozen=True)
class CandidateForce:
    """One candidate: a family (with fixed shape) whose force is ``features(df) @ phi``.

    ``family`` names the hypothesis (``"load_path_friction"``, ``"smooth_time"``;
    the report's ``effect``), ``shape`` the grid point of its shape
    parameters, ``names``/``units`` its linear parameters. ``spec`` is the
    JSON-safe form of the features (:func:`l1b2.predictor.effects.effect_features`:
    kind and the TRAIN scalars it uses), which ``Predictor.fmu`` evaluates per step.
    """

    family: str
    regressor: str
    shape: str
    names: tuple
    units: tuple
    features: Callable[[pd.DataFrame], np.ndarray] = field(repr=False, compare=False)
    description: str = ""
    generic: bool = False
    also: tuple = ()   #: further regressors of an interaction (the report's traced names)
    #: non-empty when the candidate relaxes an approximation of Eq. 29 itself (what it relaxes), rather
    #: than adding an effect the paper's physics lacks; such terms are traced after the missing effects
    structural: str = ""
    spec: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def regressors(self) -> tuple:
        """Every regressor the candidate depends on (``regressor`` first)."""
        return (self.regressor,) + tuple(self.also)

    @property
    def label(self) -> str:
        return f"{self.family}[{self.shape}]" if self.shape else self.family

    @property
    def n_params(self) -> int:
        return len(self.names)


@dataclass
class Context:
    """What the features may use besides the data columns."""

    baseline_free_run: Callable[[pd.DataFrame], np.ndarray]  # predicted speed (data sign) on any df
    m_s: float
    time_range: tuple[float, float]
    position_range: tuple[float, float]
    temperature_ref: float | None = None
    spectral_period_m: float | None = None


def signals(df: pd.DataFrame, ctx: Context, wanted) -> dict:
    """The signals of :data:`l1b2.predictor.effects.SIGNALS` in ``wanted``, from a data frame.

    ``v_base`` is the baseline's free run on ``df`` and ``a_base`` its time
    derivative per run (:func:`l1b2.predictor.effects.time_derivative`).
    """
    x = {"t": df[dataio.TIME].to_numpy(float), "s": df[dataio.POSITION].to_numpy(float),
         "V0": df[dataio.VOLTAGE].to_numpy(float), "load": df[dataio.LOAD].to_numpy(float),
         "d": df[dataio.DIRECTION].to_numpy(float)}
    if "T" in wanted:
        x["T"] = df[dataio.TEMPERATURE].to_numpy(float)
    if {"v_base", "a_base"} & set(wanted):
        x["v_base"] = np.asarray(ctx.baseline_free_run(df), float)
        starts = [sl.start for _, sl in dataio.run_slices(df[dataio.RUN])]
        x["a_base"] = fx.time_derivative(x["v_base"], x["t"], sorted(starts))
    return x


def candidate(ctx: Context, family: str, regressor: str, shape: str, names, units, spec: dict, description: str,
              **kw) -> CandidateForce:
    """A candidate whose features are :func:`l1b2.predictor.effects.effect_features` of ``spec``."""
    wanted = fx.needs(spec)

    def features(df):
        return fx.effect_features(spec, signals(df, ctx, wanted))
    return CandidateForce(family, regressor, shape, tuple(names), tuple(units), features, description, spec=spec, **kw)


def _width(ctx: Context, spec: dict, df_train: pd.DataFrame) -> int:
    """Number of feature columns (parameters) of ``spec``."""
    return fx.effect_features(spec, signals(df_train.iloc[:2], ctx, fx.needs(spec))).shape[1]


def named_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Every named candidate with its shape grid."""
    t0, t1 = ctx.time_range
    s0, s1 = ctx.position_range
    out = []
    for n_inner in (2, 4):
        k = n_inner + 4
        out.append(candidate(
            ctx, "thermal_drift", "time", f"{k} splines in t", [f"thermal_gain_{j}" for j in range(k)], ["N"] * k,
            {"kind": "thermal_drift", "t_lo": t0, "t_hi": t1, "n_inner": n_inner},
            "drive force factor drifting with the experiment clock (stator self-heating)"))
    if dataio.TEMPERATURE in df_train.columns and ctx.temperature_ref is not None:
        out.append(candidate(ctx, "thermal_drift_T", "temperature", "", ("thermal_gain_T", "thermal_gain_T2"),
                             ("N/K", "N/K2"), {"kind": "thermal_drift_T", "T_ref": float(ctx.temperature_ref)},
                             "force factor drifting with the stator temperature"))
    out.append(candidate(ctx, "direction_asymmetry", "direction", "", ("asym_gain", "asym_offset_N"), ("N", "N"),
                         {"kind": "direction_asymmetry"}, "CH1 and CH2 excite the B2 mode with different strength"))
    periods = set(np.round(np.geomspace(2e-3, 12e-3, 13), 6))
    if ctx.spectral_period_m:
        periods |= {round(ctx.spectral_period_m * f, 6) for f in np.linspace(0.85, 1.15, 13)}
    # preload modulation acts on the friction thrust, on the force factor (V0) and on the interface's damping
    # (speed); a strong modulation acts non-linearly (second harmonic)
    for L in sorted(periods):
        out.append(candidate(
            ctx, "bar_waviness", "position", f"period {L * 1e3:.2f} mm",
            ("wave_cos_N", "wave_sin_N", "wave_cos_gain_N", "wave_sin_gain_N", "wave_cos_damp_N",
             "wave_sin_damp_N", "wave_cos2_N", "wave_sin2_N"), ("N",) * 8,
            {"kind": "bar_waviness", "period_m": float(L)}, "periodic non-uniformity of the friction bar"))
    for w in (0.6e-3, 1.2e-3, 2.4e-3):
        for c in np.arange(s0 + 2e-3, s1 - 2e-3 + 1e-9, 1.0e-3):
            out.append(candidate(
                ctx, "local_defect", "position", f"at {c * 1e3:+.0f} mm, width {w * 1e3:.1f} mm", ("defect_N",),
                ("N",), {"kind": "local_defect", "center_m": float(c), "width_m": float(w)},
                "local bump or contamination of the friction bar"))
    out.append(candidate(ctx, "load_path_friction", "load", "", ("pulley_mu",), ("1",), {"kind": "load_path_friction"},
                         "Coulomb friction in the load path, proportional to the hanging weight, opposing motion"))
    out.append(candidate(ctx, "drive_saturation", "voltage", "", ("sat_quad_N", "sat_cubic_N"), ("N", "N"),
                         {"kind": "drive_saturation"},
                         "drive output not proportional to the commanded V0 (saturation or threshold)"))
    out.append(candidate(ctx, "speed_dependent_friction", "speed", "", ("drag_lin_N", "drag_quad_N"), ("N", "N"),
                         {"kind": "speed_dependent_friction"}, "friction growing non-linearly with speed (film, air)"))
    out.append(candidate(ctx, "inertia_mismatch", "acceleration", "", ("mass_error",), ("1",),
                         {"kind": "inertia_mismatch", "m_s": float(ctx.m_s)}, "moving mass other than assumed"))
    return out


def _train_ranges(ctx: Context, df_train: pd.DataFrame) -> dict:
    """The TRAIN scalars of the generic terms: ranges of time, position, voltage, |load|, |baseline speed|."""
    t0, t1 = ctx.time_range
    s0, s1 = ctx.position_range
    V = df_train[dataio.VOLTAGE].to_numpy(float)
    vp = np.abs(ctx.baseline_free_run(df_train))
    return {"t_lo": float(t0), "t_hi": float(t1), "s_lo": float(s0), "s_hi": float(s1),
            "V_lo": float(V.min()), "V_hi": float(V.max()),
            "load_abs": float(np.max(np.abs(df_train[dataio.LOAD].to_numpy(float)))) or 1.0,
            "v_lo": float(np.min(vp)), "v_hi": float(np.max(vp))}


def interaction_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Effects of two regressors: named physical forms, and a generic low-order tensor product otherwise.

    Named (physics gives the form; ``d`` the direction, ``m`` the signed load,
    ``g`` gravity, ``x`` the scaled position):

    * ``load_slope_voltage`` (load, voltage): the load's effect on speed depends
      on the drive (slip friction whose speed slope changes with V0):
      ``dF = -a d m g (V0 - V_ref)/V_ref``;
    * ``damping_voltage`` (speed, voltage): damping that changes with the drive
      amplitude: ``dF = -a (v/v_ref) (V0 - V_ref)/V_ref``;
    * ``position_load`` (position, load): the load's effect varies along the
      bar (preload profile, pulley geometry): ``dF = -d m g (a x + b x^2)``.

    Generic: ``smooth_<A>_x_<B>``, the products of two regressors' linear and
    quadratic terms (scaled to [-1, 1]; direction: itself) over TRAIN's ranges.

    Four of them are *structural* (:data:`EQ29_LINEARISATION`): Eq. 29 holds
    the slope of the drive force over speed constant, while the pure-slip
    closed form behind it (Eq. 25, docs/explanation/physics.md:
    ``F_d = sigma (omega U_w/pi - v/2) + mu F_p (2 sqrt(1 - k0^2) - 1)``,
    ``k0 = v/(omega U_w)``) has a slope that changes with ``omega U_w``, i.e.
    with V0; so the damping and the load's effect on speed depend on the
    voltage. ``load_slope_voltage``, ``damping_voltage`` and their generic
    forms ``smooth_load_x_voltage``, ``smooth_voltage_x_speed`` relax that
    approximation of the paper's model; they are still found, added and
    reported like any other effect, but traced after the effects the model
    lacks (:func:`l1b2.closeloop.loop.order_traced`).
    """
    s0, s1 = ctx.position_range
    V_ref = float(np.median(df_train[dataio.VOLTAGE].to_numpy(float)))
    out = [
        candidate(ctx, "load_slope_voltage", "load", "", ("load_V_gain",), ("1",),
                  {"kind": "load_slope_voltage", "V_ref": V_ref},
                  "the load's effect on the speed depends on the drive voltage", also=("voltage",),
                  structural=EQ29_LINEARISATION),
        candidate(ctx, "damping_voltage", "speed", "", ("damping_V_N",), ("N",),
                  {"kind": "damping_voltage", "V_ref": V_ref},
                  "damping of the slider that changes with the drive voltage", also=("voltage",),
                  structural=EQ29_LINEARISATION),
        candidate(ctx, "position_load", "position", "", ("load_pos_1", "load_pos_2"), ("1", "1"),
                  {"kind": "position_load", "s_lo": float(s0), "s_hi": float(s1)},
                  "the load's effect varies along the bar", also=("load",)),
    ]
    ranges = _train_ranges(ctx, df_train)
    names = ["time", "position", "direction", "load", "voltage", "speed"]
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            spec = {"kind": "smooth_pair", "a": a, "b": b, **ranges}
            k = _width(ctx, spec, df_train)
            out.append(candidate(ctx, f"smooth_{a}_x_{b}", a, "", [f"smooth_{a}_x_{b}_{j}" for j in range(k)],
                                 ["N"] * k, spec,
                                 f"generic smooth interaction of {a} and {b}", generic=True, also=(b,),
                                 structural=EQ29_LINEARISATION if {a, b} in _LINEARISATION_PAIRS else ""))
    return out


def generic_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Fallback smooth terms, one per regressor available in the data."""
    s0, s1 = ctx.position_range
    ranges = _train_ranges(ctx, df_train)
    ranges["n_inner"] = int(np.clip(round((s1 - s0) / 1.5e-3), 4, 40))
    ranges["m_s"] = float(ctx.m_s)
    available = ["time", "position", "direction", "load", "voltage", "speed", "acceleration"]
    if dataio.TEMPERATURE in df_train.columns:
        T = df_train[dataio.TEMPERATURE].to_numpy(float)
        ranges.update(T_lo=float(T.min()), T_hi=float(T.max()))
        available.append("temperature")
    out = []
    for reg in REGRESSORS:
        if reg not in available:
            continue
        spec = {"kind": "smooth", "regressor": reg, **ranges}
        k = _width(ctx, spec, df_train)
        out.append(candidate(ctx, f"smooth_{reg}", reg, "", [f"smooth_{reg}_{j}" for j in range(k)], ["N"] * k, spec,
                             f"generic smooth force in {reg} (no named effect)", generic=True))
    return out


# ---------------------------------------------------------------------------
# libraries: what the close-the-loop estimator takes as its candidate argument
# ---------------------------------------------------------------------------

class CandidateSource(Protocol):
    """Anything that lists candidates for a fit: ``source(ctx, df_train) -> list[CandidateForce]``."""

    def __call__(self, ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]: ...


class CandidateLibrary:
    """A composable candidate library: the concatenation of its sources' candidates, in order.

    Parameters
    ----------
    *sources : CandidateSource
        Callables ``(ctx, df_train) -> list[CandidateForce]`` (functions such
        as :func:`named_candidates`, or other libraries).
    name : str, optional
        Shown by ``repr``; default: the sources' names joined by ``+``.

    Examples
    --------
    >>> lib = named_library() + generic_library()      # the default
    >>> lib = combine(named_library(), my_source)      # any callable source
    """

    def __init__(self, *sources: CandidateSource, name: str | None = None):
        for src in sources:
            if not callable(src):
                raise TypeError(f"a candidate source must be callable (ctx, df_train) -> list, got {src!r}")
        self.sources: tuple = tuple(sources)
        self.name = name or " + ".join(getattr(s, "name", None) or getattr(s, "__name__", repr(s))
                                       for s in self.sources)

    def __call__(self, ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
        out: list[CandidateForce] = []
        for src in self.sources:
            out.extend(src(ctx, df_train))
        return out

    def __add__(self, other: CandidateSource) -> CandidateLibrary:
        return combine(self, other)

    def __radd__(self, other: CandidateSource) -> CandidateLibrary:
        return combine(other, self)

    def __repr__(self) -> str:
        return f"CandidateLibrary({self.name})"


def combine(*sources: CandidateSource) -> CandidateLibrary:
    """One library listing the candidates of every source in turn."""
    return CandidateLibrary(*sources)


def named_library() -> CandidateLibrary:
    """The named physical families (:func:`named_candidates`)."""
    return CandidateLibrary(named_candidates, name="named")


def generic_library() -> CandidateLibrary:
    """The generic smooth term per regressor (:func:`generic_candidates`)."""
    return CandidateLibrary(generic_candidates, name="generic")


def interaction_library() -> CandidateLibrary:
    """Effects of two regressors, named and generic (:func:`interaction_candidates`)."""
    return CandidateLibrary(interaction_candidates, name="interactions")


def default_library() -> CandidateLibrary:
    """``named_library() + generic_library()``: the one-regressor candidates."""
    return named_library() + generic_library()


def full_library() -> CandidateLibrary:
    """``default_library() + interaction_library()``: what the close-the-loop estimator uses unless told otherwise."""
    return default_library() + interaction_library()
