"""Carry the effects a close-the-loop job found into the subsystem FMUs' parameters, where physics has a home.

An effect of the extended predictor (:mod:`l1b2.predictor.effects`) is a
force in the reduced Eq. 29 model; the four-FMU co-simulation has physical
parameters for some of the same effects (:data:`PHYSICAL_HOMES`). Mapped:

* ``load_path_friction`` -> ``Slider.pulley_mu``: the same law in both
  (Coulomb friction ``pulley_mu g |m_load|`` opposing the motion; the
  predictor's parameter is that coefficient): copied, clipped at 0.
* ``direction_asymmetry`` -> ``Stator.asym_b`` (the B2 excitation is
  ``A_b V0 (1 + d asym_b)``): no closed form links it to the predictor's
  force ``d (a V0/V_ref + b)``, so ``asym_b`` is *calibrated*: the
  least-squares match, over TRAIN's operating points (voltages, loads, both
  directions, mid position), of the physical model's steady-speed change
  (:func:`l1b2.physics.steady.steady_state`, with and without ``asym_b``) to
  the extended predictor's (closed-form steady speeds with and without the
  effect's force); Gauss-Newton from 0 with a finite-difference slope.

Every other effect is listed with the reason it is not mapped.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..physics.params import MotorParams
from ..physics.steady import steady_state as physical_steady_state
from ..predictor import effects as fx
from ..predictor.model import steady_state as predictor_steady_state

#: effect family -> the subsystem parameter(s) that model the same physics
PHYSICAL_HOMES = {
    "load_path_friction": "Slider.pulley_mu",
    "direction_asymmetry": "Stator.asym_b",
    "thermal_drift": "Stator.df_dT_l_Hz_per_K, Stator.df_dT_b_Hz_per_K, Stator.thermal_tau_s",
    "thermal_drift_T": "Stator.df_dT_l_Hz_per_K, Stator.df_dT_b_Hz_per_K",
    "bar_waviness": "Stator.bar_wave_amp_m, Stator.bar_wave_period_m",
    "local_defect": "Stator.bar_bump_amp_m, Stator.bar_bump_center_m, Stator.bar_bump_width_m",
}
ASYM_LIMIT = 0.5    #: |asym_b| the calibration may reach [1]


def operating_grid(model: fx.ExtendedPredictor) -> list[tuple[float, float, float, float]]:
    """(s [m], V0 [V], load [kg], d) points of TRAIN's operating range (``model.source["operating_points"]``)."""
    op = model.source.get("operating_points") or {}
    volts = op.get("voltages_V") or [220.0, 270.0, 324.0]
    loads = op.get("loads_kg") or [0.0]
    lo, hi = op.get("position_m") or (0.0, 0.0)
    s_mid = 0.5 * (float(lo) + float(hi))
    return [(s_mid, float(V), float(m), d) for V in volts for m in loads for d in (1.0, -1.0)]


def _predictor_speed_change(model: fx.ExtendedPredictor, effect: fx.Effect, grid) -> np.ndarray:
    """Steady speed of the extended predictor with the effect minus without it, per grid point [m/s]."""
    s, V, m, d = (np.array(c, float) for c in zip(*grid))
    x = {"s": s, "V0": V, "load": m, "d": d}
    F = effect.force(x)
    p, m_s = model.model.params, model.model.slider_mass_kg
    return (predictor_steady_state(p, s, V, m, d, m_s, extra_force=F)
            - predictor_steady_state(p, s, V, m, d, m_s))


def _physical_speeds(mp: MotorParams, grid) -> np.ndarray:
    return np.array([physical_steady_state(mp, s, V, m, int(d)).v_m_s for s, V, m, d in grid])


def _with_asym(mp: MotorParams, a: float) -> MotorParams:
    return replace(mp, stator=replace(mp.stator, asym_b=float(a)))


def calibrate_asymmetry(model: fx.ExtendedPredictor, effect: fx.Effect, mp: MotorParams, *, iterations: int = 3,
                        h: float = 0.01) -> dict:
    """``Stator.asym_b`` whose steady-speed change matches the direction effect's (Gauss-Newton, see module)."""
    grid = operating_grid(model)
    target = _predictor_speed_change(model, effect, grid)
    v0 = _physical_speeds(_with_asym(mp, 0.0), grid)
    a, va = 0.0, v0
    for _ in range(iterations):
        J = (_physical_speeds(_with_asym(mp, a + h), grid) - va) / h
        if not np.any(J):
            break
        a = float(np.clip(a + J @ (target - (va - v0)) / (J @ J), -ASYM_LIMIT, ASYM_LIMIT))
        va = _physical_speeds(_with_asym(mp, a), grid)
    fit = va - v0
    rms_t = float(np.sqrt(np.mean(target ** 2)))
    return {"value": a, "grid_points": len(grid), "target_rms_m_s": rms_t,
            "misfit_rms_m_s": float(np.sqrt(np.mean((fit - target) ** 2)))}


def map_effects(model: fx.ExtendedPredictor, mp: MotorParams) -> tuple[MotorParams, list[dict]]:
    """The motor with every mappable effect carried into its parameters, and one record per effect.

    Records: ``{"label", "family", "mapped", "home", "parameters" ({"Component.name": value}),
    "reason"}`` plus the calibration's figures where one was done.
    """
    out = mp
    records = []
    for e in model.effects:
        home = PHYSICAL_HOMES.get(e.family)
        rec = {"label": e.label, "family": e.family, "home": home, "mapped": False, "parameters": {}}
        if e.family == "load_path_friction":
            mu = max(0.0, float(e.phi[0]))
            out = replace(out, slider=replace(out.slider, pulley_mu=mu))
            rec.update(mapped=True, parameters={"Slider.pulley_mu": mu},
                       reason="same law in both models: the identified coefficient, copied"
                              + ("" if e.phi[0] >= 0 else " (negative estimate clipped at 0)"))
        elif e.family == "direction_asymmetry":
            cal = calibrate_asymmetry(model, e, out)
            out = _with_asym(out, cal["value"])
            rec.update(mapped=True, parameters={"Stator.asym_b": cal["value"]}, calibration=cal,
                       reason="calibrated: least-squares match of the steady-speed change over TRAIN's "
                              "operating points")
        elif home is not None:
            rec["reason"] = ("the subsystem FMUs have a parameter for it, but converting the predictor's force "
                             "parameters into it is not implemented yet")
        elif e.structural:
            rec["reason"] = "a term of the reduced model (relaxes Eq. 29's own linearisation): no subsystem parameter"
        else:
            rec["reason"] = "no physical home in the subsystem FMUs (generic or reduced-model term)"
        records.append(rec)
    return out, records
