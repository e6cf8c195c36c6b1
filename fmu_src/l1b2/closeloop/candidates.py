"""The candidate library: extensions of the paper's Eq. 29 predictor, each a hypothesis of a missing effect.

Every candidate adds a force to the slider's force balance (drive
coordinates: positive pushes the slider the way it is driven), linear in its
own parameters, ``dF = features(df) @ phi``; shape parameters (a wavelength, a
time constant, a defect position) are not identified but searched on a grid.
The features depend on the data's columns and, for state-dependent
candidates, on the *baseline model's* predicted speed (never on the measured
speed, so a free-run prediction on new data needs no measurement).

The families, their forms and grids live in one registry,
:mod:`l1b2.predictor.effects` (one :class:`~l1b2.predictor.effects.Effect`
per family); this module turns a family's hypotheses into
:class:`CandidateForce` objects over data frames. Candidates come from a
:class:`CandidateLibrary`, a callable ``(ctx, df_train) ->
list[CandidateForce]`` that the close-the-loop estimator takes as an
argument; libraries combine with ``+`` or :func:`combine`. The default,
:func:`default_library`, is ``named_library() + generic_library()`` (the
registry's ``named`` and ``generic`` groups); the estimator uses
:func:`full_library`, which adds the two-regressor candidates
(:func:`interaction_candidates`). A family registered at run time
(:func:`l1b2.predictor.effects.register`) is listed by its group's library.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
import pandas as pd

from ..data import measurements as dataio
from ..predictor import effects as fx
from ..predictor.frequency import contact_angle, sample_frequency
from ..predictor.model import viscous_damping
from ..predictor.effects import SPEED_REF, V_REF  # noqa: F401  (re-exported: the features' scales)
from ..predictor.effects.interactions import EQ29_LINEARISATION  # noqa: F401  (re-exported)
from .auxiliary import NOT_CANDIDATES, derived_columns, label_columns, varies_within_runs
from .relabels import follows_plan
from .runclock import time_in_run_s


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
    #: physical ranges of the parameters (``((lo, hi), ...)``, empty: unbounded), kept by the identification
    bounds: tuple = ()

    def clip(self, phi) -> np.ndarray:
        """``phi`` inside :attr:`bounds` (unchanged when unbounded)."""
        phi = np.asarray(phi, float).ravel()
        if not self.bounds:
            return phi
        lo, hi = np.array(self.bounds, float).T
        return np.clip(phi, lo, hi)

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
    #: :func:`training_summary` per training frame (by identity), computed once per fit
    summaries: dict = field(default_factory=dict, repr=False, compare=False)
    #: logged columns that are measured responses of the motor (listed, never candidates; the user's setting
    #: ``CloseLoop(response_columns=...)``, default :data:`l1b2.predictor.effects.channels.RESPONSE_COLUMNS`)
    response_columns: tuple = fx.channels.RESPONSE_COLUMNS
    #: the baseline's smallest viscous damping over TRAIN [N s/m] (:func:`baseline_damping`; None: not known), the
    #: floor the damping forms of the channels keep (:func:`l1b2.predictor.effects.channels.damping_bounds`)
    damping_N_s_per_m: float | None = None
    #: :func:`signals` of the last few frames (by identity; their arrays read-only), not pickled with the context
    signal_cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __getstate__(self):
        return {**self.__dict__, "signal_cache": {}}


#: frames whose signals :func:`signals` keeps (the training frame and the few a round predicts on)
SIGNAL_FRAMES = 4


def signals(df: pd.DataFrame, ctx: Context, wanted) -> dict:
    """The signals of :data:`l1b2.predictor.effects.SIGNALS` in ``wanted``, from a data frame.

    ``v_base`` is the baseline's free run on ``df`` and ``a_base`` its time
    derivative per run (:func:`l1b2.predictor.effects.time_derivative`). Every signal is computed once per
    frame (the same object) and kept in ``ctx.signal_cache`` for the last :data:`SIGNAL_FRAMES` frames, read-only:
    a round scores a few hundred candidates on the same frame, and ``v_base`` costs a free run.
    """
    memo = _frame_memo(df, ctx)
    keys = ["t", "s", "V0", "load", "d"] + (["T"] if "T" in wanted else [])
    keys += [k for k in wanted if k.startswith(("col:", "run:"))]
    keys += ["v_base", "a_base"] if {"v_base", "a_base"} & set(wanted) else []
    for key in keys:
        if key not in memo:
            memo[key] = _signal(df, ctx, key, memo)
            memo[key].setflags(write=False)
    return {k: memo[k] for k in keys}


_COLUMNS = {"t": dataio.TIME, "s": dataio.POSITION, "V0": dataio.VOLTAGE, "load": dataio.LOAD,
            "d": dataio.DIRECTION, "T": dataio.TEMPERATURE}


def _signal(df: pd.DataFrame, ctx: Context, key: str, memo: dict) -> np.ndarray:
    """One signal of :func:`signals` (``memo``: the frame's signals so far; ``a_base`` after ``v_base``)."""
    if key in _COLUMNS:
        return df[_COLUMNS[key]].to_numpy(float).copy()
    if key.startswith("col:"):
        return df[key[4:]].to_numpy(float).copy()
    if key.startswith("run:"):
        return df.groupby(dataio.RUN, sort=False)[key[4:]].transform("mean").to_numpy(float)
    if key == "v_base":
        return np.array(ctx.baseline_free_run(df), float)
    starts = [sl.start for _, sl in dataio.run_slices(df[dataio.RUN])]
    return np.asarray(fx.time_derivative(memo["v_base"], memo["t"], sorted(starts)), float)


def _frame_memo(df: pd.DataFrame, ctx: Context) -> dict:
    """The signals computed so far on the frame ``df`` (a new entry, the oldest dropped, for a new frame; no
    context: nothing kept)."""
    if ctx is None:
        return {}
    cache = ctx.signal_cache
    hit = cache.get(id(df))
    if hit is not None and hit[0] is df:
        return hit[1]
    while cache and len(cache) >= SIGNAL_FRAMES:
        cache.pop(next(iter(cache)))
    cache[id(df)] = (df, {})
    return cache[id(df)][1]


def candidate(ctx: Context, h: fx.Hypothesis) -> CandidateForce:
    """The candidate of one hypothesis: its features are :func:`l1b2.predictor.effects.effect_features` of its spec."""
    spec = h.spec
    wanted = fx.needs(spec)

    def features(df):
        return fx.effect_features(spec, signals(df, ctx, wanted))
    return CandidateForce(h.family, h.regressor, h.shape, tuple(h.names), tuple(h.units), features, h.description,
                          generic=h.generic, also=tuple(h.also), structural=h.structural, spec=spec,
                          bounds=tuple(tuple(b) for b in h.bounds))


#: the share of a logged channel's variation within runs that a function of the position (one per direction) must
#: hold for the channel to be read along the stroke only (:func:`along_stroke_share`), and that function's degree
ALONG_STROKE_SHARE = 0.9
ALONG_STROKE_DEGREE = 8
#: the fewest samples within runs (beyond one per run) per coefficient of that function for the share to be read
ALONG_STROKE_SAMPLES = 10
#: how much more of the within-run variation the position must hold than the run's clock
ALONG_STROKE_MARGIN = 0.05


def _within_run_share(c, runs, x, d) -> float:
    """``1 - SSE / SST`` of the column ``c`` on Legendre polynomials ``P_1 .. P_8`` of ``x`` (in [-1, 1]), one set
    per direction ``d``, both taken about their run's mean (``runs``)."""
    P = np.polynomial.legendre.legvander(x, ALONG_STROKE_DEGREE)[:, 1:]
    B = np.concatenate([P * (d > 0)[:, None], P * (d <= 0)[:, None]], axis=1)
    B = B - pd.DataFrame(B).groupby(runs).transform("mean").to_numpy()
    coef = np.linalg.lstsq(B, c, rcond=None)[0]
    return float(min(max(1.0 - float(np.sum((c - B @ coef) ** 2)) / float(np.sum(c ** 2)), 0.0), 1.0))


def _unit(v: np.ndarray) -> np.ndarray:
    lo, hi = float(v.min()), float(v.max())
    return (2.0 * v - lo - hi) / max(hi - lo, 1e-300)


def along_stroke_share(df: pd.DataFrame, name: str) -> tuple[float, float]:
    """``(position, clock)``: the shares of the column ``name``'s variation within runs that a function of the
    position and a function of the time since the run's first sample hold. Each is ``1 - SSE / SST`` of the least
    squares of the column on Legendre polynomials ``P_1 .. P_8`` of the variable (scaled to its range over ``df``),
    one set per direction, the column and the basis each taken about their run's mean. NaN when the column does not
    vary within runs, or when the samples within runs (beyond one per run) are fewer than
    :data:`ALONG_STROKE_SAMPLES` per coefficient (a short log: a polynomial would follow any column).

    A channel that the position holds (at least :data:`ALONG_STROKE_SHARE`) better than the run's clock (by
    :data:`ALONG_STROKE_MARGIN`) is a function of where the slider is (a homing probe's field, a limit switch, a
    second position sensor): its mean over a run's samples weighs each position by the time the slider spent there,
    so it follows how the run moved, the motor's response, not a setting of the run. When every run moves alike the
    two shares are equal, and so are the runs' weights."""
    runs = df[dataio.RUN].to_numpy()
    c = df[name].to_numpy(float)
    c = c - pd.Series(c).groupby(runs).transform("mean").to_numpy()
    if not float(np.sum(c ** 2)) > 0 or len(c) - len(pd.unique(runs)) < ALONG_STROKE_SAMPLES * 2 * ALONG_STROKE_DEGREE:
        return float("nan"), float("nan")
    d = df[dataio.DIRECTION].to_numpy(float)
    return (_within_run_share(c, runs, _unit(df[dataio.POSITION].to_numpy(float)), d),
            _within_run_share(c, runs, _unit(time_in_run_s(df)), d))


def is_along_stroke(df: pd.DataFrame, name: str) -> bool:
    """Whether the column ``name`` is read along the stroke only (:func:`along_stroke_share`)."""
    pos, clock = along_stroke_share(df, name)
    return bool(pos >= ALONG_STROKE_SHARE and pos >= clock + ALONG_STROKE_MARGIN)


#: the share of a logged channel's spread of run means that its course in the run's clock carries through the
#: runs' lengths (:func:`run_length_share`) from which its run mean is taken for a reading of the run's length
RUN_LENGTH_SHARE = 0.5


def run_length_share(df: pd.DataFrame, name: str) -> float:
    """The share of the column ``name``'s spread of run means that the runs' lengths carry through its course in the
    run's clock. Per run ``r``: the least-squares slope ``b_r`` of the column on the time since the run's first
    sample, whose mean over the run's samples is ``tbar_r``; ``delta_r = b_r (tbar_r - min_r tbar_r)`` is how far
    the run's mean moved from the column's value at the shortest run's mean time. The share is
    ``sum (delta_r - mean delta)^2 / sum (m_r - mean m)^2`` (``m_r`` the run means), clipped to [0, 1]; NaN when
    the run means do not vary.

    A reading that accumulates over each run from its start (an energy or charge meter, a counter, a clock reset
    at each start) has a run mean that is its rate times half the run's length: how long the run lasted, the
    motor's response, not a setting of the run (a share near 1). A setting, a level, or a temperature whose drift
    within a run is small beside its spread between runs has a share near 0."""
    g = pd.DataFrame({"run": df[dataio.RUN].to_numpy(), "t": time_in_run_s(df), "c": df[name].to_numpy(float)})
    g["tt"], g["tc"] = g["t"] * g["t"], g["t"] * g["c"]
    sums = g.groupby("run", sort=False).agg(t=("t", "mean"), c=("c", "mean"), tt=("tt", "mean"), tc=("tc", "mean"))
    var_t = (sums["tt"] - sums["t"] ** 2).to_numpy(float)
    cov_tc = (sums["tc"] - sums["t"] * sums["c"]).to_numpy(float)
    slope = np.divide(cov_tc, var_t, out=np.zeros_like(cov_tc), where=var_t > 0)
    tbar, m = sums["t"].to_numpy(float), sums["c"].to_numpy(float)
    delta = slope * (tbar - tbar.min())
    sst = float(np.sum((m - m.mean()) ** 2))
    if not sst > 0:
        return float("nan")
    return float(min(float(np.sum((delta - delta.mean()) ** 2)) / sst, 1.0))


def channel_kinds(df: pd.DataFrame, response_columns=None) -> list[tuple[str, str]]:
    """``(name, kind)`` of every candidate channel of a frame, in :func:`channels_of`'s order and with its kinds:
    every numeric column beyond the required ones and the speed whose values are all finite, then the clock."""
    required = NOT_CANDIDATES - {dataio.TIME}
    responses = set(fx.channels.RESPONSE_COLUMNS if response_columns is None else response_columns)
    labels = set(label_columns(df))
    names = [c for c in df.columns if c not in required and c != dataio.TIME
             and pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c])]
    out = []
    for name in names + [dataio.TIME]:
        if not np.all(np.isfinite(df[name].to_numpy(float))):
            continue
        out.append((str(name), "protocol" if name == dataio.TIME else "run_clock" if name == fx.channels.RUN_CLOCK
                    else "run_travel" if name == fx.channels.RUN_TRAVEL
                    else "response" if name in responses else "label" if name in labels else "logged"))
    return out


def channels_of(df: pd.DataFrame, response_columns=None) -> tuple:
    """The candidate channels of a frame: every numeric column beyond the required ones and the speed, then the clock.

    One ``{"name", "kind", "mean", "sd", "lo", "hi", "within_run", "run_values", "run_spread"}`` each (``lo``/``hi``:
    the smallest and largest value; ``kind``:
    ``"logged"``, ``"protocol"`` for the session clock ``time_s``, ``"run_clock"`` for the run's own clock
    :data:`l1b2.predictor.effects.channels.RUN_CLOCK` and ``"run_travel"`` for its own travel
    :data:`~l1b2.predictor.effects.channels.RUN_TRAVEL` (:mod:`l1b2.closeloop.runclock`: offered along the stroke
    only),
    ``"response"`` for a measured response of the motor (``response_columns``, default
    :data:`l1b2.predictor.effects.channels.RESPONSE_COLUMNS`: listed, no hypothesis), ``"relabel"`` for a logged
    channel that is, run by run, a function of one or two of the plan's inputs
    (:func:`l1b2.closeloop.relabels.follows_plan`, those inputs under ``follows``: listed, no hypothesis; never a
    channel the loop derived, :func:`l1b2.closeloop.auxiliary.derived_columns`: its histories have their own
    rules; a run setting, :mod:`l1b2.closeloop.runsetting`, is read as a logged setting), or ``"label"`` for a
    text column coded by :func:`l1b2.closeloop.auxiliary.with_usable_channels` (its codes have no order: only the
    categorical run-level family reads them);
    ``sd`` 0 for a constant column, which is listed but gets no hypothesis;
    ``within_run``: it varies inside some run; ``run_values``: how many distinct run means it has; ``run_spread``:
    :func:`l1b2.predictor.effects.channels.run_spread`; ``along_stroke``: a logged channel whose variation within
    runs is a function of the position rather than of the run's clock (:func:`is_along_stroke`), offered at the
    sample level only and with no run-level signal; ``run_length``: a logged channel whose run means follow the
    runs' lengths (:func:`run_length_share` at least :data:`RUN_LENGTH_SHARE`), offered likewise).
    """
    out, derived = [], set(derived_columns(df, settings=False))
    for name, kind in channel_kinds(df, response_columns):
        c = df[name].to_numpy(float)
        follows = follows_plan(df, name) if kind == "logged" and name not in derived else ()
        kind = "relabel" if follows else kind
        within = varies_within_runs(df, name)
        along = bool(kind == "logged" and within and is_along_stroke(df, name))
        length = bool(kind == "logged" and within and not along and run_length_share(df, name) >= RUN_LENGTH_SHARE)
        run_values = len(np.unique(df.groupby(dataio.RUN, sort=False)[name].mean().to_numpy(float)))
        out.append({"name": str(name), "kind": kind, "mean": float(np.mean(c)), "sd": float(np.std(c)),
                    "lo": float(np.min(c)), "hi": float(np.max(c)), "within_run": within, "run_values": run_values,
                    "run_spread": fx.channels.run_spread(c, df[dataio.RUN]), "along_stroke": along,
                    "run_length": length, **({"follows": follows} if follows else {})})
    return tuple(out)


def training_summary(ctx: Context, df_train: pd.DataFrame) -> fx.TrainingSummary:
    """What the families' grids may use of TRAIN: ranges, median voltage, temperature, spectral peak (cached)."""
    key = id(df_train)
    if key in ctx.summaries and ctx.summaries[key][0] is df_train:
        return ctx.summaries[key][1]
    t0, t1 = ctx.time_range
    s0, s1 = ctx.position_range
    V = df_train[dataio.VOLTAGE].to_numpy(float)
    vp = np.abs(ctx.baseline_free_run(df_train))
    ranges = {"t_lo": float(t0), "t_hi": float(t1), "s_lo": float(s0), "s_hi": float(s1),
              "V_lo": float(V.min()), "V_hi": float(V.max()),
              "load_abs": float(np.max(np.abs(df_train[dataio.LOAD].to_numpy(float)))) or 1.0,
              "v_lo": float(np.min(vp)), "v_hi": float(np.max(vp))}
    T = (df_train[dataio.TEMPERATURE].to_numpy(float) if dataio.TEMPERATURE in df_train.columns else None)
    out = fx.TrainingSummary(m_s=float(ctx.m_s), time_range=ctx.time_range, position_range=ctx.position_range,
                             voltage_median=float(np.median(V)), ranges=ranges,
                             temperature_ref=ctx.temperature_ref,
                             temperature_range=None if T is None else (float(T.min()), float(T.max())),
                             spectral_period_m=ctx.spectral_period_m,
                             channels=channels_of(df_train, ctx.response_columns),
                             damping_N_s_per_m=ctx.damping_N_s_per_m)
    ctx.summaries[key] = (df_train, out)
    return out


def baseline_damping(model, df: pd.DataFrame, mask) -> float:
    """The smallest viscous damping [N s/m] of a fitted predictor (``params_``, ``result_.frequency_response``) over
    the masked samples of ``df``: :func:`l1b2.predictor.model.viscous_damping` at their positions, with the
    pure-slip family's contact angle when its response carries the contact law."""
    prm, fr = model.params_, getattr(model.result_, "frequency_response", None)
    m = np.asarray(mask, bool)
    contact = None
    if prm.drive_law == "pure_slip" and fr is not None and fr.has_contact:
        V0 = df[dataio.VOLTAGE].to_numpy(float)[m]
        contact = contact_angle(V0, sample_frequency(df[m], fr.f_ref_Hz), fr)
    return float(np.min(viscous_damping(prm, df[dataio.POSITION].to_numpy(float)[m], contact)))


def damping_floors(effects, model, df: pd.DataFrame, mask, channels) -> dict:
    """``{label: N s/m}``: the total viscous damping's smallest value over TRAIN's range of the channel
    (:func:`l1b2.predictor.effects.channels.damping_floor`) of every damping form of a channel among ``effects``
    (an :class:`~l1b2.closeloop.acceptance.EffectSet` with its fitted ``phi``), with ``model``'s own damping
    (:func:`baseline_damping`); ``channels``: TRAIN's channel records (``name``, ``lo``, ``hi``)."""
    rng = {ch["name"]: (ch["lo"], ch["hi"]) for ch in channels if "lo" in ch and "hi" in ch}
    picks = [(c, p) for c, p in zip(effects.candidates, effects.phi)
             if c.spec.get("kind") == "channel" and c.spec.get("form") == "damping" and c.spec["channel"] in rng]
    if not picks:
        return {}
    D = baseline_damping(model, df, mask)
    return {c.label: fx.channels.damping_floor(c.spec, p, *rng[c.spec["channel"]], D) for c, p in picks}


def range_check(effects, model, df: pd.DataFrame, mask, channels, n_rnd: int, label: str) -> dict | None:
    """The physical-range check of a joint refit (``effects`` with their fitted ``phi``, ``model``) that added
    ``label`` in round ``n_rnd``: ``{"round", "label", "damping_floor_N_s_per_m", "outcome"}`` with
    :func:`damping_floors`, ``outcome`` ``"kept"`` or ``"refused: negative total damping (<labels>)"`` when the
    total viscous damping of a channel's damping form turns negative within TRAIN's range of the channel; None
    when no damping form of a channel is among ``effects``."""
    floors = damping_floors(effects, model, df, mask, channels)
    if not floors:
        return None
    low = sorted(k for k, v in floors.items() if not v >= 0)
    return {"round": n_rnd, "label": label, "damping_floor_N_s_per_m": floors,
            "outcome": f"refused: negative total damping ({', '.join(low)})" if low else "kept"}


def group_candidates(groups, ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Every hypothesis of the registered families of ``groups``, in group then registration order."""
    train = training_summary(ctx, df_train)
    return [candidate(ctx, h) for g in groups for e in fx.families(g) for h in e.grid(train)]


def named_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Every named candidate (the registry's ``named`` families) with its shape grid."""
    return group_candidates(("named",), ctx, df_train)


def interaction_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Effects of two regressors: the named physical forms, then the generic low-order tensor products.

    See :mod:`l1b2.predictor.effects.interactions` and
    :mod:`l1b2.predictor.effects.generic`; the structural ones relax
    Eq. 29's own linearisation (:data:`EQ29_LINEARISATION`) and are traced
    after the effects the model lacks (:func:`l1b2.closeloop.evidence.order_traced`).
    """
    return group_candidates(("interaction", "generic_interaction"), ctx, df_train)


def generic_candidates(ctx: Context, df_train: pd.DataFrame) -> list[CandidateForce]:
    """Fallback smooth terms, one per regressor available in the data."""
    return group_candidates(("generic",), ctx, df_train)


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
