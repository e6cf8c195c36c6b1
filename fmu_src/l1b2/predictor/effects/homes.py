"""Carry the effects of a calibrated extended predictor into the subsystem FMUs' parameters, where physics has a home.

An effect of the extended predictor is a force in the reduced Eq. 29 model;
the four-FMU co-simulation has physical parameters for some of the same
effects (each family's :attr:`~l1b2.predictor.effects.base.Effect.home`).
:func:`map_effects` asks each family to carry its identified effect there
(:meth:`~l1b2.predictor.effects.base.Effect.calibrate`); every other effect
is listed with the reason it is not mapped, and so is an effect with a home
whose parameters are not identified (a standard error that is missing or not
finite): the calibrated motor carries only identified values. The helpers here are what a
calibration against steady-state speeds needs: TRAIN's operating grid, the
predictor's steady-speed change of one effect and the physical model's speeds.
"""

from __future__ import annotations

import numpy as np

from .base import family
from .model import ExtendedPredictor, IdentifiedEffect


def physical_homes() -> dict:
    """``{family: "Component.a, Component.b"}`` of every registered family with a physical home."""
    from .base import families
    return {e.kind: ", ".join(e.home) for e in families() if e.home}


def operating_grid(model: ExtendedPredictor) -> list[tuple[float, float, float, float]]:
    """(s [m], V0 [V], load [kg], d) points of TRAIN's operating range (``model.source["operating_points"]``)."""
    op = model.source.get("operating_points") or {}
    volts = op.get("voltages_V") or [220.0, 270.0, 324.0]
    loads = op.get("loads_kg") or [0.0]
    lo, hi = op.get("position_m") or (0.0, 0.0)
    s_mid = 0.5 * (float(lo) + float(hi))
    return [(s_mid, float(V), float(m), d) for V in volts for m in loads for d in (1.0, -1.0)]


def predictor_speed_change(model: ExtendedPredictor, effect: IdentifiedEffect, grid) -> np.ndarray:
    """Steady speed of the extended predictor with the effect minus without it, per grid point [m/s]."""
    from ..model import steady_state as predictor_steady_state
    s, V, m, d = (np.array(c, float) for c in zip(*grid))
    x = {"s": s, "V0": V, "load": m, "d": d}
    F = effect.force(x)
    p, m_s = model.model.params, model.model.slider_mass_kg
    return (predictor_steady_state(p, s, V, m, d, m_s, extra_force=F)
            - predictor_steady_state(p, s, V, m, d, m_s))


def physical_speeds(mp, grid) -> np.ndarray:
    """Steady speeds [m/s] of the physical model ``mp`` at each grid point."""
    from ...physics.steady import steady_state as physical_steady_state
    return np.array([physical_steady_state(mp, s, V, m, int(d)).v_m_s for s, V, m, d in grid])


def map_effects(model: ExtendedPredictor, mp) -> tuple:
    """The motor with every mappable effect carried into its parameters, and one record per effect.

    Records: ``{"label", "family", "home", "mapped", "parameters" ({"Component.name": value}),
    "reason"}`` plus the calibration's figures where one was done.
    """
    out = mp
    records = []
    for e in model.effects:
        fam = family(e.spec.get("kind"))
        home = ", ".join(fam.home) if fam.home and fam.kind == e.family else None
        rec = {"label": e.label, "family": e.family, "home": home, "mapped": False, "parameters": {}}
        unidentified = [n for n, se in zip(e.names, e.stderr) if se is None or not np.isfinite(se)]
        if home is not None and unidentified:   # only identified values go into the calibrated motor
            rec["reason"] = (f"not identified ({', '.join(unidentified)} without a standard error): the subsystem "
                             "FMUs keep their own value")
            records.append(rec)
            continue
        done = fam.calibrate(e, model, out) if home is not None else None
        if done is not None:
            out, upd = done
            rec.update(mapped=True, **upd)
        elif home is not None:
            rec["reason"] = ("the subsystem FMUs have a parameter for it, but converting the predictor's force "
                             "parameters into it is not implemented yet")
        elif e.structural:
            rec["reason"] = "a term of the reduced model (relaxes Eq. 29's own linearisation): no subsystem parameter"
        else:
            rec["reason"] = "no physical home in the subsystem FMUs (generic or reduced-model term)"
        records.append(rec)
    return out, records
