"""Parameter recovery: is an injected physical parameter inside the identified model's 95 % interval?

For every rig injection whose effect family has a physical parameter
(:data:`TARGETS`), one seed of the study

1. runs the rig world with that injection, its size drawn from the seed in
   :attr:`RecoveryTarget.sizes` (the sign too, where the physics allows both),
2. identifies the Eq. 29 predictor *with* that family on TRAIN (the close
   loop's baseline settings: order 8, free-run maximum likelihood, the
   family's physical bounds), and
3. expresses the estimate in the rig's parameter: ``pulley_mu`` is the same
   law in both models (copied); the direction asymmetry's force parameters
   are carried into ``Stator.asym_b`` by the family's calibration
   (:func:`l1b2.predictor.effects.direction.calibrate_asymmetry`), its interval
   by the delta method (the calibration's gradient over the force parameters,
   by forward differences, times their covariance).

Each interval the identification offers is checked: the AR(1)-inflated
Fisher one (``ci95``, what the close-the-loop report shows) and the
cluster-by-run robust one (``ci95_robust``). Optionally the same family is also
fitted on the same seed's data *without* the injection (``clean_fit``): its
estimate there is what the model's structural error alone makes of the
family's parameter (the estimate's bias, for the study's diagnosis).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..data import measurements as dataio
from ..errors import IdentificationError
from ..ident.estimator import PredictorIdentifier
from ..ident.extra import ExtraForces
from ..predictor import effects as fx
from ..predictor.effects.direction import calibrate_asymmetry
from ..predictor.setup import PredictorSetup
from .world import World, world_data


@dataclass(frozen=True)
class RecoveryTarget:
    """One injection with a physical parameter: the family that models it and how its value is read.

    ``rig_parameter``: the injection's ``"Component.name"``; ``parameter``: the
    family's name of it (``mapping="copy"``: a parameter of the family with the
    same law) or the calibrated home (``mapping="calibrated"``); ``sizes``:
    ``(low, high)`` of the injected magnitude drawn per seed; ``signed``: the
    physics allows both signs (the sign is drawn too).
    """

    injection: str
    family: str
    rig_parameter: str
    parameter: str
    mapping: str
    sizes: tuple
    signed: bool = False

    def draw(self, seed: int) -> float:
        """The injected value of ``seed`` (its own stream, independent of the rig's draws)."""
        rng = np.random.default_rng([int(seed), 2801])
        value = float(rng.uniform(*self.sizes))
        return -value if self.signed and rng.uniform() < 0.5 else value


#: the injections whose family carries a physical parameter (the families of the rig's other injections are
#: force polynomials, splines or shape grids without one: drive_saturation, bar_waviness, bar_bump, thermal_drift)
TARGETS = {t.injection: t for t in [
    RecoveryTarget("pulley_friction", "load_path_friction", "Slider.pulley_mu", "pulley_mu", "copy", (0.05, 0.5)),
    RecoveryTarget("direction_asymmetry", "direction_asymmetry", "Stator.asym_b", "Stator.asym_b", "calibrated",
                   (0.02, 0.09), signed=True),
]}


@dataclass(frozen=True)
class FitSettings:
    """The identification of a recovery fit (the close loop's baseline search by default)."""

    order: int = 8
    n_starts: int = 4
    noise: str = "common"
    noise_fit: str = "alternate"


def family_forces(kind: str) -> tuple[ExtraForces, fx.Hypothesis]:
    """The family's one hypothesis as :class:`~l1b2.ident.extra.ExtraForces` (features over the data's columns).

    Only families whose grid is a single hypothesis over the data's own
    signals (no baseline speed, no TRAIN-dependent shape) qualify.
    """
    fam = fx.family(kind)
    try:
        hyps = fam.grid(None)   # a grid that reads TRAIN's summary is a shape search, not one hypothesis
    except (AttributeError, TypeError):
        hyps = []
    if len(hyps) != 1 or not fx.needs(hyps[0].spec) <= {"t", "s", "V0", "load", "d"}:
        raise IdentificationError(f"family {kind!r}: a recovery fit needs one hypothesis over t, s, V0, load, d")
    h = hyps[0]

    def features(df):
        x = {"t": df[dataio.TIME].to_numpy(float), "s": df[dataio.POSITION].to_numpy(float),
             "V0": df[dataio.VOLTAGE].to_numpy(float), "load": df[dataio.LOAD].to_numpy(float),
             "d": df[dataio.DIRECTION].to_numpy(float)}
        return fx.effect_features(h.spec, x)
    lower = tuple(b[0] for b in h.bounds) if h.bounds else None
    upper = tuple(b[1] for b in h.bounds) if h.bounds else None
    return ExtraForces(names=tuple(h.names), units=tuple(h.units), features=features, lower=lower, upper=upper,
                       description=h.description), h


def fit_family(train: dataio.Measurements, kind: str, settings: FitSettings = FitSettings()):
    """``(estimator, hypothesis)``: the Eq. 29 predictor with the family ``kind``, identified on ``train``."""
    extra, h = family_forces(kind)
    est = PredictorIdentifier(order=settings.order, criterion="free_run", fixed="recommended",
                              n_starts=settings.n_starts, seed=0, noise_fit=settings.noise_fit, noise=settings.noise,
                              extra=extra)
    est.fit(train.df, slider_mass_kg=train.slider_mass_kg, mask=np.array(train.mask))
    return est, h


def _phi_block(est, key: str) -> np.ndarray:
    p = len(est.extra_names_)
    return np.asarray(getattr(est, key), float)[-p:, -p:]


def _intervals(value: float, se: dict, dof: dict) -> dict:
    out = {}
    for kind, s in se.items():
        q = float(stats.t.ppf(0.975, dof[kind])) if np.isfinite(dof[kind]) else float(stats.norm.ppf(0.975))
        out[kind] = (value - q * s, value + q * s, s)
    return out


def read_parameter(target: RecoveryTarget, est, h, train: dataio.Measurements, mp) -> dict:
    """The target's value and intervals from a fitted estimator: ``{"estimate", kind: (lo, hi, se)}``.

    Interval kinds: ``"ar1"`` (the report's ``ci95``) and ``"robust"`` (``ci95_robust``).
    """
    dof = {"ar1": float(est.dof_), "robust": float(len(est.runs_) - 1)}
    if target.mapping == "copy":
        i = list(h.names).index(target.parameter)
        name = h.names[i]
        value = float(est.extra_params_[name])
        se = {"ar1": float(est.extra_stderr_[name]), "robust": float(est.extra_stderr_robust_[name])}
        return {"estimate": value, **_intervals(value, se, dof)}
    phi = np.array([est.extra_params_[n] for n in h.names], float)
    grad, value = calibration_gradient(est, h, phi, train, mp)
    se = {k: float(np.sqrt(grad @ _phi_block(est, c) @ grad)) for k, c in
          (("ar1", "cov_all_"), ("robust", "cov_robust_all_"))}
    return {"estimate": value, **_intervals(value, se, dof)}


def calibration_gradient(est, h, phi: np.ndarray, train: dataio.Measurements, mp,
                         rel_step: float = 0.05) -> tuple[np.ndarray, float]:
    """``(d asym_b / d phi, asym_b)``: the direction calibration's value and its gradient (forward differences).

    The step per parameter is ``rel_step`` of its magnitude (or of the largest
    magnitude when it is 0).
    """
    df = train.df
    pos = df[dataio.POSITION].to_numpy(float)
    source = {"operating_points": {
        "voltages_V": sorted(float(v) for v in np.unique(df[dataio.VOLTAGE].round(6))),
        "loads_kg": sorted(float(v) for v in np.unique(df[dataio.LOAD].round(9))),
        "position_m": [float(pos.min()), float(pos.max())]}}
    setup = PredictorSetup(est.params_, est.m_s_, est.T_s_)
    model = fx.ExtendedPredictor(setup, setup, (), None, source)

    def asym(p):
        eff = fx.IdentifiedEffect(h.family, h.family, dict(h.spec), tuple(h.names), tuple(h.units),
                                  tuple(float(v) for v in p), (None,) * len(p))
        return calibrate_asymmetry(model, eff, mp)["value"]

    value = asym(phi)
    scale = np.max(np.abs(phi)) or 1.0
    grad = np.zeros(len(phi))
    for j in range(len(phi)):
        step = rel_step * (abs(phi[j]) or scale)
        e = np.zeros(len(phi))
        e[j] = step
        grad[j] = (asym(phi + e) - value) / step
    return grad, value


def recover_one(injection: str, seed: int, world: World = World(), settings: FitSettings = FitSettings(),
                clean_fit: bool = True) -> dict:
    """One seed of the recovery study of ``injection`` (:data:`TARGETS`): a flat row (see the module)."""
    target = TARGETS[injection]
    t0 = time.perf_counter()
    truth_value = target.draw(seed)
    train, _, truth = world_data(world, seed, [(injection, {target.rig_parameter: truth_value})])
    mp = world.motor_params()
    est, h = fit_family(train, target.family, settings)
    got = read_parameter(target, est, h, train, mp)
    row = {"study": "coverage", "injection": injection, "family": target.family, "parameter": target.parameter,
           "seed": int(seed), "world": world.motor, "injected": truth_value, "estimate": got["estimate"],
           "train_runs": len(est.runs_)}
    for kind in ("ar1", "robust"):
        lo, hi, se = got[kind]
        row.update({f"se_{kind}": se, f"lo_{kind}": lo, f"hi_{kind}": hi,
                    f"covered_{kind}": bool(lo <= truth_value <= hi)})
    row["wrong_sign"] = bool(got["estimate"] * truth_value < 0)
    if clean_fit:
        clean, _, _ = world_data(world, seed)
        est0, h0 = fit_family(clean, target.family, settings)
        row["clean_estimate"] = read_parameter(target, est0, h0, clean, mp)["estimate"]
    row["wall_s"] = round(time.perf_counter() - t0, 2)
    return row
