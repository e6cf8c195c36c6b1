"""The calibrated extended predictor: identified effects, the output filter, and the vectorised free run.

:class:`IdentifiedEffect` is one effect of a fitted model (its family's spec,
parameter names, units, values and standard errors);
:class:`ExtendedPredictor` is the whole calibrated model that
``Predictor.fmu`` carries: the baseline Eq. 29 setup (for ``v_base``), the
re-identified setup, the effects and an optional output filter of the speed
channel; :meth:`ExtendedPredictor.free_run` is the vectorised reference of
the FMU.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..frequency import contact_angle, effective_voltage
from ..setup import PredictorSetup
from .base import EffectSpecError, effect_features, needs, time_derivative
from .sensor import SpeedSensorGain


def _current_spec(spec: Mapping) -> dict:
    """``spec`` as a dict, a former categorical spec (kind ``run_level``, transform ``category``) in its family's
    own form (kind ``run_level_category``, no transform; the same scalars, features and names)."""
    out = dict(spec)
    if out.get("kind") == "run_level" and out.get("transform") == "category":
        out.pop("transform")
        out["kind"] = "run_level_category"
    return out


@dataclass(frozen=True)
class IdentifiedEffect:
    """One identified effect: its spec, parameter names, units, values and standard errors.

    ``cov``: the covariance matrix of ``phi`` (one row per parameter, the interval the standard errors come from),
    or None when not recorded (a record written before it was, or an identification without one); a calibration
    into a physical parameter carries its standard error from it (the delta method).
    """

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
    cov: tuple | None = None

    def to_dict(self) -> dict:
        return {"family": self.family, "label": self.label, "spec": dict(self.spec), "names": list(self.names),
                "units": list(self.units), "phi": [float(p) for p in self.phi],
                "stderr": [None if s is None else float(s) for s in self.stderr], "description": self.description,
                "regressors": list(self.regressors), "structural": self.structural,
                "cov": None if self.cov is None else [[float(v) for v in row] for row in self.cov]}

    @classmethod
    def from_dict(cls, d: Mapping) -> IdentifiedEffect:
        """The record of :meth:`to_dict`; a categorical run setting written as the ``run_level`` family's
        transform ``category`` (before it had a family of its own) is read as ``run_level_category``."""
        try:
            e = cls(str(d["family"]), str(d.get("label", d["family"])), _current_spec(d["spec"]), tuple(d["names"]),
                    tuple(d["units"]), tuple(float(p) for p in d["phi"]),
                    tuple(None if s is None else float(s) for s in d.get("stderr", [None] * len(d["phi"]))),
                    str(d.get("description", "")), tuple(d.get("regressors", ())), str(d.get("structural") or ""),
                    None if d.get("cov") is None else tuple(tuple(float(v) for v in row) for row in d["cov"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise EffectSpecError(f"effect record {d.get('family', '?')!r}: {exc}") from None
        if not (len(e.names) == len(e.units) == len(e.phi) == len(e.stderr)):
            raise EffectSpecError(f"effect {e.label}: names, units, phi and stderr differ in length")
        if e.cov is not None and (len(e.cov) != len(e.phi) or any(len(row) != len(e.phi) for row in e.cov)):
            raise EffectSpecError(f"effect {e.label}: cov is not {len(e.phi)} x {len(e.phi)}")
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
    start), with ``lo_m_s``/``hi_m_s`` when the channel's range clips it
    (:func:`apply_output_filter`), or None; ``source``: where the data came from (free text fields).
    """

    baseline: PredictorSetup
    model: PredictorSetup
    effects: tuple = ()
    output_filter: dict | None = None
    source: dict = field(default_factory=dict)
    speed_gain: dict | None = None

    @property
    def signals(self) -> set:
        """Every signal the effects read, as ``Predictor.fmu`` gives it: a signal of :data:`SIGNALS`, the input
        that gives a ``col:``/``run:`` signal of an input column, ``col:<column>`` for a logged channel's own input
        (:func:`~l1b2.predictor.effects.channels.fmu_signal`), or the key itself when no input gives it."""
        from .channels import fmu_signal
        out: set = set()
        for e in self.effects:
            out |= {fmu_signal(k) or k for k in needs(e.spec)}
        return out

    @property
    def needs_temperature(self) -> bool:
        return "T" in self.signals

    @property
    def channel_inputs(self) -> dict:
        """The logged channels the effects read through inputs of their own, ``{column: TRAIN's mean}``
        (:func:`~l1b2.predictor.effects.channels.channel_inputs`): ``Predictor.fmu``'s extra inputs."""
        from .channels import channel_inputs
        return channel_inputs(e.spec for e in self.effects)

    def to_dict(self) -> dict:
        return {"baseline": self.baseline.to_dict(), "model": self.model.to_dict(),
                "effects": [e.to_dict() for e in self.effects],
                "output_filter": None if self.output_filter is None else filter_dict(self.output_filter),
                "source": dict(self.source),
                **({} if self.speed_gain is None else {"speed_gain": dict(self.speed_gain)})}

    @classmethod
    def from_dict(cls, d: Mapping) -> ExtendedPredictor:
        try:
            base, model = PredictorSetup.from_dict(d["baseline"]), PredictorSetup.from_dict(d["model"])
        except (KeyError, TypeError) as exc:
            raise EffectSpecError(f"extended predictor: missing or bad {exc}") from None
        filt = d.get("output_filter")
        return cls(base, model, tuple(IdentifiedEffect.from_dict(e) for e in d.get("effects", [])),
                   None if filt is None else filter_dict(filt), dict(d.get("source", {})),
                   None if d.get("speed_gain") is None else SpeedSensorGain.from_dict(d["speed_gain"]).to_dict())

    def extra_force(self, x: Mapping) -> np.ndarray:
        """Sum of the effects' forces per sample [N].

        A ``col:``/``run:`` signal of an input column that ``x`` lacks is that input's value
        (:func:`~l1b2.predictor.effects.channels.with_input_signals`): a run-level signal is the input's current
        value, as in ``Predictor.fmu`` (exact when the input is constant within a run).
        """
        from .channels import with_input_signals
        n = len(np.asarray(x["V0"]))
        out = np.zeros(n)
        for e in self.effects:
            out = out + e.force(with_input_signals(x, needs(e.spec)))
        return out

    def free_run(self, t, s, V0, load, direction, v_start, run_index=None, temperature=None,
                 frequency=None, channels=None) -> np.ndarray:
        """Free-run speed per sample [m/s] along measured inputs (the vectorised reference of the FMU).

        Flat per-sample arrays, runs contiguous and labelled by ``run_index``
        (None: one run); ``v_start`` [m/s] one value per run (or scalar);
        ``temperature`` [degC] per sample when an effect needs it;
        ``frequency`` [Hz] the drive frequency per sample (None: each setup's
        nominal one, gain 1), which scales the setups' force factors by their
        frequency response (:mod:`l1b2.predictor.frequency`; effects see the commanded V0).
        ``channels``: ``{column: values per sample}`` of every logged channel
        of :attr:`channel_inputs` (the drive frequency's column ``frequency_Hz``
        defaults to ``frequency``), each as the FMU's input of that name.
        A run-level signal of an input (a run-level voltage effect, a logged
        setting's run value) is the input's value per sample, as in the FMU:
        the identified model's run mean when the input is constant within each
        run (the rig's protocol).
        """
        from ..simulate import RunLayout, free_run

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
        given = dict(channels or {})
        if frequency is not None:
            given.setdefault("frequency_Hz", frequency)
        for col in self.channel_inputs:
            if col not in given:
                raise EffectSpecError(f"an effect reads the logged channel {col!r}: pass channels={{{col!r}: "
                                      "values per sample}")
            x["col:" + col] = np.broadcast_to(np.asarray(given[col], float), t.shape)
        sig = self.signals
        if "T" in sig and "T" not in x:
            raise EffectSpecError("an effect needs the stator temperature: pass temperature= (degC per sample)")
        if sig & {"v_base", "a_base"}:
            x["v_base"] = free_run(b.params, x["s"], _drive(b, x["V0"], frequency), x["load"], x["d"], t, vs,
                                   b.slider_mass_kg, run_index, contact=_contact(b, x["V0"], frequency))
            x["a_base"] = time_derivative(x["v_base"], t, starts_sorted)
        F = self.extra_force(x) if self.effects else None
        m = self.model
        v = free_run(m.params, x["s"], _drive(m, x["V0"], frequency), x["load"], x["d"], t, vs, m.slider_mass_kg,
                     run_index, extra_force=F, contact=_contact(m, x["V0"], frequency))
        if self.speed_gain is not None:
            v = SpeedSensorGain.from_dict(self.speed_gain).apply(x["s"], v)
        if self.output_filter is not None:
            v = apply_output_filter(self.output_filter, v, starts_sorted)
        return v


def _contact(setup: PredictorSetup, V0, frequency) -> np.ndarray | None:
    """The half contact angle per sample [rad] of a pure-slip setup whose response carries the contact law, else None."""
    fr = setup.frequency
    if frequency is None or fr is None or not fr.has_contact or setup.params.drive_law != "pure_slip":
        return None
    V0, f = np.broadcast_arrays(np.asarray(V0, float), np.asarray(frequency, float))
    return contact_angle(V0, f, fr)


def _drive(setup: PredictorSetup, V0, frequency) -> np.ndarray:
    """The setup's effective drive amplitude ``V0 g(f)`` [V] (``V0`` at the nominal frequency or without a response)."""
    if frequency is None or setup.frequency is None:
        return np.asarray(V0, float)
    return effective_voltage(V0, frequency, setup.frequency)


#: the optional range limits of the speed channel in an output filter's mapping [m/s]
FILTER_RAILS = ("lo_m_s", "hi_m_s")


def filter_dict(filt: Mapping) -> dict:
    """An output filter's mapping as floats: ``a``, ``b0``, ``b1`` and the rails of :data:`FILTER_RAILS` it holds.

    Raises :class:`EffectSpecError` naming the key when one of ``a``, ``b0``, ``b1`` is missing or a value is not a
    number (a saved model with a malformed filter fails where it is read)."""
    missing = [k for k in ("a", "b0", "b1") if k not in filt]
    if missing:
        raise EffectSpecError(f"output filter: missing {', '.join(repr(k) for k in missing)} (it needs a, b0 and b1)")
    out = {}
    for k in ("a", "b0", "b1") + FILTER_RAILS:
        if k in filt:
            try:
                out[k] = float(filt[k])
            except (TypeError, ValueError):
                raise EffectSpecError(f"output filter: {k!r} is not a number ({filt[k]!r})") from None
    return out


def apply_output_filter(filt: Mapping, u, run_starts=None) -> np.ndarray:
    """``y(k) = a y(k-1) + b0 u(k) + b1 u(k-1)`` run by run, ``y(0) = (b0 + b1)/(1 - a) u(0)`` (steady start),
    then held within the speed channel's range when ``filt`` has rails: ``clip(y, lo_m_s, hi_m_s)`` [m/s] (a missing
    rail is no limit on its side; the filter's state is the unclipped ``y``, the range is the sensor's last stage)."""
    rails = (float(filt.get("lo_m_s", -np.inf)), float(filt.get("hi_m_s", np.inf)))
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
    return np.clip(y, *rails) if np.isfinite(rails).any() else y


def filter_step(filt: Mapping, y_prev, u, u_prev):
    """One step of the output filter: ``a y_prev + b0 u + b1 u_prev``."""
    return filt["a"] * y_prev + filt["b0"] * u + filt["b1"] * u_prev


def filter_start_gain(filt: Mapping) -> float:
    """Steady gain ``(b0 + b1)/(1 - a)`` of the output filter (1 when ``a`` is 1)."""
    a, b0, b1 = float(filt["a"]), float(filt["b0"]), float(filt["b1"])
    return (b0 + b1) / (1.0 - a) if abs(1.0 - a) > 1e-9 else 1.0
