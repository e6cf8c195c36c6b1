"""Maximum-likelihood identification of the reduced predictor (paper Eq. 32, 35).

:class:`PredictorIdentifier` fits theta of :mod:`l1b2.predictor.model` (Eq. 35
order) to measured traverses in the rig data format (docs/reference/data-format.md)
(a :class:`~l1b2.data.measurements.Measurements` or a DataFrame; SI units).
It follows the scikit-learn convention: the constructor stores the settings,
:meth:`PredictorIdentifier.fit` returns the estimator with fitted attributes
ending in ``_``, above all ``result_`` (an
:class:`~l1b2.ident.result.IdentificationResult`) and ``params_`` (a
:class:`~l1b2.predictor.model.PredictorParams`).

The fit runs, in order (one module each):

1. data and problem (:mod:`l1b2.ident.problem`): the criterion ``free_run``
   or ``one_step``, residuals [m/s] and their analytic Jacobian;
2. a data-driven start (:mod:`l1b2.ident.reduced`): a linear window equation-error fit of the reduced
   functions D(s), B'(s), C(s) and an equation-error fit of the Eq. 35 structure from many Sobol starts (or
   the warm start ``init``; ``solver="offset_reduced"``: the linear fit mapped to Eq. 35 alone);
3. the global search (:mod:`l1b2.ident.search`): local ``least_squares``
   runs from several starts with a statistical stopping rule, then the
   alternation with the noise model (:mod:`l1b2.ident.noise`, Eq. 32:
   per-run variance and the start-speed term);
4. uncertainty and identifiability (:mod:`l1b2.ident.uncertainty`): Fisher
   covariance with AR(1) inflation, null and weak directions, AIC/BIC.

Identifiability
---------------
The data (any data with v' > 0 and known m_s)
determine the functions D(s), B'(s) and C(s) above (B' via the voltage
dependence; the absolute force scale via the known load weights and mass).
Writing ``a = mu g1(k0) - mu_sd kappa`` and ``b = mu (pi/2) G(k0)``::

    D(s) = c_r + sigma/2 - sigma A'(s)
    C(s) = P(s) (a - b A'(s)) - 9.81 m_s mu_sd

is invariant under three one-parameter groups:

1. ``sigma -> r sigma, A' - alpha_0 -> (A' - alpha_0)/r`` with c_r, alpha_0,
   mu, k0 adjusted (keeps sigma A'(s) up to a constant, b/sigma and
   a - b alpha_0);
2. ``alpha_0 -> alpha_0 + delta/sigma, c_r -> c_r + delta`` with mu, k0
   adjusted so that ``a - b alpha_0`` is unchanged;
3. ``P -> lambda P`` with mu, k0 (and thus a, b) scaled by 1/lambda.

With all 3n+8 parameters varied (the paper's setting) the Fisher matrix
therefore has three null directions: ``unidentifiable_`` reports them
numerically and the affected parameters get ``stderr = inf``. mu_sd is
practically unidentifiable (it enters C(s) only as a constant), and the split
of C(s) into P(s) and (a - b A'(s)) can be bimodal: ``alternative_optima_``
reports a second optimum the global search finds.

``fixed="recommended"`` pins sigma, k0, mu (one per structural direction; any
values give the same predictions) and mu_sd (the guide's datasheet value);
the fitted c_r, alpha, p are then conditional on those pins. The measured
singular values and coverage behind this choice:
``docs/decisions/0002-pin-sigma-k0-mu-and-mu_sd.md``.

Extra forces ("closing the loop")
---------------------------------
``PredictorIdentifier(extra=ExtraForces(...))`` (:mod:`l1b2.ident.extra`)
adds candidate physical effects the paper's model lacks as extra forces with
their own parameters phi: ``X_total = X + features(df) @ phi`` [N, drive
coordinates]. phi is identified jointly with theta: it enters the window
equation error (linear in phi), the analytic Jacobian, bounds, scaling (phi's
scale makes the force ~1 % of the typical drive force), ``fixed``, the
SVD/Fisher uncertainty and the AIC/BIC count. ``init=`` (e.g. a baseline's
``params_``) warm-starts the search; with ``n_starts=1`` it is one local
refinement: first phi given theta (the baseline can sit on a kink of the
free run where the joint step cannot move), then jointly; the warm runs also
stop when the projected gain over the remaining budget is below 50 *
``stat_tol`` log-likelihood units. It is a *local* refinement: the baseline's
theta was bent to absorb the missing effect and may lie in another basin of
the (multi-modal, see above) likelihood; ``n_starts >= 2`` fits two tracks,
the warm start and the data-driven search with ``n_starts - 1`` starts, and
keeps the higher final log-likelihood (``convergence_["tracks"]``).

*Confounding.* A feature that is (nearly) a function of position alone is
largely reproducible by the position polynomials of Eq. 35 (C(s) has order
2n): its parameter is then weakly determined or not at all. The fit reports
it: ``stderr = inf`` and a null direction in ``unidentifiable_`` when exactly
confounded, otherwise a large ``extra_confounding_[name]["variance_inflation"]``,
entries in ``weak_directions_`` and a [[Warnings]] line in the fit report.
Direction-dependent or voltage-dependent features are not confounded this way.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from types import SimpleNamespace
from typing import Any, Mapping

import numpy as np

from ..data.measurements import Measurements
from ..data.metrics import (
    evaluation_mask,  # re-exported: the data-format evaluation mask
)
from ..errors import IdentificationError
from ..predictor.model import DRIVE_LAWS, PredictorParams
from ..predictor.model import steady_state as predictor_steady_state
from .convention import EstimatorSettings
from .extra import ExtraForces
from .frequency import fit_frequency_response, response_setting
from .frequency import resolve as resolve_frequency
from .noise import NoiseModel
from .problem import (
    RECOMMENDED_FIXED,
    ParameterSpace,
    SampleData,
    ScaledObjective,
    extra_parameter_scale,
    param_scale,
    run_label,
)
from .reduced import data_driven_start, init_theta, reduced_summary
from .result import IdentificationResult
from .slipproblem import RECOMMENDED_FIXED_PURE_SLIP, make_problem
from .search import (LocalSolver, alternate_noise, multi_start, polish_stalled, profile_search, search_nfev,
                     start_points, warm_prestep)
from .uncertainty import alternative_optima, extra_confounding, fisher_uncertainty
from .offset import BRACKETS, auto_solver, projected_search

__all__ = ["PredictorIdentifier", "clone", "RECOMMENDED_FIXED", "evaluation_mask"]

#: exceptions of numpy/scipy that mean the data cannot support the fit (wrapped in IdentificationError)
NUMERICAL_FAILURES = (np.linalg.LinAlgError, FloatingPointError, OverflowError, ZeroDivisionError, ValueError)

#: constructor arguments that are not part of the serialised settings
_NOT_SERIALISED = ("verbose", "extra", "init", "init_extra", "frequency")

#: the searches of ``noise_fit`` (``"auto"``: profile without extra forces, alternate with them)
NOISE_FITS = ("auto", "alternate", "profile")

#: the local solvers of the global search (``solver``): variable projection, or the joint multistart
SOLVERS = ("auto", "varpro", "joint", "offset", "offset_bracket", "offset_reduced", "offset_kappa0")


def clone(estimator, **changes):
    """A new unfitted estimator with the same settings (scikit-learn's ``clone``), ``changes`` applied."""
    return type(estimator)(**{**estimator.get_params(), **changes})


def _slider_mass(slider_mass_kg) -> float:
    if slider_mass_kg is None:
        raise IdentificationError(
            "slider_mass_kg is missing: give the slider mass [kg] (sidecar 'slider_mass_kg')"
        )
    try:
        m_s = float(slider_mass_kg)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"slider_mass_kg must be a number [kg], got {slider_mass_kg!r}") from exc
    if not (math.isfinite(m_s) and m_s > 0):
        raise IdentificationError(f"slider_mass_kg must be a positive mass [kg], got {slider_mass_kg!r}")
    return m_s


class PredictorIdentifier(EstimatorSettings):
    """Maximum-likelihood identification of the Eq. 29 predictor (see module docstring).

    Parameters
    ----------
    order : polynomial order n of A', B', P (paper: 8).
    criterion : ``"free_run"`` (default) or ``"one_step"``.
    n_starts : number of local optimisations of the global search (centre + Sobol points).
    seed : seed of the Sobol sequence.
    fixed : parameters pinned at a value (``vary=False``): dict name -> value
        (value ``None`` = pin at the data-driven/conventional centre value),
        a sequence of names, or ``"recommended"`` (= :data:`RECOMMENDED_FIXED`).
        ``None`` varies all Eq. 35 parameters (the paper's setting).
    noise : ``"common"`` (default: one variance for all residuals, the paper's
        single R of Eq. 32) or ``"per_run"`` (one variance per run, floored at
        10 % of the median). Per-run variances reward fits that specialise on
        some runs when the model does not fit the data exactly
        (``docs/decisions/0003-one-common-noise-variance.md``).
    kappa : share of the preload loading the guide (fixed, not identified).
    include_load_inertia : m_eff = m_s + |m_load| (True) or m_s.
    max_nfev : function evaluations per local optimisation.
    start_spread : relative half-width of the global-search box.
    max_outer : maximum number of (theta, R) alternations.
    svd_rtol : relative singular-value threshold for non-identifiable directions.
    weak_rtol : directions with svd_rtol < relative singular value < weak_rtol are
        reported in ``weak_directions_`` (identifiable, but barely).
    tol : ftol = xtol = gtol of every local least_squares.
    stat_tol, stat_window : statistical convergence: a local run also stops when
        its cost (= -log-likelihood + const) decreased by less than ``stat_tol``
        over ``stat_window`` iterations (scipy >= 1.16; 0 disables).
    noise_fit : how Eq. 32's unknown noise variances are fitted with theta.
        ``"auto"`` (default): ``"profile"`` for the Eq. 29 model alone,
        ``"alternate"`` when ``extra`` forces are fitted with it (not all of
        them pinned in ``fixed``); the report's settings give the search used.
        ``"alternate"``: a two-stage multi-start of ``least_squares`` at
        variances fixed at the start, then fit theta / re-estimate R
        alternately (``max_outer`` times at most); on data the model does not
        fit exactly it converges slowly (tens of refits).
        ``"profile"``: every local search maximises the profile
        likelihood (variances at their ML values at every point, a damped
        Gauss-Newton iteration with the theta-variance coupling,
        :func:`l1b2.ident.search.profile_refine`) from each start in turn, and
        the global search compares the starts by their likelihood. Its damped
        steps can stall on a kink of the free run (a run at the edge of
        sticking) or creep until its iteration limit (common variance, exact
        data); the best start is therefore always continued by least-squares
        refits at the ML variances, kept if they gain (:func:`l1b2.ident.search.polish_stalled`).
        Why ``"auto"`` chooses so: ``docs/decisions/0004-noise-fit-auto.md``.
    start_agree : profile search: stop the global search once this many starts
        reached the best log-likelihood within ``10 * stat_tol`` (0: run every start).
    stat_window_profile : profile search: a local search stops when its
        log-likelihood gained less than ``stat_tol`` over this many iterations.
    alt_tol : a refined optimum of the global search whose log-likelihood is within
        ``alt_tol`` of the best but which differs by > 3 stderr is reported in
        ``alternative_optima_`` (a discrete ambiguity the local stderr cannot show).
    explore_nfev, n_refine : global search in two stages (when n_starts > n_refine):
        every start gets a short local run of ``explore_nfev`` evaluations, then
        the ``n_refine`` best continue to convergence (``max_nfev`` in total).
    start_noise : free run: model the noise of the measured start speed of each
        run, which propagates through the recursion (residual covariance
        ``R_r (I + g g^T)``, ``g = d v_pred/d v_start``); see
        :class:`l1b2.ident.noise.NoiseModel`.
    verbose : print the progress of the search.
    extra : :class:`~l1b2.ident.extra.ExtraForces` or None. Extra exogenous forces with their own parameters
        phi, identified jointly with theta: in drive coordinates ``X_total = X + features(df) @ phi``. ``None``
        (default) is the paper's model, unchanged.
    init : PredictorParams (or theta in Eq. 35 order) to warm-start from,
        e.g. a baseline fit. With ``n_starts=1`` only this start is run: one
        local refinement (phi given theta, then jointly, with the noise
        re-estimation), no equation-error search. With ``n_starts >= 2`` two
        tracks are fitted and the higher final log-likelihood wins: this
        warm start, and the data-driven search with ``n_starts - 1`` starts
        (as without init); ``convergence_["tracks"]`` records both. (One
        global search with init among the starts would compare the starts
        under init's noise variances, which are wrong for the others when
        init lacks an effect.) Parameters pinned by ``fixed`` without a value
        take init's values in the warm track. Its polynomials are
        re-expanded exactly if its position scaling (s_center, s_half)
        differs from the data's; kappa and include_load_inertia are the
        identifier's.
    init_extra : start values of phi for the warm start (default ``extra.start``, else zeros); only with ``init``.
    solver : ``"auto"`` (default: ``"offset_kappa0"`` or ``"joint"``, :func:`l1b2.ident.offset.auto_solver`),
        ``"joint"`` (the searches of ``noise_fit``), ``"varpro"`` (:mod:`l1b2.ident.varpro`),
        ``"offset"`` (the drive offset as a search coordinate: a profile on a grid of offsets, then varpro;
        :mod:`l1b2.ident.offset`), ``"offset_bracket"`` (the same with a bracketed search over the offset on each
        side of the barrier, warm-started points, a result never below the profile's best point; framed at the best
        equation-error minimum of ``seed``'s starts), ``"offset_reduced"`` (framed at the mapped reduced linear fit,
        :func:`l1b2.ident.reduced.map_reduced_to_theta`: no ``seed``) or ``"offset_kappa0"`` (``offset_reduced``
        with the drive offset in place of K in its identifiable stage); their settings: ``offset.BRACKETS[solver]``.
    model : the predictor family: ``"eq29"`` (default, the paper's Eq. 29) or
        ``"pure_slip"`` (the slip ratio follows the state,
        :mod:`l1b2.predictor.pureslip`; same parameters, likelihood, noise
        model and uncertainty; ``fixed="recommended"`` then pins
        :data:`~l1b2.ident.slipproblem.RECOMMENDED_FIXED_PURE_SLIP`; the
        variable projection (``solver="varpro"``) is Eq. 29's only).
    frequency : the drive-frequency response of the force factor (:mod:`l1b2.ident.frequency`):
        ``"auto"`` (default) estimates it when the data's drive frequency varies
        between runs and holds it fixed at gain 1 when it does not (``"contact"``: the
        pure-slip family estimates the contact law too); ``"off"``; or a
        :class:`~l1b2.predictor.frequency.FrequencyResponse` held fixed.
        ``result_.frequency`` records which (fit report, ``identification.json``).

    The constructor only stores the settings (scikit-learn convention:
    :meth:`get_params`, :meth:`set_params`, :func:`clone`); they are checked
    by :meth:`fit`, which raises :class:`~l1b2.errors.IdentificationError`
    for an invalid one.

    Fitted attributes
    -----------------
    ``result_`` (:class:`~l1b2.ident.result.IdentificationResult`: report,
    JSON, plots) and, for direct use, read-only views of it (:data:`FITTED_VIEWS`: arrays
    share its data and cannot be written), ``theta_``, ``params_``, ``varied_``,
    ``identifiable_``, ``stderr_`` (AR(1)-corrected), ``stderr_fisher_``,
    ``ci95_`` (p, 2), ``stderr_robust_`` / ``ci95_robust_`` / ``cov_robust_``
    (cluster-robust sandwich by run, valid under misspecification; see
    :mod:`l1b2.ident.uncertainty`), ``cov_``, ``cov_fisher_``, ``corr_`` (p, p) with p =
    3n+8 (the theta block), ``fixed_``, ``loglik_``, ``aic_``, ``bic_``,
    ``k_params_``, ``n_obs_``, ``n_eff_``, ``dof_``, ``t_quantile_``,
    ``noise_var_``, ``ar1_rho_``, ``ar1_factor_``, ``residual_rms_`` [m/s],
    ``singular_values_``, ``unidentifiable_``, ``weak_directions_``,
    ``alternative_optima_``, ``convergence_``, ``fit_time_s_``, ``m_s_``,
    ``s_center_``, ``s_half_``, ``T_s_``, ``runs_``; the fit diagnostics
    ``reduced_``, ``theta_init_``, ``extra_init_``, ``warm_prestep_``,
    ``null_space_``. With extras: ``phi_``, ``extra_names_``,
    ``extra_units_``, ``extra_description_``, ``extra_params_``,
    ``extra_stderr_``, ``extra_stderr_fisher_`` (dict name -> float),
    ``extra_ci95_`` (dict name -> (lo, hi)), ``extra_varied_``,
    ``extra_identifiable_``, ``extra_confounding_`` and the joint quantities
    ``param_names_all_``, ``varied_all_``, ``identifiable_all_``,
    ``stderr_all_``, ``stderr_fisher_all_``, ``ci95_all_``, ``cov_all_``,
    ``cov_fisher_all_``, ``corr_all_`` (theta then phi). Without extras these
    exist and are empty (or equal the theta versions).
    """

    settings_error = IdentificationError

    def __init__(
        self,
        order: int = 8,
        criterion: str = "free_run",
        n_starts: int = 8,
        seed: int | None = 0,
        fixed=None,
        noise: str = "common",
        kappa: float = 0.5,
        include_load_inertia: bool = True,
        max_nfev: int = 200,
        start_spread: float = 0.5,
        max_outer: int = 5,
        svd_rtol: float = 1e-8,
        weak_rtol: float = 1e-5,
        tol: float = 1e-10,
        start_noise: bool = True,
        explore_nfev: int = 30,
        n_refine: int = 3,
        stat_tol: float = 0.01,
        stat_window: int = 10,
        alt_tol: float = 2.0,
        noise_fit: str = "auto",
        start_agree: int = 2,
        stat_window_profile: int = 3,
        verbose: bool = False,
        extra: ExtraForces | None = None,
        init: PredictorParams | None = None,
        init_extra=None,
        solver: str = "auto",
        model: str = "eq29",
        frequency="auto",
    ):
        self.order = order
        self.criterion = criterion
        self.n_starts = n_starts
        self.seed = seed
        self.fixed = fixed
        self.noise = noise
        self.kappa = kappa
        self.include_load_inertia = include_load_inertia
        self.max_nfev = max_nfev
        self.start_spread = start_spread
        self.max_outer = max_outer
        self.svd_rtol = svd_rtol
        self.weak_rtol = weak_rtol
        self.tol = tol
        self.start_noise = start_noise
        self.explore_nfev = explore_nfev
        self.n_refine = n_refine
        self.stat_tol = stat_tol
        self.stat_window = stat_window
        self.alt_tol = alt_tol
        self.noise_fit = noise_fit
        self.start_agree = start_agree
        self.stat_window_profile = stat_window_profile
        self.verbose = verbose
        self.extra = extra
        self.init = init
        self.init_extra = init_extra
        self.solver = solver
        self.model = model
        self.frequency = frequency

    # -- settings: the scikit-learn protocol of :class:`l1b2.ident.convention.EstimatorSettings` --------
    def _checked_settings(self) -> SimpleNamespace:
        """The settings with their types normalised; IdentificationError for an invalid one."""
        cfg = SimpleNamespace(**self.get_params())
        for name in ("order", "n_starts", "max_nfev", "max_outer", "explore_nfev", "stat_window", "start_agree",
                     "stat_window_profile"):
            setattr(cfg, name, int(getattr(cfg, name)))
        for name in ("kappa", "start_spread", "svd_rtol", "weak_rtol", "tol", "stat_tol", "alt_tol"):
            setattr(cfg, name, float(getattr(cfg, name)))
        for name in ("include_load_inertia", "start_noise", "verbose"):
            setattr(cfg, name, bool(getattr(cfg, name)))
        cfg.n_refine = max(1, int(cfg.n_refine))
        cfg.frequency = response_setting(cfg.frequency)
        if cfg.criterion not in ("free_run", "one_step"):
            raise IdentificationError(f"criterion must be 'free_run' or 'one_step', got {cfg.criterion!r}")
        if cfg.solver not in SOLVERS:
            raise IdentificationError(f"solver must be one of {SOLVERS}, got {cfg.solver!r}")
        cfg.solver = auto_solver(cfg) if cfg.solver == "auto" else cfg.solver
        if cfg.model not in DRIVE_LAWS:
            raise IdentificationError(f"model must be one of {DRIVE_LAWS}, got {cfg.model!r}")
        if cfg.model == "pure_slip":
            if cfg.solver != "joint":
                raise IdentificationError(f"solver {cfg.solver!r} needs the Eq. 29 model (its speed is linear "
                                          "in B'); use solver='joint' with model='pure_slip'")
            if isinstance(cfg.fixed, str) and cfg.fixed == "recommended":
                cfg.fixed = {k: None for k in RECOMMENDED_FIXED_PURE_SLIP}
        if cfg.noise_fit not in NOISE_FITS:
            raise IdentificationError(f"noise_fit must be one of {NOISE_FITS}, got {cfg.noise_fit!r}")
        if cfg.noise_fit == "auto":  # the search measured better for the model at hand (class docstring)
            pinned = cfg.fixed if isinstance(cfg.fixed, Mapping) else {}
            fitted = [n for n in (cfg.extra.names if isinstance(cfg.extra, ExtraForces) else ()) if n not in pinned]
            cfg.noise_fit = "alternate" if fitted else "profile"
        if cfg.start_agree < 0 or cfg.stat_window_profile < 1:
            raise IdentificationError("start_agree must be >= 0 and stat_window_profile >= 1")
        if cfg.noise not in ("per_run", "common"):
            raise IdentificationError(f"noise must be 'per_run' or 'common', got {cfg.noise!r}")
        if cfg.order < 0:
            raise IdentificationError("order must be >= 0")
        if cfg.n_starts < 1:
            raise IdentificationError("n_starts must be >= 1")
        extra = cfg.extra
        if extra is not None and not isinstance(extra, ExtraForces):
            raise IdentificationError(f"extra must be an ExtraForces or None, got {type(extra).__name__}")
        n_theta = len(PredictorParams.names(cfg.order))
        if extra is not None:
            clash = set(extra.names) & set(PredictorParams.names(cfg.order))
            if clash:
                raise IdentificationError(f"extra: names {sorted(clash)} clash with Eq. 35 parameter names")
        if cfg.init_extra is not None:
            cfg.init_extra = np.atleast_1d(np.asarray(cfg.init_extra, float)).ravel()
            if extra is None:
                raise IdentificationError("init_extra given without extra")
            if cfg.init_extra.size != extra.n:
                raise IdentificationError(
                    f"init_extra has {cfg.init_extra.size} values, expected {extra.n} ({list(extra.names)})"
                )
        init = cfg.init
        if init is not None and not isinstance(init, PredictorParams):
            if np.asarray(init, dtype=float).ravel().size != n_theta:
                raise IdentificationError(f"init: expected PredictorParams or theta of length {n_theta}")
        elif init is not None and init.order != cfg.order:
            raise IdentificationError(f"init has polynomial order {init.order}, the identifier {cfg.order}")
        return cfg

    def _settings_record(self, cfg, fixed) -> dict:
        """The serialised settings (``fixed``: the pins as applied)."""
        return {k: (dict(fixed) if k == "fixed" else getattr(cfg, k))
                for k in self._param_names() if k not in _NOT_SERIALISED}

    @property
    def param_names(self) -> list[str]:
        """Names of theta (Eq. 35 order); extra parameters are in :attr:`extra_names`."""
        return PredictorParams.names(int(self.order))

    @property
    def extra_names(self) -> list[str]:
        """Names of the extra-force parameters (empty without extras)."""
        if self.extra is not None:
            return list(self.extra.names)
        return list(getattr(self, "extra_names_", []))

    def _log(self, msg):
        if self.verbose:
            print(msg, flush=True)

    # -- fitting ---------------------------------------------------------------------------
    def fit(self, data, slider_mass_kg=None, mask=None) -> "PredictorIdentifier":
        """Identify theta (and the extra-force parameters); returns self.

        Parameters
        ----------
        data : Measurements or pandas.DataFrame
            Measured traverses in the data format. A
            :class:`~l1b2.data.measurements.Measurements` supplies the slider
            mass and the evaluation mask unless given here; a DataFrame is
            checked against the data-format contract and needs
            ``slider_mass_kg``.
        slider_mass_kg : float, optional
            Slider mass m_s [kg].
        mask : array_like of bool, optional
            Samples whose residuals enter the likelihood (DataFrame default:
            all; Measurements default: its evaluation mask).

        Raises
        ------
        IdentificationError
            Bad settings or data, and every numerical failure inside the fit
            (a singular or non-converging linear algebra, overflow, non-finite
            residuals), as "the data do not determine ... because ...".
        """
        try:
            if resolve_frequency(self, data)[2]:   # TRAIN's frequency varies: estimate the response
                return fit_frequency_response(self, data, slider_mass_kg, mask,
                                              contact=self.frequency == "contact" and self.model == "pure_slip")
            return self._fit(data, slider_mass_kg, mask)
        except NUMERICAL_FAILURES as exc:
            text = " ".join(str(exc).split()) or type(exc).__name__
            raise IdentificationError(
                "the data do not determine the Eq. 29 parameters: the fit failed numerically because "
                f"{type(exc).__name__}: {text} (check the units of time, position, speed, voltage, load and "
                "the slider mass; too few or too similar runs also do this)") from exc

    def _fit(self, data, slider_mass_kg, mask) -> "PredictorIdentifier":
        cfg = self._checked_settings()
        if cfg.init is not None and cfg.n_starts >= 2:
            return self._fit_two_tracks(cfg, data, slider_mass_kg, mask)
        t_start, c_start = time.perf_counter(), time.process_time()
        if isinstance(data, Measurements):
            slider_mass_kg = data.slider_mass_kg if slider_mass_kg is None else slider_mass_kg
            mask = data.mask if mask is None else mask
        m_s = _slider_mass(slider_mass_kg)
        response, frequency_rec, _ = resolve_frequency(self, data)
        sample = SampleData(data, mask, frequency=response)
        E = None if cfg.extra is None else cfg.extra.evaluate(sample.frame)  # features, once, flat order
        space = ParameterSpace(cfg.order, cfg.extra, cfg.fixed)
        sample.check_sufficient(int(space.varied.sum()), cfg.order)
        s_center, s_half = sample.position_scaling()
        warm = cfg.init is not None  # (then n_starts == 1, see _fit_two_tracks)

        # ---- start: data-driven centre and equation-error minima, or init ----
        red, minima = data_driven_start(sample, space, m_s, cfg.kappa, cfg.include_load_inertia, s_center,
                                        s_half, E, cfg.n_starts, cfg.seed, warm=warm,
                                        n_ee_starts={"varpro": 4 * cfg.n_starts, "offset": 4, "offset_reduced": 0,
                                                     "offset_kappa0": 0}.get(cfg.solver, BRACKETS.get(
                                                         cfg.solver, {}).get("start_fits")), drive_law=cfg.model)
        theta0, fixed_final = self._centre(cfg, space, minima, s_center, s_half)
        t_centre, c_centre = time.perf_counter(), time.process_time()
        self.reduced_ = reduced_summary(red, minima, space.extra_names)
        self.theta_init_ = theta0[: space.p_theta].copy()
        self.extra_init_ = theta0[space.p_theta:].copy()

        # ---- the likelihood problem in scaled coordinates --------------------
        problem = make_problem(cfg.model, sample, cfg.order, cfg.kappa, cfg.include_load_inertia, cfg.criterion,
                               s_center, s_half, m_s, E=E)
        scale = param_scale(theta0, cfg.order)
        if space.extra_names:
            scale[space.p_theta:] = extra_parameter_scale(problem, theta0, E, sample.mask, m_s)
        noise = NoiseModel(problem.run_sel, sample.layout.R, cfg.noise)
        obj = ScaledObjective(problem, noise, theta0, space.varied, scale, space.lo, space.hi, cfg.start_noise)
        z_centre = obj.z_of(theta0)
        if not np.all(np.isfinite(problem.residual(obj.theta_of(z_centre)))):
            raise IdentificationError(
                ("the warm start (init) gives" if warm else "the data-driven initial guess gives")
                + " a non-finite prediction; check units (m, m/s, V, kg) and slider_mass_kg"
            )
        obj.update_noise(obj.theta_of(z_centre))

        # ---- search: (warm pre-step,) multi-start, noise alternation -----------
        solver = LocalSolver(obj, cfg.tol, cfg.stat_tol, cfg.stat_window, warm=warm)
        self.warm_prestep_ = None
        xv = np.flatnonzero(obj.vidx >= space.p_theta)
        if warm and xv.size:
            z_centre, self.warm_prestep_ = warm_prestep(obj, z_centre, xv, cfg.tol, cfg.max_nfev, self._log)
        starts = start_points(z_centre, [obj.z_of(th) for _, th in minima[1:]], cfg.n_starts, cfg.seed,
                              cfg.start_spread, obj.zlo, obj.zhi)
        stages, t_search, c_search = ([{"stage": "start", "time_s": t_centre - t_start, "cpu_s": c_centre - c_start}],
                                      time.perf_counter(), time.process_time())
        if cfg.solver != "joint":
            search, outer, more = projected_search(cfg, obj, starts, theta0, space.p_theta, self._log)
            stages += more
        elif cfg.noise_fit == "profile":
            search, outer = profile_search(obj, starts, cfg.max_nfev // 2, cfg.stat_tol, cfg.stat_window_profile,
                                           cfg.start_agree, self._log)
            # always continued by least-squares refits at the ML variances: the damped Gauss-Newton can stop
            # short of the optimum numerically (a kink) or at its iteration limit (with the common variance on
            # exact data it crept for 100 iterations and ended at 5.7e-8 m/s rms; the refit reached 4e-16,
            # tests/test_identify.py); a refit that gains nothing is not kept
            outer = polish_stalled(solver, outer, cfg.max_outer, cfg.max_nfev, cfg.stat_tol, self._log)
        else:
            search = multi_start(solver, starts, cfg.max_nfev, cfg.explore_nfev, cfg.n_refine, self._log)
            best = search.results[search.best]
            outer = alternate_noise(solver, best.x, best, cfg.max_outer, cfg.max_nfev, self._log)
        if cfg.solver == "joint":
            stages.append({"stage": f"search ({cfg.noise_fit})", "time_s": time.perf_counter() - t_search,
                           "cpu_s": time.process_time() - c_search,
                           "nfev": search_nfev(cfg.solver, cfg.noise_fit, search, outer)})

        # ---- uncertainty and the result ------------------------------------------
        result = self._result(cfg, space, sample, obj, search, outer, fixed_final, t_start, stages)
        result.frequency = frequency_rec
        self._publish(result)
        return self

    def _centre(self, cfg, space, minima, s_center, s_half):
        """Centre of the search (joint vector, pins applied) and the pins as applied."""
        if cfg.init is not None:
            extra = cfg.extra
            phi_init = (
                cfg.init_extra if cfg.init_extra is not None
                else (extra.start_vector() if extra is not None else np.zeros(0))
            )
            start = np.concatenate([init_theta(cfg.init, cfg.order, s_center, s_half), phi_init])
            theta0 = space.clip(space.with_fixed(start))
        else:
            theta0 = minima[0][1].copy()
        # pin fixed-without-value at the centre
        fixed_final = {k: (theta0[space.index(k)] if v is None else v) for k, v in space.fixed.items()}
        for k, v in fixed_final.items():
            theta0[space.index(k)] = v
        return theta0, {k: float(v) for k, v in fixed_final.items()}

    def _result(self, cfg, space, sample, obj, search, outer, fixed, t_start, stages) -> IdentificationResult:
        """Uncertainty at the optimum and the :class:`IdentificationResult` of the fit.

        ``stages``: the per-stage records so far (``convergence["stages"]`` gets the uncertainty's too).
        """
        t_unc, c_unc = time.perf_counter(), time.process_time()
        problem, noise = obj.problem, obj.noise
        theta_hat = obj.theta_of(outer.z)
        r = problem.residual(theta_hat)
        Jz = obj.jac(outer.z)  # whitened with the final noise model, scaled
        unc = fisher_uncertainty(Jz, r, problem, noise, obj.vidx, obj.sv_scale, theta_hat, space.varied,
                                 space.names, cfg.svd_rtol, cfg.weak_rtol)
        self.null_space_ = unc.null_space
        records, outer_hist, final = search.records, outer.history, outer.final
        convergence = {
            "criterion": cfg.criterion,
            "n_starts": len(records),
            "best_start": int(search.best),
            "starts": records,
            "outer": outer_hist,
            "noise_converged": bool(outer.converged),
            "status": int(final.status),
            "message": str(final.message),
            "success": bool(final.status > 0 or final.status == -2),
            "optimality": float(final.optimality),
            "cost": float(0.5 * np.sum(noise.weighted(r) ** 2)),
            "nfev_total": search_nfev(cfg.solver, cfg.noise_fit, search, outer),
            "solver": cfg.solver,
            "stages": stages + [{"stage": "uncertainty", "time_s": time.perf_counter() - t_unc, "cpu_s":
                                 time.process_time() - c_unc}],
        }
        p = space.p_theta
        extra = cfg.extra
        return IdentificationResult(
            settings=self._settings_record(cfg, fixed),
            params=PredictorParams.from_vector(theta_hat[:p], problem.s_center, problem.s_half, cfg.kappa,
                                               cfg.include_load_inertia, cfg.model),
            values=theta_hat, extra_names=list(space.extra_names),
            extra_units=[] if extra is None else list(extra.units),
            extra_description="" if extra is None else extra.description,
            varied=space.varied.copy(), identifiable=unc.identifiable, stderr=unc.stderr,
            stderr_fisher=unc.stderr_fisher, ci95=unc.ci95, cov=unc.cov, cov_fisher=unc.cov_fisher, corr=unc.corr,
            stderr_robust=unc.stderr_robust, ci95_robust=unc.ci95_robust, cov_robust=unc.cov_robust,
            run_influence=unc.run_influence, slider_mass_kg=problem.m_s, T_s=sample.sample_period(),
            runs=[run_label(x) for x in sample.layout.labels], noise_var=noise.R.copy(), ar1_rho=unc.ar1_rho,
            n_obs=int(problem.run_sel.size), n_eff=unc.n_eff, k_params=unc.k_params, dof=unc.dof,
            t_quantile=unc.t_quantile, loglik=unc.loglik, aic=unc.aic, bic=unc.bic,
            residual_rms=float(np.sqrt(np.mean(r * r))), singular_values=unc.singular_values,
            unidentifiable=unc.unidentifiable, weak_directions=unc.weak_directions,
            alternative_optima=alternative_optima(search.results, search.refined, search.best, obj.theta_of,
                                                  theta_hat, unc, space.names, cfg.alt_tol),
            extra_confounding=extra_confounding(unc, p, obj.vidx, obj.sv_scale, space.names, cfg.svd_rtol),
            convergence=convergence, fit_time_s=time.perf_counter() - t_start, extra=extra,
        )

    def _fit_two_tracks(self, cfg, data, slider_mass_kg, mask):
        """Warm start with n_starts >= 2: the warm track and the data-driven track; keep the better."""
        t_start = time.perf_counter()
        warm = clone(self, n_starts=1).fit(data, slider_mass_kg, mask)
        tracks = [("warm start (init)", warm)]
        try:
            cold = clone(self, n_starts=cfg.n_starts - 1, init=None, init_extra=None).fit(data, slider_mass_kg, mask)
            tracks.append(("data-driven", cold))
        except IdentificationError as exc:  # e.g. too few forward windows for the linear fit
            self._log(f"data-driven track failed: {exc}")
            tracks.append(("data-driven", exc))
        fitted = [(nm, t) for nm, t in tracks if not isinstance(t, Exception)]
        name, best = max(fitted, key=lambda nt: nt[1].loglik_)
        for k, v in vars(best).items():
            if k.endswith("_") and not k.startswith("_"):
                setattr(self, k, v)
        rec = []
        for nm, t in tracks:
            if isinstance(t, Exception):
                rec.append({"track": nm, "error": str(t)})
                continue
            rec.append({
                "track": nm, "chosen": t is best, "loglik": t.loglik_, "residual_rms": t.residual_rms_,
                "n_starts": t.convergence_["n_starts"], "nfev_total": t.convergence_["nfev_total"],
                "fit_time_s": t.fit_time_s_, "theta": t.theta_.tolist(), "phi": t.phi_.tolist(),
                "fixed": dict(t.fixed_),
            })
        convergence = dict(best.convergence_)
        convergence["tracks"] = rec
        convergence["chosen_track"] = name
        convergence["nfev_total"] = int(sum(r.get("nfev_total", 0) for r in rec))
        result = replace(best.result_, settings=self._settings_record(cfg, best.result_.fixed),
                         convergence=convergence, fit_time_s=time.perf_counter() - t_start)
        self._publish(result)
        self._log(f"warm start: tracks {[(r['track'], r.get('loglik')) for r in rec]}; chosen: {name}")
        return self

    def _publish(self, result: IdentificationResult) -> None:
        """Set ``result_``; every fitted attribute derived from it is a read-only view (:data:`FITTED_VIEWS`)."""
        self.result_ = result

    # -- predictions -----------------------------------------------------------------------
    def _check_fitted(self):
        if not hasattr(self, "result_"):
            raise IdentificationError("PredictorIdentifier is not fitted yet: call fit() first")

    def extra_force(self, df) -> np.ndarray:
        """The identified extra force ``features(df) @ phi`` per sample [N, drive coordinates] (0 without extras)."""
        self._check_fitted()
        return self.result_.extra_force(df)

    def predict_free_run(self, df) -> np.ndarray:
        """Free-run speed per sample [m/s] (from each run's first measured speed).

        With extra forces their features are computed on ``df``.
        """
        self._check_fitted()
        return self.result_.predict(df, "free_run")

    def predict_one_step(self, df) -> np.ndarray:
        """v(k+1 | measured v(k)) per sample [m/s]; NaN at the first sample of each run.

        With extra forces their features are computed on ``df``.
        """
        self._check_fitted()
        return self.result_.predict(df, "one_step")

    def steady_state(self, s, V0, load, direction, extra_force_N=0.0) -> np.ndarray:
        """Closed-form steady speed [m/s] (see :func:`l1b2.predictor.model.steady_state`).

        ``extra_force_N`` [N, drive coordinates, broadcasts] is added to X
        (default 0). With extra forces, pass ``features @ phi`` for the
        conditions of interest (e.g. ``self.extra_force(df)``); it is not
        computed here because the features need a data frame.
        """
        self._check_fitted()
        return predictor_steady_state(self.params_, s, V0, load, direction, self.m_s_, extra_force=extra_force_N)

    # -- reporting -----------------------------------------------------------------------
    def fit_report(self, min_correl: float = 0.9) -> str:
        """Readable summary in the spirit of lmfit's fit_report (see :meth:`IdentificationResult.fit_report`)."""
        self._check_fitted()
        return self.result_.fit_report(min_correl)

    def to_dict(self) -> dict[str, Any]:
        """Strict-JSON summary (NaN -> None, inf -> "inf") that :meth:`from_dict` restores."""
        self._check_fitted()
        return self.result_.to_dict()

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], extra: ExtraForces | None = None) -> "PredictorIdentifier":
        """Rebuild a fitted identifier (for prediction and reporting) from :meth:`to_dict`.

        The values of extra-force parameters (section ``"extra"``) are
        restored; their feature function cannot be serialised: pass the same
        ``extra=ExtraForces(...)`` to reattach it (its names must match).
        Without it, predictions of a model with extra forces raise
        :class:`IdentificationError`.
        """
        result = IdentificationResult.from_dict(d, extra=extra)
        st = dict(d["settings"])
        fixed = st.pop("fixed", None)
        obj = cls(fixed=fixed or None, extra=extra, **st)
        obj._publish(result)
        return obj


# ---------------------------------------------------------------------------
# fitted attributes: read-only views of result_
# ---------------------------------------------------------------------------

def _ro(a):
    """A read-only view of an array (the result's own data, not a copy)."""
    v = np.asarray(a).view()
    v.flags.writeable = False
    return v


def _extra(fn):
    """A dict name -> fn(value) over the extra-force parameters (the phi block) of ``result.<field>``."""
    return lambda field: (lambda r: {n: fn(v) for n, v in zip(r.extra_names, getattr(r, field)[r.p_theta:])})


_scalar, _pair = _extra(float), _extra(lambda ab: (float(ab[0]), float(ab[1])))
#: fitted attribute -> its value from ``result_`` (:class:`~l1b2.ident.result.IdentificationResult`)
FITTED_VIEWS = {
    **{f"{k}_all_": (lambda k: lambda r: _ro(getattr(r, k)))(k)
       for k in ("varied", "identifiable", "stderr", "stderr_fisher", "ci95", "stderr_robust", "ci95_robust",
                 "cov", "cov_fisher", "cov_robust", "corr")},
    **{f"{k}_": (lambda k: lambda r: _ro(getattr(r, k)[: r.p_theta]))(k)
       for k in ("varied", "identifiable", "stderr", "stderr_fisher", "ci95", "stderr_robust", "ci95_robust")},
    **{f"{k}_": (lambda k: lambda r: _ro(getattr(r, k)[: r.p_theta, : r.p_theta]))(k)
       for k in ("cov", "cov_fisher", "cov_robust", "corr")},
    "extra_varied_": lambda r: _ro(r.varied[r.p_theta:]),
    "extra_identifiable_": lambda r: _ro(r.identifiable[r.p_theta:]),
    "extra_params_": lambda r: {n: float(v) for n, v in zip(r.extra_names, r.values[r.p_theta:])},
    "extra_stderr_": _scalar("stderr"), "extra_stderr_fisher_": _scalar("stderr_fisher"),
    "extra_stderr_robust_": _scalar("stderr_robust"),
    "extra_ci95_": _pair("ci95"), "extra_ci95_robust_": _pair("ci95_robust"),
    "params_": lambda r: r.params, "theta_": lambda r: _ro(r.values[: r.p_theta]),
    "phi_": lambda r: _ro(r.values[r.p_theta:]),
    "param_names_all_": lambda r: r.names, "extra_names_": lambda r: list(r.extra_names),
    "extra_units_": lambda r: list(r.extra_units), "extra_description_": lambda r: r.extra_description,
    "extra_confounding_": lambda r: r.extra_confounding, "fixed_": lambda r: r.fixed,
    "m_s_": lambda r: r.slider_mass_kg, "s_center_": lambda r: r.params.s_center,
    "s_half_": lambda r: r.params.s_half, "T_s_": lambda r: r.T_s,
    **{f"{k}_": (lambda k: lambda r: getattr(r, k))(k)
       for k in ("runs", "noise_var", "ar1_rho", "ar1_factor", "n_obs", "n_eff", "dof", "t_quantile", "k_params",
                 "loglik", "aic", "bic", "residual_rms", "singular_values", "unidentifiable", "weak_directions",
                 "alternative_optima", "convergence", "fit_time_s", "run_influence")},
}


def _view(name: str, fn):
    def get(self):
        try:
            result = self.__dict__["result_"]
        except KeyError:
            raise AttributeError(f"{name}: PredictorIdentifier is not fitted yet (call fit() first)") from None
        return fn(result)
    return property(get, doc=f"Fitted: read-only view of ``result_`` ({name}).")


for _name, _fn in FITTED_VIEWS.items():
    setattr(PredictorIdentifier, _name, _view(_name, _fn))
