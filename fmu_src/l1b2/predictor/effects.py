"""Extra forces of the extended predictor, as pure functions of serialisable effect specs.

The close-the-loop estimator (:mod:`l1b2.closeloop.candidates`) extends the
paper's Eq. 29 predictor with forces ``dF = features @ phi`` [N, drive
coordinates: positive pushes the slider the way it is driven]. Each feature
matrix is a function of the per-sample signals and of a few scalars fixed on
the training data (ranges, a wavelength, a defect position). This module holds
that function, :func:`effect_features`, over a JSON-safe *spec* (``{"kind":
..., scalars}``), so the same code evaluates an effect on a whole data set
(identification) and one sample at a time inside ``Predictor.fmu``.

Signals (:data:`SIGNALS`, flat float arrays of one length):

* ``t`` [s]: the session clock (the data's ``time_s``; in the FMU its own time);
* ``s`` [m]: slider position; ``V0`` [V]: drive amplitude; ``load`` [kg]:
  signed load mass; ``d`` [1]: direction (+1/-1);
* ``T`` [degC]: measured stator temperature (only the temperature effects);
* ``v_base`` [m/s]: the *baseline* model's free-run speed (signed data
  convention), ``a_base`` [m/s^2] its time derivative
  (:func:`time_derivative`); only the state-dependent effects use them.

:class:`ExtendedPredictor` is the whole calibrated model: the baseline
Eq. 29 setup (for ``v_base``), the re-identified setup, the effects with
their parameters and an optional output filter of the speed channel; its
:meth:`ExtendedPredictor.free_run` is the vectorised reference of the FMU.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy.interpolate import BSpline

from ..errors import L1B2Error
from ..units import G_M_S2
from .setup import PredictorSetup

V_REF = 300.0    #: voltage scale of the features [V]
SPEED_REF = 0.2  #: speed scale of the features [m/s]

SIGNALS = ("t", "s", "V0", "load", "d", "T", "v_base", "a_base")

#: generic single-regressor kinds and the pair factors: regressor -> signals used
_REGRESSOR_SIGNALS = {"time": ("t",), "position": ("s",), "direction": ("d",), "load": ("load", "d"),
                      "voltage": ("V0",), "speed": ("v_base",), "acceleration": ("a_base", "d"),
                      "temperature": ("T",)}
#: named kinds -> the signals they use (besides V0 and d, which every kind may use)
_NAMED_SIGNALS = {
    "thermal_drift": ("t",), "thermal_drift_T": ("T",), "direction_asymmetry": (), "bar_waviness": ("s", "v_base"),
    "local_defect": ("s",), "load_path_friction": ("load",), "drive_saturation": (),
    "speed_dependent_friction": ("v_base",), "inertia_mismatch": ("a_base",), "load_slope_voltage": ("load",),
    "damping_voltage": ("v_base",), "position_load": ("s", "load"),
}


class EffectSpecError(L1B2Error):
    """An effect spec cannot be evaluated (unknown kind, missing scalar or signal)."""


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


def needs(spec: Mapping) -> set:
    """The signals (:data:`SIGNALS`) an effect spec reads."""
    kind = spec.get("kind")
    base = {"V0", "d"}
    if kind in _NAMED_SIGNALS:
        return base | set(_NAMED_SIGNALS[kind])
    if kind == "smooth":
        return base | set(_REGRESSOR_SIGNALS[_regressor(spec, "regressor")])
    if kind == "smooth_pair":
        return base | set(_REGRESSOR_SIGNALS[_regressor(spec, "a")]) | set(_REGRESSOR_SIGNALS[_regressor(spec, "b")])
    raise EffectSpecError(f"unknown effect kind {kind!r}; known: {', '.join(KINDS)}")


def _regressor(spec, key):
    r = spec.get(key)
    if r not in _REGRESSOR_SIGNALS:
        raise EffectSpecError(f"effect spec {spec.get('kind')!r}: {key} = {r!r} is not a regressor "
                              f"({', '.join(_REGRESSOR_SIGNALS)})")
    return r


def _num(spec, key) -> float:
    try:
        return float(spec[key])
    except KeyError:
        raise EffectSpecError(f"effect spec {spec.get('kind')!r} lacks the scalar {key!r}") from None


def _sig(x: Mapping, name: str) -> np.ndarray:
    try:
        return np.asarray(x[name], float)
    except KeyError:
        raise EffectSpecError(f"effect needs the signal {name!r}, not given") from None


def _lin_quad(u):
    return np.column_stack([u, u ** 2])


def _factor(reg: str, spec: Mapping, x: Mapping) -> np.ndarray:
    """The linear and quadratic terms of one regressor scaled to [-1, 1] (direction: itself), for pair terms."""
    if reg == "time":
        return _lin_quad(2 * scaled(_sig(x, "t"), _num(spec, "t_lo"), _num(spec, "t_hi")) - 1)
    if reg == "position":
        return _lin_quad(2 * scaled(_sig(x, "s"), _num(spec, "s_lo"), _num(spec, "s_hi")) - 1)
    if reg == "direction":
        return _sig(x, "d")[:, None]
    if reg == "load":
        return _lin_quad(_sig(x, "d") * _sig(x, "load") / _num(spec, "load_abs"))
    if reg == "voltage":
        return _lin_quad(2 * scaled(_sig(x, "V0"), _num(spec, "V_lo"), _num(spec, "V_hi")) - 1)
    if reg == "speed":
        return _lin_quad(2 * scaled(np.abs(_sig(x, "v_base")), _num(spec, "v_lo"), _num(spec, "v_hi")) - 1)
    raise EffectSpecError(f"regressor {reg!r} has no pair factor (pairs of: time, position, direction, load, "
                          f"voltage, speed)")


def _single(reg: str, spec: Mapping, x: Mapping) -> np.ndarray:
    """The generic smooth term of one regressor."""
    if reg == "time":
        return bspline_basis(scaled(_sig(x, "t"), _num(spec, "t_lo"), _num(spec, "t_hi")), 6)
    if reg == "position":
        return bspline_basis(scaled(_sig(x, "s"), _num(spec, "s_lo"), _num(spec, "s_hi")), int(_num(spec, "n_inner")))
    if reg == "direction":
        return _sig(x, "d")[:, None]
    if reg == "load":
        m = _sig(x, "load") / _num(spec, "load_abs")
        dm = _sig(x, "d") * m
        return np.column_stack([dm, np.abs(m), dm ** 2])
    if reg == "voltage":
        return _lin_quad(2 * scaled(_sig(x, "V0"), _num(spec, "V_lo"), _num(spec, "V_hi")) - 1)
    if reg == "speed":
        return bspline_basis(scaled(np.abs(_sig(x, "v_base")), _num(spec, "v_lo"), _num(spec, "v_hi")), 4)
    if reg == "acceleration":
        acc = _sig(x, "d") * _sig(x, "a_base") * _num(spec, "m_s")
        return np.column_stack([acc, np.abs(acc)])
    if reg == "temperature":
        return bspline_basis(scaled(_sig(x, "T"), _num(spec, "T_lo"), _num(spec, "T_hi")), 4)
    raise EffectSpecError(f"no generic term for regressor {reg!r}")


def _named(kind: str, spec: Mapping, x: Mapping) -> np.ndarray:
    V = _sig(x, "V0")
    d = _sig(x, "d")
    g = V / V_REF
    if kind == "thermal_drift":
        u = scaled(_sig(x, "t"), _num(spec, "t_lo"), _num(spec, "t_hi"))
        return g[:, None] * bspline_basis(u, int(_num(spec, "n_inner")))
    if kind == "thermal_drift_T":
        dT = _sig(x, "T") - _num(spec, "T_ref")
        return np.column_stack([g * dT, g * dT ** 2 / 10.0])
    if kind == "direction_asymmetry":
        return np.column_stack([d * g, d])
    if kind == "bar_waviness":
        ph = 2 * np.pi * _sig(x, "s") / _num(spec, "period_m")
        u = d * _sig(x, "v_base") / SPEED_REF
        c, s = np.cos(ph), np.sin(ph)
        return np.column_stack([c, s, g * c, g * s, u * c, u * s, np.cos(2 * ph), np.sin(2 * ph)])
    if kind == "local_defect":
        return np.exp(-0.5 * ((_sig(x, "s") - _num(spec, "center_m")) / _num(spec, "width_m")) ** 2)[:, None]
    if kind == "load_path_friction":
        return (-G_M_S2 * np.abs(_sig(x, "load")))[:, None]
    if kind == "drive_saturation":
        return np.column_stack([g ** 2, g ** 3])
    if kind == "speed_dependent_friction":
        vp = d * _sig(x, "v_base")
        return np.column_stack([-vp / SPEED_REF, -vp * np.abs(vp) / SPEED_REF ** 2])
    if kind == "inertia_mismatch":
        return (-_num(spec, "m_s") * d * _sig(x, "a_base"))[:, None]
    dv = (V - _num(spec, "V_ref")) / V_REF if kind in ("load_slope_voltage", "damping_voltage") else None
    if kind == "load_slope_voltage":
        return (-(d * _sig(x, "load") * G_M_S2) * dv)[:, None]
    if kind == "damping_voltage":
        return (-(d * _sig(x, "v_base")) / SPEED_REF * dv)[:, None]
    if kind == "position_load":
        w = d * _sig(x, "load") * G_M_S2
        xp = 2 * scaled(_sig(x, "s"), _num(spec, "s_lo"), _num(spec, "s_hi")) - 1
        return np.column_stack([-w * xp, -w * xp ** 2])
    raise EffectSpecError(f"unknown effect kind {kind!r}")


#: every kind :func:`effect_features` evaluates
KINDS = tuple(_NAMED_SIGNALS) + ("smooth", "smooth_pair")


def effect_features(spec: Mapping, x: Mapping) -> np.ndarray:
    """Feature matrix ``(n, k)`` of one effect: its force is ``effect_features(spec, x) @ phi`` [N].

    ``spec``: ``{"kind": one of KINDS, scalars...}`` (JSON-safe; from
    :attr:`l1b2.closeloop.candidates.CandidateForce.spec`); ``x``: the signals
    of :data:`SIGNALS` that :func:`needs` lists, flat arrays of one length.
    """
    kind = spec.get("kind")
    if kind == "smooth":
        return _single(_regressor(spec, "regressor"), spec, x)
    if kind == "smooth_pair":
        A = _factor(_regressor(spec, "a"), spec, x)
        B = _factor(_regressor(spec, "b"), spec, x)
        return np.column_stack([A[:, j] * B[:, k] for j in range(A.shape[1]) for k in range(B.shape[1])])
    if kind not in _NAMED_SIGNALS:
        raise EffectSpecError(f"unknown effect kind {kind!r}; known: {', '.join(KINDS)}")
    return _named(kind, spec, x)


# ---------------------------------------------------------------------------
# the calibrated, extended model
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Effect:
    """One identified effect: its spec, parameter names, units, values and standard errors."""

    family: str
    label: str
    spec: dict
    names: tuple
    units: tuple
    phi: tuple
    stderr: tuple
    description: str = ""
    regressors: tuple = ()
    structural: str = ""

    def to_dict(self) -> dict:
        return {"family": self.family, "label": self.label, "spec": dict(self.spec), "names": list(self.names),
                "units": list(self.units), "phi": [float(p) for p in self.phi],
                "stderr": [None if s is None else float(s) for s in self.stderr], "description": self.description,
                "regressors": list(self.regressors), "structural": self.structural}

    @classmethod
    def from_dict(cls, d: Mapping) -> Effect:
        try:
            e = cls(str(d["family"]), str(d.get("label", d["family"])), dict(d["spec"]), tuple(d["names"]),
                    tuple(d["units"]), tuple(float(p) for p in d["phi"]),
                    tuple(None if s is None else float(s) for s in d.get("stderr", [None] * len(d["phi"]))),
                    str(d.get("description", "")), tuple(d.get("regressors", ())), str(d.get("structural") or ""))
        except (KeyError, TypeError, ValueError) as exc:
            raise EffectSpecError(f"effect record {d.get('family', '?')!r}: {exc}") from None
        if not (len(e.names) == len(e.units) == len(e.phi) == len(e.stderr)):
            raise EffectSpecError(f"effect {e.label}: names, units, phi and stderr differ in length")
        needs(e.spec)  # the kind is known
        return e

    def force(self, x: Mapping) -> np.ndarray:
        """The effect's force per sample [N, drive coordinates]."""
        return effect_features(self.spec, x) @ np.asarray(self.phi, float)


@dataclass(frozen=True)
class ExtendedPredictor:
    """A calibrated extended Eq. 29 predictor: what ``Predictor.fmu`` carries after the close-the-loop job.

    ``baseline``: the Eq. 29 setup whose free run gives the signals
    ``v_base``/``a_base`` (identified first, never refit); ``model``: the
    re-identified setup that the effects' forces are added to; ``effects``:
    in the order they were chosen; ``output_filter``: ``{"a", "b0", "b1"}``
    of the speed channel (``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)``, steady
    start) or None; ``source``: where the data came from (free text fields).
    """

    baseline: PredictorSetup
    model: PredictorSetup
    effects: tuple = ()
    output_filter: dict | None = None
    source: dict = field(default_factory=dict)

    @property
    def signals(self) -> set:
        """Every signal (:data:`SIGNALS`) the effects read."""
        out: set = set()
        for e in self.effects:
            out |= needs(e.spec)
        return out

    @property
    def needs_temperature(self) -> bool:
        return "T" in self.signals

    def to_dict(self) -> dict:
        return {"baseline": self.baseline.to_dict(), "model": self.model.to_dict(),
                "effects": [e.to_dict() for e in self.effects],
                "output_filter": None if self.output_filter is None else {k: float(self.output_filter[k])
                                                                          for k in ("a", "b0", "b1")},
                "source": dict(self.source)}

    @classmethod
    def from_dict(cls, d: Mapping) -> ExtendedPredictor:
        try:
            base, model = PredictorSetup.from_dict(d["baseline"]), PredictorSetup.from_dict(d["model"])
        except (KeyError, TypeError) as exc:
            raise EffectSpecError(f"extended predictor: missing or bad {exc}") from None
        filt = d.get("output_filter")
        return cls(base, model, tuple(Effect.from_dict(e) for e in d.get("effects", [])),
                   None if filt is None else {k: float(filt[k]) for k in ("a", "b0", "b1")}, dict(d.get("source", {})))

    def extra_force(self, x: Mapping) -> np.ndarray:
        """Sum of the effects' forces per sample [N]."""
        n = len(np.asarray(x["V0"]))
        out = np.zeros(n)
        for e in self.effects:
            out = out + e.force(x)
        return out

    def free_run(self, t, s, V0, load, direction, v_start, run_index=None, temperature=None) -> np.ndarray:
        """Free-run speed per sample [m/s] along measured inputs (the vectorised reference of the FMU).

        Flat per-sample arrays, runs contiguous and labelled by ``run_index``
        (None: one run); ``v_start`` [m/s] one value per run (or scalar);
        ``temperature`` [degC] per sample when an effect needs it.
        """
        from .simulate import RunLayout, free_run

        t = np.asarray(t, float)
        lay = RunLayout(run_index, len(t))
        vs = np.broadcast_to(np.asarray(v_start, float).ravel(), (lay.R,)) if np.size(v_start) in (1, lay.R) else None
        if vs is None:
            raise EffectSpecError("v_start must be a scalar or one value per run")
        starts_sorted = np.sort(lay.starts)
        b = self.baseline
        x = {"t": t, "s": np.asarray(s, float), "V0": np.broadcast_to(np.asarray(V0, float), t.shape),
             "load": np.broadcast_to(np.asarray(load, float), t.shape),
             "d": np.broadcast_to(np.asarray(direction, float), t.shape)}
        if temperature is not None:
            x["T"] = np.asarray(temperature, float)
        sig = self.signals
        if "T" in sig and "T" not in x:
            raise EffectSpecError("an effect needs the stator temperature: pass temperature= (degC per sample)")
        if sig & {"v_base", "a_base"}:
            x["v_base"] = free_run(b.params, x["s"], x["V0"], x["load"], x["d"], t, vs, b.slider_mass_kg, run_index)
            x["a_base"] = time_derivative(x["v_base"], t, starts_sorted)
        F = self.extra_force(x) if self.effects else None
        m = self.model
        v = free_run(m.params, x["s"], x["V0"], x["load"], x["d"], t, vs, m.slider_mass_kg, run_index, extra_force=F)
        if self.output_filter is not None:
            v = apply_output_filter(self.output_filter, v, starts_sorted)
        return v


def apply_output_filter(filt: Mapping, u, run_starts=None) -> np.ndarray:
    """``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` run by run, ``y(0) = (b0 + b1)/(1 - a) u(0)`` (steady start)."""
    filt = {k: float(filt[k]) for k in ("a", "b0", "b1")}
    u = np.asarray(u, float)
    y = np.empty_like(u)
    gain0 = filter_start_gain(filt)
    starts = [0] if run_starts is None else [int(i) for i in run_starts]
    for i0, i1 in zip(starts, starts[1:] + [len(u)]):
        if i1 <= i0:
            continue
        y[i0] = gain0 * u[i0]
        for k in range(i0 + 1, i1):
            y[k] = filter_step(filt, y[k - 1], u[k], u[k - 1])
    return y


def filter_step(filt: Mapping, y_prev, u, u_prev):
    """One step of the output filter: ``a y_prev + b0 u + b1 u_prev``."""
    return filt["a"] * y_prev + filt["b0"] * u + filt["b1"] * u_prev


def filter_start_gain(filt: Mapping) -> float:
    """Steady gain ``(b0 + b1)/(1 - a)`` of the output filter (1 when ``a`` is 1)."""
    a, b0, b1 = float(filt["a"]), float(filt["b0"]), float(filt["b1"])
    return (b0 + b1) / (1.0 - a) if abs(1.0 - a) > 1e-9 else 1.0
