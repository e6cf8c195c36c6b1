"""Parameter recovery: is an injected physical parameter inside the identified model's 95 % interval?

For every rig injection whose effect family has a physical parameter
(:data:`TARGETS`), one seed of the study

1. runs the rig world with that injection, its size drawn from the seed in
   :attr:`RecoveryTarget.sizes` (the sign too, where the physics allows both),
2. identifies the predictor (:attr:`FitSettings.model`: Eq. 29, the close
   loop's default baseline, or the pure-slip family) *with* that family on
   TRAIN (the close loop's baseline settings: order 8, free-run maximum
   likelihood, the family's physical bounds), and
3. expresses the estimate in the rig's parameter: ``pulley_mu`` is the same
   law in both models (copied); the direction asymmetry's force parameters
   are carried into ``Stator.asym_b`` by the family's calibration
   (:func:`l1b2.predictor.effects.direction.calibrate_asymmetry`), its interval
   by the delta method (the calibration's gradient over the force parameters,
   by forward differences, times their covariance); the drive frequency's
   target reads the identified response's ``f_b0_Hz`` (no effect family: the
   response is estimated because TRAIN's frequencies vary) against the
   stator's ``f_b0_Hz`` set for the seed. That response is an *effective*
   resonance (it absorbs the interface's damping, :mod:`l1b2.predictor.frequency`),
   so the target measures how far the effective value is from the physical
   one until a calibration maps one onto the other.

Each interval kind of :data:`INTERVALS` is checked (:func:`covariances`): the
AR(1)-inflated Fisher one (the close-the-loop report's ``ci95_model``), the
cluster-by-run robust one (its ``ci95_run``), and the cluster-robust ones whose
clusters are the runs of one operating condition (:data:`GROUPINGS`; ``level`` is
the report's ``ci95``, decision 0031). The drive frequency's response has the same kinds from its own run
influences (theta profiled out) and two more, with the runs at one drive frequency as one cluster
(``frequency``: Bell-McCaffrey CR2 with Satterthwaite degrees of freedom; ``frequency_cr1``: CR1 with t on
clusters - 1; :func:`frequency_parameter`); the other targets' rows have them as NaN (one drive
frequency). Each row also holds the correlation of the paired runs' mean
residuals (:func:`paired_residual_correlation`), the evidence for the level
at which errors are shared. Optionally the same family is also
fitted on the same seed's data *without* the injection (``clean_fit``): its
estimate there is what the model's structural error alone makes of the
family's parameter (the estimate's bias, for the study's diagnosis).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy import stats

from ..data import measurements as dataio
from ..errors import IdentificationError
from ..ident.clusters import RUN_GROUPINGS, frequency_levels, run_groups
from ..ident.estimator import PredictorIdentifier
from ..ident.extra import ExtraForces
from ..ident.frequency import ResponseLinearisation, coordinates
from ..ident.uncertainty import grouped_sandwich
from ..predictor import effects as fx
from ..predictor.effects.direction import calibration_gradient as direction_gradient
from ..predictor.effects.direction import delta_stderr
from ..predictor.frequency import FrequencyResponse
from ..predictor.setup import PredictorSetup
from .world import World, world_data

#: the interval kinds of every row (:func:`covariances`)
INTERVALS = ("ar1", "robust", "condition", "mirror", "level", "frequency", "frequency_cr1")


@dataclass(frozen=True)
class RecoveryTarget:
    """One injection with a physical parameter: the family that models it and how its value is read.

    ``rig_parameter``: the injection's ``"Component.name"``; ``parameter``: the
    family's name of it (``mapping="copy"``: a parameter of the family with the
    same law), the calibrated home (``mapping="calibrated"``), or the
    identification's own drive-frequency response (``mapping="frequency"``:
    ``family`` is empty, the value is the response's ``parameter`` in the fit's
    frequency record, the rig parameter is set on the world's motor and the rig
    records at ``world_changes``' frequencies); ``sizes``: ``(low, high)`` of
    the injected magnitude drawn per seed; ``signed``: the physics allows both
    signs (the sign is drawn too).
    """

    injection: str
    family: str
    rig_parameter: str
    parameter: str
    mapping: str
    sizes: tuple
    signed: bool = False
    #: :class:`~l1b2.study.world.World` fields this target's rig needs, as ``(field, value)`` pairs
    world_changes: tuple = ()

    def draw(self, seed: int) -> float:
        """The injected value of ``seed`` (its own stream, independent of the rig's draws)."""
        rng = np.random.default_rng([int(seed), 2801])
        value = float(rng.uniform(*self.sizes))
        return -value if self.signed and rng.uniform() < 0.5 else value


#: the rig's frequency plan of the drive-frequency target: five frequencies +-500 Hz around the drive, and a
#: +-50 Hz per-run offset (a drive that tracks the resonance), as in the frequency decision's measurements
FREQUENCY_PLAN = (("frequencies_Hz", (48000.0, 48250.0, 48500.0, 48750.0, 49000.0)), ("frequency_jitter_Hz", 50.0))

#: the injections whose family carries a physical parameter (the families of the rig's other injections are
#: force polynomials, splines or shape grids without one: drive_saturation, bar_waviness, bar_bump, thermal_drift),
#: and the drive frequency's response (B2 resonance of the rig's stator, drawn per seed, runs over 48-49 kHz)
TARGETS = {t.injection: t for t in [
    RecoveryTarget("pulley_friction", "load_path_friction", "Slider.pulley_mu", "pulley_mu", "copy", (0.05, 0.5)),
    RecoveryTarget("direction_asymmetry", "direction_asymmetry", "Stator.asym_b", "Stator.asym_b", "calibrated",
                   (0.02, 0.09), signed=True),
    RecoveryTarget("drive_frequency", "", "Stator.f_b0_Hz", "f_b0_Hz", "frequency", (47500.0, 48100.0),
                   world_changes=FREQUENCY_PLAN),
]}


@dataclass(frozen=True)
class FitSettings:
    """The identification of a recovery fit (the close loop's baseline search by default)."""

    order: int = 8
    n_starts: int = 4
    model: str = "eq29"
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
    """``(estimator, hypothesis)``: the predictor (``settings.model``) with the family ``kind``, identified on
    ``train`` (``kind`` empty: no family, hypothesis None; the frequency response is estimated when TRAIN's
    frequency varies)."""
    extra, h = family_forces(kind) if kind else (None, None)
    est = PredictorIdentifier(order=settings.order, criterion="free_run", fixed="recommended", model=settings.model,
                              n_starts=settings.n_starts, seed=0, noise_fit=settings.noise_fit, noise=settings.noise,
                              extra=extra)
    est.fit(train.df, slider_mass_kg=train.slider_mass_kg, mask=np.array(train.mask))
    return est, h


def _phi_block(est, cov) -> np.ndarray:
    p = len(est.extra_names_)
    return np.asarray(cov, float)[-p:, -p:]


#: the groupings of runs into clusters (:data:`l1b2.ident.clusters.RUN_GROUPINGS`): the rig's condition (V0,
#: signed load: one run opposing, one aiding the motion), its mirror image (V0, direction x load: the same load
#: relative to the motion, both directions) and both together (V0, |load|: the four runs of one voltage and load size)
GROUPINGS = RUN_GROUPINGS


def run_conditions(est, train: dataio.Measurements, grouping: str = "condition") -> list:
    """Each of the fit's runs' cluster label under ``grouping`` (:data:`GROUPINGS`), in the fit's run order."""
    return run_groups(train.df, est.runs_, grouping)


def covariances(est, train: dataio.Measurements) -> tuple[dict, dict]:
    """``({kind: joint covariance}, {kind: degrees of freedom})`` of the interval kinds (:data:`INTERVALS`).

    ``"ar1"``: the AR(1)-inflated Fisher covariance (t with the fit's dof);
    ``"robust"``: cluster-robust by run (t with runs - 1); each of
    :data:`GROUPINGS`: cluster-robust with the runs of one group as one
    cluster (:func:`run_conditions`; :func:`l1b2.ident.uncertainty.grouped_sandwich`,
    CR1 factor, t with clusters - 1).
    """
    covs = {"ar1": est.cov_all_, "robust": est.cov_robust_all_}
    dof = {"ar1": float(est.dof_), "robust": float(len(est.runs_) - 1)}
    for kind in GROUPINGS:
        covs[kind], n = grouped_sandwich(est.run_influence_, run_conditions(est, train, kind))
        dof[kind] = float(n - 1)
    return covs, dof


def paired_residual_correlation(est, train: dataio.Measurements) -> dict:
    """Correlation over conditions of the two runs' mean free-run residuals, per pairing of :func:`run_conditions`.

    ``{"condition": r, "mirror": r}``: within each pair the +direction run is
    the first member; NaN with fewer than three complete pairs. Errors shared
    by a pair of runs (what a cluster of the pair accounts for) show as r > 0.
    """
    df = train.df
    resid = df[dataio.SPEED].to_numpy(float) - est.predict_free_run(df)
    keep = np.asarray(train.mask, bool) & np.isfinite(resid)
    mean = pd.Series(resid[keep]).groupby(df[dataio.RUN].to_numpy()[keep]).mean()
    first = df.groupby(dataio.RUN, sort=False)[dataio.DIRECTION].first()
    out = {}
    for kind in ("condition", "mirror"):
        pairs: dict = {}
        for run, c in zip(est.runs_, run_conditions(est, train, kind)):
            if run in mean.index:
                pairs.setdefault(c, {})[int(np.sign(first[run]))] = float(mean[run])
        both = np.array([(p[1], p[-1]) for p in pairs.values() if 1 in p and -1 in p])
        out[kind] = float(np.corrcoef(both[:, 0], both[:, 1])[0, 1]) if len(both) >= 3 else float("nan")
    return out


def _intervals(value: float, se: dict, dof: dict) -> dict:
    out = {}
    for kind, s in se.items():
        q = float(stats.t.ppf(0.975, dof[kind])) if np.isfinite(dof[kind]) else float(stats.norm.ppf(0.975))
        out[kind] = (value - q * s, value + q * s, s)
    return out


def read_parameter(target: RecoveryTarget, est, h, train: dataio.Measurements, mp) -> dict:
    """The target's value and intervals from a fitted estimator: ``{"estimate", kind: (lo, hi, se)}``.

    Interval kinds: :func:`covariances` (``"ar1"`` is the close-loop report's model-based
    ``ci95_model``, ``"robust"`` its run-robust ``ci95_run``, ``"level"`` its ``ci95``).
    """
    if target.mapping == "frequency":
        return frequency_parameter(est, target.parameter, train)
    covs, dof = covariances(est, train)
    if target.mapping == "copy":
        j = len(est.param_names_all_) - len(h.names) + list(h.names).index(target.parameter)
        value = float(est.extra_params_[target.parameter])
        se = {k: float(np.sqrt(c[j, j])) for k, c in covs.items()}
    else:
        phi = np.array([est.extra_params_[n] for n in h.names], float)
        grad, value = calibration_gradient(est, h, phi, train, mp)
        se = {k: delta_stderr(grad, _phi_block(est, c)) for k, c in covs.items()}
    out = {"estimate": value, **_intervals(value, se, dof)}
    return {**out, **{k: (float("nan"),) * 3 for k in INTERVALS if k not in out}}   # one drive frequency


def frequency_parameter(est, name: str, train: dataio.Measurements | None = None) -> dict:
    """The identified frequency response's ``name`` with its intervals: ``{"estimate", kind: (lo, hi, se)}``.

    ``"ar1"``: the joint Fisher standard error of the fit's record
    (:func:`l1b2.ident.frequency.fit_frequency_response`) with the normal
    quantile. With ``train`` (the fit's data), the cluster-robust ones of the
    response's run influences (theta profiled out,
    :meth:`l1b2.ident.frequency.ResponseLinearisation.cluster_influence`):
    ``"robust"`` by run and each of :data:`GROUPINGS`, CR1 with t on
    clusters - 1 as :func:`covariances`; ``"frequency"``: the runs at one
    drive frequency as one cluster (:func:`l1b2.ident.clusters.frequency_levels`),
    Bell-McCaffrey CR2 with t on its Satterthwaite degrees of freedom;
    ``"frequency_cr1"``: the same clusters, CR1 with t on clusters - 1. A kind
    not computed (no ``train``, fewer than two clusters) is NaN.
    """
    rec = est.result_.frequency or {}
    if rec.get("status") != "estimated":
        raise IdentificationError(f"drive frequency: the response was not estimated ({rec.get('reason', 'no record')})")
    value = float(rec["response"][name])
    se = {"ar1": float((rec.get("stderr") or {}).get(name, float("nan")))}
    dof = {"ar1": float("inf")}
    if train is not None:
        more_se, more_dof = _frequency_robust(est, name, train)
        se.update(more_se)
        dof.update(more_dof)
    out = {"estimate": value, **_intervals(value, se, dof)}
    return {**out, **{k: (float("nan"),) * 3 for k in INTERVALS if k not in out}}


def _codes(labels) -> np.ndarray:
    index: dict = {}
    return np.array([index.setdefault(x, len(index)) for x in labels], int)


def _frequency_robust(est, name: str, train: dataio.Measurements) -> tuple[dict, dict]:
    """``({kind: se}, {kind: dof})`` of :func:`frequency_parameter`'s cluster-robust kinds."""
    resp = FrequencyResponse.from_dict(est.result_.frequency["response"])
    lin = ResponseLinearisation(est.result_, train.df, np.array(train.mask), resp.f_ref_Hz, coordinates(resp))
    j = ["f_b0_Hz", "zeta_b", "f_l0_Hz", "contact_V"].index(name)
    rows = lin.cluster_influence()[:, j:j + 1]
    groupings = {"robust": est.runs_, **{k: run_conditions(est, train, k) for k in GROUPINGS}}
    se, dof = {}, {}
    for kind, labels in groupings.items():
        cov, n = grouped_sandwich(rows, labels)
        if n >= 2:
            se[kind], dof[kind] = float(np.sqrt(cov[0, 0])), float(n - 1)
    levels = _codes(frequency_levels(train.df, est.runs_))
    if levels.max() >= 1:
        cov, n = grouped_sandwich(rows, levels)
        se["frequency_cr1"], dof["frequency_cr1"] = float(np.sqrt(cov[0, 0])), float(n - 1)
        u = lin.cluster_influence(levels, cr2=True)[:, j]
        se["frequency"], dof["frequency"] = float(np.sqrt(u @ u)), lin.bell_mccaffrey_dof(levels, j)
    return se, dof


def calibration_gradient(est, h, phi: np.ndarray, train: dataio.Measurements, mp,
                         rel_step: float = 0.05) -> tuple[np.ndarray, float]:
    """``(d asym_b / d phi, asym_b)`` of a fit of the direction family at ``phi``: the family's own
    :func:`l1b2.predictor.effects.direction.calibration_gradient` over TRAIN's operating points."""
    df = train.df
    pos = df[dataio.POSITION].to_numpy(float)
    source = {"operating_points": {
        "voltages_V": sorted(float(v) for v in np.unique(df[dataio.VOLTAGE].round(6))),
        "loads_kg": sorted(float(v) for v in np.unique(df[dataio.LOAD].round(9))),
        "position_m": [float(pos.min()), float(pos.max())]}}
    setup = PredictorSetup(est.params_, est.m_s_, est.T_s_)
    model = fx.ExtendedPredictor(setup, setup, (), None, source)
    eff = fx.IdentifiedEffect(h.family, h.family, dict(h.spec), tuple(h.names), tuple(h.units),
                              tuple(float(v) for v in phi), (None,) * len(phi))
    return direction_gradient(model, eff, mp, rel_step=rel_step)


def recover_one(injection: str, seed: int, world: World = World(), settings: FitSettings = FitSettings(),
                clean_fit: bool = True) -> dict:
    """One seed of the recovery study of ``injection`` (:data:`TARGETS`): a flat row (see the module)."""
    target = TARGETS[injection]
    t0 = time.perf_counter()
    truth_value = target.draw(seed)
    if target.world_changes:
        world = replace(world, **dict(target.world_changes))
    if target.mapping == "frequency":   # a motor parameter of the world, not a rig injection
        train, _, truth = world_data(world, seed, (), {target.rig_parameter: truth_value})
    else:
        train, _, truth = world_data(world, seed, [(injection, {target.rig_parameter: truth_value})])
    mp = world.motor_params()
    est, h = fit_family(train, target.family, settings)
    got = read_parameter(target, est, h, train, mp)
    row = {"study": "coverage", "injection": injection, "family": target.family, "parameter": target.parameter,
           "seed": int(seed), "world": world.motor, "injected": truth_value, "estimate": got["estimate"],
           "train_runs": len(est.runs_)}
    for kind in INTERVALS:
        lo, hi, se = got[kind]
        row.update({f"se_{kind}": se, f"lo_{kind}": lo, f"hi_{kind}": hi,
                    f"covered_{kind}": bool(lo <= truth_value <= hi) if np.isfinite(se) else None})
    row["wrong_sign"] = bool(got["estimate"] * truth_value < 0)
    if target.mapping == "frequency":
        row["frequency_levels"] = len(set(frequency_levels(train.df, est.runs_)))
    row.update({f"pair_corr_{k}": v for k, v in paired_residual_correlation(est, train).items()})
    if clean_fit:
        clean, _, _ = world_data(world, seed)   # the frequency target: the world's own B2 resonance
        est0, h0 = fit_family(clean, target.family, settings)
        row["clean_estimate"] = read_parameter(target, est0, h0, clean, mp)["estimate"]
    row["wall_s"] = round(time.perf_counter() - t0, 2)
    return row
