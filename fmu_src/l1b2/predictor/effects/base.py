"""The effect family contract and its registry.

An :class:`Effect` is one family of extra forces of the extended Eq. 29
predictor, ``dF = features(spec, x) @ phi`` [N, drive coordinates: positive
pushes the slider the way it is driven]. One class holds everything about its
family: the regressor it shows up in, the signals it reads, its parameters
with units and its shape grid (:meth:`Effect.grid`), its features
(:meth:`Effect.features`, over a JSON-safe *spec* ``{"kind": ..., scalars}``
so that ``Predictor.fmu`` evaluates the same code per step), and, where the
subsystem FMUs model the same physics, its physical home (:attr:`Effect.home`)
with the calibration that carries it there (:meth:`Effect.calibrate`).

The registry maps a spec's ``kind`` to its family; :func:`register` adds one
(the package's families register on import, in the candidate order of the
close-the-loop library). Signals (:data:`SIGNALS`, flat float arrays of one
length): ``t`` [s] the session clock, ``s`` [m] slider position, ``V0`` [V]
drive amplitude, ``load`` [kg] signed load mass, ``d`` [1] direction (+1/-1),
``T`` [degC] measured stator temperature, ``v_base`` [m/s] the baseline
model's free-run speed (signed data convention) and ``a_base`` [m/s^2] its
time derivative (:func:`time_derivative`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.interpolate import BSpline

from ...errors import L1B2Error

V_REF = 300.0    #: voltage scale of the features [V]
SPEED_REF = 0.2  #: speed scale of the features [m/s]

SIGNALS = ("t", "s", "V0", "load", "d", "T", "v_base", "a_base")
#: the signals every effect may read without declaring them
ALWAYS_SIGNALS = ("V0", "d")


class EffectSpecError(L1B2Error):
    """An effect spec cannot be evaluated (unknown kind, missing scalar or signal)."""


# ---------------------------------------------------------------------------
# shared helpers of the features
# ---------------------------------------------------------------------------

def scaled(x, lo: float, hi: float) -> np.ndarray:
    """``x`` mapped from [lo, hi] to [0, 1] and clipped (zeros when the range is empty)."""
    x = np.asarray(x, float)
    return np.clip((x - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.zeros(len(x))


def bspline_basis(u: np.ndarray, n_inner: int, degree: int = 3) -> np.ndarray:
    """Cubic B-spline basis on [0, 1] with ``n_inner`` equally spaced inner knots (``u`` clipped to [0, 1))."""
    inner = np.linspace(0, 1, n_inner + 2)[1:-1]
    t = np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])
    n_basis = len(t) - degree - 1
    u = np.clip(np.asarray(u, float), 0.0, 1.0 - 1e-12)
    return np.column_stack([BSpline(t, np.eye(n_basis)[i], degree, extrapolate=False)(u) for i in range(n_basis)])


def derivative_step(v_prev, v, v_next, h_prev, h):
    """Second-order derivative at the middle of three samples spaced ``h_prev``, ``h`` [s] (numpy.gradient's)."""
    return (-(h / (h_prev * (h_prev + h))) * v_prev + ((h - h_prev) / (h_prev * h)) * v
            + (h_prev / (h * (h_prev + h))) * v_next)


def time_derivative(v, t, run_starts=None) -> np.ndarray:
    """dv/dt per sample [units of v per s], run by run: one-sided at a run's ends, :func:`derivative_step` inside.

    ``run_starts``: index of each run's first sample (default: one run). A
    run of one sample has derivative 0.
    """
    v = np.asarray(v, float)
    t = np.asarray(t, float)
    n = len(v)
    starts = [0] if run_starts is None else [int(i) for i in run_starts]
    bounds = list(zip(starts, starts[1:] + [n]))
    out = np.zeros(n)
    for i0, i1 in bounds:
        if i1 - i0 < 2:
            continue
        vv, tt = v[i0:i1], t[i0:i1]
        h = np.diff(tt)
        o = out[i0:i1]
        o[0] = (vv[1] - vv[0]) / h[0]
        o[-1] = (vv[-1] - vv[-2]) / h[-1]
        if i1 - i0 > 2:
            o[1:-1] = derivative_step(vv[:-2], vv[1:-1], vv[2:], h[:-1], h[1:])
    return out


def num(spec: Mapping, key: str) -> float:
    """The scalar ``spec[key]`` as a float (:class:`EffectSpecError` when missing)."""
    try:
        return float(spec[key])
    except KeyError:
        raise EffectSpecError(f"effect spec {spec.get('kind')!r} lacks the scalar {key!r}") from None


def signal(x: Mapping, name: str) -> np.ndarray:
    """The signal ``x[name]`` as a float array (:class:`EffectSpecError` when not given)."""
    try:
        return np.asarray(x[name], float)
    except KeyError:
        raise EffectSpecError(f"effect needs the signal {name!r}, not given") from None


def drive_gain(x: Mapping) -> np.ndarray:
    """``V0 / V_REF`` per sample: the force factor's scale of most named families."""
    return signal(x, "V0") / V_REF


# ---------------------------------------------------------------------------
# what a family's grid sees of TRAIN, and what it proposes
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class TrainingSummary:
    """What an effect's shape grid may use of the training data (computed once per fit by the loop).

    ``ranges``: the TRAIN scalars of the generic terms (``t_lo``/``t_hi``,
    ``s_lo``/``s_hi``, ``V_lo``/``V_hi``, ``load_abs``, ``v_lo``/``v_hi`` of
    the baseline's |free-run speed|); ``temperature_range`` (min, max) [degC]
    when the data log a temperature; ``channels`` the candidate channels.
    """

    m_s: float
    time_range: tuple
    position_range: tuple
    voltage_median: float
    ranges: dict
    temperature_ref: float | None = None
    temperature_range: tuple | None = None
    spectral_period_m: float | None = None
    #: the logged channels (:mod:`l1b2.predictor.effects.channels`): ``{"name", "kind", "mean", "sd", "lo", "hi",
    #: "within_run"}`` per numeric column beyond the required ones, and the session clock
    channels: tuple = ()
    #: the baseline's smallest viscous damping over TRAIN [N s/m] (None: not known): the floor a channel's damping
    #: form keeps (:func:`l1b2.predictor.effects.channels.damping_bounds`)
    damping_N_s_per_m: float | None = None

    @property
    def has_temperature(self) -> bool:
        return self.temperature_range is not None


@dataclass(frozen=True)
class Hypothesis:
    """One grid point of a family: a candidate force with fixed shape, linear in ``names``.

    ``family`` names the hypothesis in reports (the family's ``kind`` for
    named families; ``smooth_<regressor>`` etc. for generic ones), ``spec``
    is the JSON-safe form :func:`effect_features` evaluates.
    """

    family: str
    regressor: str
    shape: str
    names: tuple
    units: tuple
    spec: dict
    description: str = ""
    generic: bool = False
    also: tuple = ()
    structural: str = ""
    #: physical ranges of the parameters, ``((lo, hi), ...)`` one per name (empty: unbounded); the identification
    #: keeps each value inside its range
    bounds: tuple = ()


# ---------------------------------------------------------------------------
# the family contract
# ---------------------------------------------------------------------------

class Effect:
    """One effect family (subclass it, set the class attributes, and :func:`register` an instance).

    Class attributes
    ----------------
    kind : str
        The registry key, ``spec["kind"]``.
    regressor : str
        The data regressor the effect shows up in (the report's ``traced_to``).
    also : tuple
        Further regressors (two-regressor interactions).
    signals : tuple
        Signals of :data:`SIGNALS` it reads besides ``V0`` and ``d``.
    group : {"named", "generic", "interaction"}
        Which candidate library lists it (``l1b2.closeloop.candidates``).
    description : str
        One line for reports and the FMU's variable descriptions.
    structural : str
        Non-empty when it relaxes an approximation of Eq. 29 itself (what it relaxes).
    home : tuple
        ``"Component.parameter"`` of the subsystem FMUs that model the same physics (empty: none).
    exportable : bool
        False when ``Predictor.fmu`` cannot evaluate the family's specs: a model carrying it is not exported
        (:func:`l1b2.predictor.effects.channels.export_problem`). Every family of the package is but the session's
        blocks (:mod:`l1b2.predictor.effects.blocks`: the session clock is no input of the FMU).
    run_folds : bool
        True when the family reads the session clock only to place each run in a block whose level the runs within
        it carry: its refits are cross-validated over runs, not over blocks of the session
        (:func:`l1b2.closeloop.acceptance.time_dependent`).
    session_average : bool
        True when the family is a fact of the recorded session whose columns average to zero over TRAIN's runs: the
        calibrated model leaves it out (:func:`l1b2.closeloop.calibrated.calibrated_model`).
    """

    kind: str = ""
    regressor: str = ""
    also: tuple = ()
    signals: tuple = ()
    group: str = "named"
    description: str = ""
    structural: str = ""
    home: tuple = ()
    exportable: bool = True
    run_folds: bool = False
    session_average: bool = False

    def needs(self, spec: Mapping) -> set:
        """The signals a spec of this family reads."""
        return set(ALWAYS_SIGNALS) | set(self.signals)

    def features(self, spec: Mapping, x: Mapping) -> np.ndarray:
        """Feature matrix ``(n, k)``: the force is ``features(spec, x) @ phi`` [N]."""
        raise NotImplementedError

    def channel_mean(self, spec: Mapping) -> float | None:
        """TRAIN's mean of the logged channel a spec reads (``spec["channel"]``): its ``mean`` scalar (the
        samples' for a channel, the runs' values' for a run-level signal), None when it records none."""
        return float(spec["mean"]) if "mean" in spec else None

    def grid(self, train: TrainingSummary) -> list[Hypothesis]:
        """The family's hypotheses (one per shape-grid point) for a fit on ``train``."""
        raise NotImplementedError

    def calibrate(self, effect, model, mp):
        """Carry an identified effect into the subsystem parameters: ``(MotorParams, record)`` or None.

        ``effect``: :class:`l1b2.predictor.effects.model.IdentifiedEffect` of
        this family; ``model``: the whole
        :class:`~l1b2.predictor.effects.model.ExtendedPredictor`; ``mp``: the
        motor so far. ``record`` has ``parameters`` (``{"Component.name":
        value}``), ``reason`` and optionally ``calibration``. None: the home
        is declared but no conversion exists.
        """
        return None

    def hypothesis(self, names, units, spec: dict, shape: str = "", **kw) -> Hypothesis:
        """A :class:`Hypothesis` of this family (``spec["kind"]`` set to :attr:`kind`)."""
        kw.setdefault("family", self.kind)
        kw.setdefault("regressor", self.regressor)
        kw.setdefault("description", self.description)
        kw.setdefault("also", tuple(self.also))
        kw.setdefault("structural", self.structural)
        return Hypothesis(names=tuple(names), units=tuple(units), spec={"kind": self.kind, **spec}, shape=shape, **kw)

    def width(self, spec: Mapping) -> int:
        """Number of feature columns (parameters) of ``spec``."""
        return self.features(spec, {s: np.ones(2) for s in SIGNALS}).shape[1]


# ---------------------------------------------------------------------------
# the registry
# ---------------------------------------------------------------------------

_REGISTRY: dict[str, Effect] = {}


def register(effect: Effect | type) -> Effect | type:
    """Add a family to the registry (an instance, or a class, which is instantiated); usable as a decorator.

    A family registered under a kind already present replaces it.
    """
    inst = effect() if isinstance(effect, type) else effect
    if not isinstance(inst, Effect) or not inst.kind:
        raise EffectSpecError(f"{effect!r}: an effect family is an Effect with a non-empty kind")
    _REGISTRY[inst.kind] = inst
    return effect


def unregister(kind: str) -> None:
    """Remove a family (what :func:`register` added; a test's toy family)."""
    _REGISTRY.pop(kind, None)


def families(group: str | None = None) -> tuple:
    """Every registered family (of ``group``, when given), in registration order."""
    return tuple(e for e in _REGISTRY.values() if group is None or e.group == group)


def kinds() -> tuple:
    """Every registered kind, in registration order."""
    return tuple(_REGISTRY)


def family(kind) -> Effect:
    """The family of a kind (:class:`EffectSpecError` when unknown)."""
    try:
        return _REGISTRY[kind]
    except (KeyError, TypeError):
        raise EffectSpecError(f"unknown effect kind {kind!r}; known: {', '.join(_REGISTRY)}") from None


def needs(spec: Mapping) -> set:
    """The signals (:data:`SIGNALS`) an effect spec reads."""
    return family(spec.get("kind")).needs(spec)


def effect_features(spec: Mapping, x: Mapping) -> np.ndarray:
    """Feature matrix ``(n, k)`` of one effect: its force is ``effect_features(spec, x) @ phi`` [N].

    ``spec``: ``{"kind": a registered kind, scalars...}`` (JSON-safe); ``x``:
    the signals :func:`needs` lists, flat arrays of one length.
    """
    return family(spec.get("kind")).features(spec, x)
