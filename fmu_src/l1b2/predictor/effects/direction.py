"""``direction_asymmetry`` (direction): CH1 and CH2 excite the B2 mode unequally (electrode area, polarisation).

``dF = d (a V0/V_ref + b)``. Home: ``Stator.asym_b`` (the B2 excitation is
``A_b V0 (1 + d asym_b)``); no closed form links it to the force, so it is
*calibrated*: the least-squares match, over TRAIN's operating points
(voltages, loads, both directions, mid position), of the physical model's
steady-speed change (:func:`l1b2.physics.steady.steady_state`, with and
without ``asym_b``) to the extended predictor's (closed-form steady speeds
with and without the effect's force); Gauss-Newton from 0 with a
finite-difference slope. Its standard error is the delta method's,
``sqrt(g' C g)`` with ``g`` the calibration's gradient over the effect's two
force parameters (:func:`calibration_gradient`) and ``C`` their covariance
(the effect's ``cov``: the gain and offset columns ``d V0/V_ref`` and ``d``
are strongly correlated, so their standard errors alone do not give it).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .base import Effect, drive_gain, register, signal

ASYM_LIMIT = 0.5    #: |asym_b| the calibration may reach [1]


def with_asymmetry(mp, a: float):
    """``mp`` with ``Stator.asym_b = a``."""
    return replace(mp, stator=replace(mp.stator, asym_b=float(a)))


def calibrate_asymmetry(model, effect, mp, *, iterations: int = 3, h: float = 0.01) -> dict:
    """``Stator.asym_b`` whose steady-speed change matches the direction effect's (Gauss-Newton, see module)."""
    from .homes import operating_grid, physical_speeds, predictor_speed_change
    grid = operating_grid(model)
    target = predictor_speed_change(model, effect, grid)
    v0 = physical_speeds(with_asymmetry(mp, 0.0), grid)
    a, va = 0.0, v0
    for _ in range(iterations):
        J = (physical_speeds(with_asymmetry(mp, a + h), grid) - va) / h
        if not np.any(J):
            break
        a = float(np.clip(a + J @ (target - (va - v0)) / (J @ J), -ASYM_LIMIT, ASYM_LIMIT))
        va = physical_speeds(with_asymmetry(mp, a), grid)
    fit = va - v0
    rms_t = float(np.sqrt(np.mean(target ** 2)))
    return {"value": a, "grid_points": len(grid), "target_rms_m_s": rms_t,
            "misfit_rms_m_s": float(np.sqrt(np.mean((fit - target) ** 2)))}


def calibration_gradient(model, effect, mp, *, rel_step: float = 0.05,
                         value: float | None = None) -> tuple[np.ndarray, float]:
    """``(d asym_b / d phi, asym_b)``: the calibration's (:func:`calibrate_asymmetry`) gradient over the effect's
    force parameters ``phi`` by forward differences, and its value at ``phi`` (``value``: when already known).

    The step per parameter is ``rel_step`` of its magnitude (or of the largest magnitude when it is 0).
    """
    phi = np.asarray(effect.phi, float)

    def asym(p):
        return calibrate_asymmetry(model, replace(effect, phi=tuple(float(v) for v in p)), mp)["value"]

    value = asym(phi) if value is None else float(value)
    scale = np.max(np.abs(phi)) or 1.0
    grad = np.zeros(len(phi))
    for j in range(len(phi)):
        step = rel_step * (abs(phi[j]) or scale)
        e = np.zeros(len(phi))
        e[j] = step
        grad[j] = (asym(phi + e) - value) / step
    return grad, value


def delta_stderr(grad, cov) -> float:
    """The delta method's standard error ``sqrt(g' C g)`` of a function with gradient ``grad`` of parameters with
    covariance ``cov`` (NaN when not finite or negative)."""
    g = np.asarray(grad, float)
    var = float(g @ np.asarray(cov, float) @ g)
    return float(np.sqrt(var)) if np.isfinite(var) and var >= 0 else float("nan")


@register
class DirectionAsymmetry(Effect):
    kind = "direction_asymmetry"
    regressor = "direction"
    description = "CH1 and CH2 excite the B2 mode with different strength"
    home = ("Stator.asym_b",)

    def features(self, spec, x):
        d = signal(x, "d")
        return np.column_stack([d * drive_gain(x), d])

    def grid(self, train):
        return [self.hypothesis(("asym_gain", "asym_offset_N"), ("N", "N"), {})]

    def calibrate(self, effect, model, mp):
        """``Stator.asym_b`` calibrated, with its delta-method standard error when the effect records its
        covariance (``stderr``: ``{"Stator.asym_b": se}``, None without one; ``calibration["gradient"]``)."""
        cal = calibrate_asymmetry(model, effect, mp)
        se = None
        if effect.cov is not None:
            grad, _ = calibration_gradient(model, effect, mp, value=cal["value"])
            cal["gradient"] = [float(g) for g in grad]
            se = delta_stderr(grad, effect.cov)
        return with_asymmetry(mp, cal["value"]), {
            "parameters": {"Stator.asym_b": cal["value"]}, "stderr": {"Stator.asym_b": se}, "calibration": cal,
            "reason": "calibrated: least-squares match of the steady-speed change over TRAIN's operating points"
                      + ("" if se is not None else "; no standard error (the effect's record has no covariance)")}
