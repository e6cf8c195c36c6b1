"""Uncertainty and identifiability of a maximum-likelihood fit.

Covariance from the Fisher information ``(J^T R^-1 J)^-1`` at the optimum via
the SVD of the weighted (whitened), scaled Jacobian (:func:`fisher_uncertainty`).
Singular values below ``svd_rtol * s_max`` (default 1e-8) mark directions the
data cannot separate; every parameter with a component > :data:`NULL_TOL` in
that null space gets ``stderr = inf`` (not determined) -- never a
pseudo-inverse value. For the other parameters the pseudo-inverse restricted
to the identified subspace is exact (they are estimable functions).
Directions with relative singular values below ``weak_rtol`` (1e-5) are
reported as weak directions; both kinds are described as parameter changes
per unit change of a pivot parameter (:func:`describe_direction`).

AR(1) inflation
---------------
Free-run residuals are autocorrelated when the model is not exact, which
makes the white-noise Fisher covariance too optimistic. The corrected
covariance inflates the noise variance of each run by the AR(1) long-run
variance factor ``(1 + rho)/(1 - rho)``, rho = lag-1 autocorrelation of that
run's (whitened) residuals, clipped to [0, 0.99] so the correction never
shrinks an interval (:func:`ar1_factors`). Chosen over a run-block sandwich
estimator because the sandwich needs many more runs than parameters to be
stable (72 runs vs 32 parameters at order 8, far fewer runs in small
experiments), whereas the AR(1) factor uses every sample and is exact for
slowly varying sensitivities under AR(1) errors. The plain white-noise values
are kept as ``*_fisher``. Intervals use the t distribution with ``n_eff - k``
degrees of freedom, ``n_eff = sum_r n_r / f_r`` (AR(1)-effective sample
count) and k = number of varied identifiable parameters. (One-step residuals
are MA(1)-like, negatively correlated; with rho clipped at 0 their intervals
are conservative.)

Robust (sandwich) covariance
----------------------------
Both covariances above trust the model: the residuals are noise. When the
model misses an effect, the residual holds a smooth, run-specific error and
the Fisher intervals (even AR(1)-inflated) are too narrow -- an injected
pulley coefficient of 0.4 got [0.384, 0.389]. Beside them the cluster-robust
(Huber-White) sandwich, clustered by run, is reported:
``A^+ (G/(G-1) sum_r s_r s_r^T) A^+`` with ``A = J^T J`` (the whitened
Fisher information, restricted to the identified subspace), ``s_r = J_r^T w_r``
the score of run r (whitened Jacobian rows and residuals of that run) and G
the number of runs. It assumes only that runs are independent, so any error
correlated within a run -- a missing effect, drift, coloured noise -- is
accounted for; its intervals use the t distribution with G - 1 degrees of
freedom. It is noisier than the Fisher covariance with few runs (G should
well exceed the number of parameters), so both are reported
(``stderr_robust``, ``ci95_robust``); a robust stderr much larger than the
Fisher one says the model is misspecified for that parameter. In a
simulated misspecified world (tests/test_uncertainty_robust.py: a
speed-sensor offset per run the model lacks) the Fisher intervals of a
pulley coefficient cover it in 0-25 % of repetitions, the sandwich ones in
all with ``noise="common"``; with the default per-run variances, which are
estimated from the misspecified residuals (so the weights depend on the
missing effect), in about 75 %: much better, still below nominal. The
sandwich does not remove a bias of the estimate itself.

Information criteria: the log-likelihood at the final (theta, R) (including
the start-speed term); ``aic = 2k - 2 loglik``, ``bic = k ln(n) - 2 loglik``
with n the number of residuals and k counting only varied, identifiable
parameters (noise variances not counted: they are the same for all models
compared on the same data with the same ``noise`` option).

Extra forces: :func:`extra_confounding` compares each extra parameter's
stderr with the one it would have if theta were known (variance inflation);
:func:`alternative_optima` lists other optima of the global search that fit
almost as well but lie > 3 stderr away (a discrete ambiguity the local
intervals cannot show).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.linalg import qr

__all__ = [
    "NULL_TOL", "describe_direction", "ar1_factors", "Uncertainty", "fisher_uncertainty", "extra_confounding",
    "alternative_optima", "cluster_sandwich", "run_influence", "grouped_sandwich", "singular",
    "profiled_influence", "bell_mccaffrey_dof",
]

#: a parameter with a component above this in a null direction is not identifiable
NULL_TOL = 1e-6


def describe_direction(vec_z, pivot, vidx, sv_scale, names):
    """A direction in scaled coordinates as physical parameter changes per unit change of ``pivot``."""
    dtheta = vec_z * sv_scale
    dtheta = dtheta / dtheta[pivot]
    zmag = np.abs(vec_z)
    members = np.flatnonzero(zmag > 1e-3 * zmag.max())
    members = members[np.argsort(-zmag[members])]
    terms = [(names[vidx[i]], float(dtheta[i])) for i in members]
    return {
        "pivot": names[vidx[pivot]],
        "direction": terms,
        "parameters": [nm for nm, _ in terms],
        "text": " ".join(f"{c:+.4g}*d({nm})" for nm, c in terms),
    }


def ar1_factors(r, run_sel, sample_sel, n_runs):
    """Lag-1 autocorrelation rho per run of consecutive residuals and the factor ``(1 + rho)/(1 - rho)``.

    ``r``: whitened residuals; ``run_sel`` / ``sample_sel``: run and flat
    sample index of each residual (consecutive = adjacent samples of one run).
    rho is clipped to [0, 0.99].
    """
    order_ = np.lexsort((sample_sel, run_sel))
    rs = r[order_]
    runs_o = run_sel[order_]
    samp_o = sample_sel[order_]
    adj = (runs_o[1:] == runs_o[:-1]) & (samp_o[1:] == samp_o[:-1] + 1)
    num = np.bincount(runs_o[1:][adj], weights=(rs[1:] * rs[:-1])[adj], minlength=n_runs)
    den = np.bincount(run_sel, weights=r * r, minlength=n_runs)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(den > 0, num / den, 0.0)
    rho = np.clip(np.nan_to_num(rho), 0.0, 0.99)
    return rho, (1.0 + rho) / (1.0 - rho)


@dataclass
class Uncertainty:
    """Joint (theta then phi) uncertainty of a fit; see :func:`fisher_uncertainty`.

    Arrays have the joint length p (fixed entries: NaN; not identifiable:
    inf on the diagonal, NaN elsewhere). ``jac_ar1`` is the AR(1)-corrected
    whitened scaled Jacobian (for :func:`extra_confounding`).
    """

    ar1_rho: np.ndarray
    ar1_factor: np.ndarray
    singular_values: np.ndarray
    cov: np.ndarray
    cov_fisher: np.ndarray
    stderr: np.ndarray
    stderr_fisher: np.ndarray
    corr: np.ndarray
    n_eff: float
    dof: float
    t_quantile: float
    ci95: np.ndarray
    identifiable: np.ndarray
    k_params: int
    loglik: float
    aic: float
    bic: float
    unidentifiable: list
    null_space: np.ndarray
    weak_directions: list
    jac_ar1: np.ndarray
    cov_robust: np.ndarray | None = None
    stderr_robust: np.ndarray | None = None
    ci95_robust: np.ndarray | None = None
    run_influence: np.ndarray | None = None


def singular(J):
    """``(s, Vt)``: the singular values and right singular vectors of ``J`` (n x p).

    With more rows than columns, those of the R factor of ``J = QR`` (the same values and vectors, up to the
    vectors' signs, which no use here depends on: they enter as ``V V^T`` or scaled by a pivot entry); one QR of
    n x p and an SVD of p x p cost about half the SVD of n x p.
    """
    J = np.asarray(J, float)
    if J.shape[0] > J.shape[1]:
        J = np.linalg.qr(J, mode="r")
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    return s, Vt


def _covariance(J, sv_scale, svd_rtol, sv_vt=None):
    """Pseudo-inverse covariance of the scaled parameters restricted to the identified subspace
    (``sv_vt``: :func:`singular` of ``J`` when the caller has it)."""
    s_, Vt_ = singular(J) if sv_vt is None else sv_vt
    keep = s_ > svd_rtol * s_[0]
    Vr = Vt_[keep].T
    cz = (Vr / s_[keep] ** 2) @ Vr.T
    return cz * np.outer(sv_scale, sv_scale)


def run_influence(J, w, clusters, sv_scale, svd_rtol, sv_vt=None):
    """Each cluster's influence on the estimate: row g is ``A^+ s_g * scale`` (physical units).

    ``A = J^T J`` (restricted to the identified subspace) and ``s_g = J_g^T w_g``
    the summed score of cluster g (arguments as :func:`cluster_sandwich`). The
    cluster-robust covariance is ``G/(G-1) sum_g u_g u_g^T`` of these rows, and
    merging clusters (e.g. the runs of one operating condition) merges rows by
    summing them (:func:`grouped_sandwich`). Shape ``(G, p)``; a cluster without
    residuals has a row of zeros. ``sv_vt``: :func:`singular` of ``J`` when the caller has it.
    """
    s_, Vt_ = singular(J) if sv_vt is None else sv_vt
    keep = s_ > svd_rtol * s_[0]
    Vr = Vt_[keep].T
    a_inv = (Vr / s_[keep] ** 2) @ Vr.T
    G = int(np.max(clusters)) + 1 if clusters.size else 0
    scores = np.zeros((G, J.shape[1]))
    np.add.at(scores, clusters, J * w[:, None])
    return (scores @ a_inv) * sv_scale[None, :]


def grouped_sandwich(influence, groups):
    """Cluster-robust covariance with the clusters of ``influence`` merged by ``groups``: ``(cov, n_groups)``.

    ``influence``: ``(G, p)`` rows of :func:`run_influence`; ``groups``: one
    label per row (rows of the same label form one cluster; a row of zeros
    counts for nothing). ``cov = H/(H-1) sum_h v_h v_h^T``, ``v_h`` the sum of
    the rows of group h and H the number of groups with a non-zero row (the
    CR1 small-sample factor). With one row per group this is
    :func:`cluster_sandwich`.
    """
    infl = np.asarray(influence, float)
    labels = [g.item() if isinstance(g, np.generic) else g for g in groups]   # any hashable label, e.g. (V0, load)
    if len(labels) != infl.shape[0]:
        raise ValueError(f"grouped_sandwich: {len(labels)} group labels for {infl.shape[0]} clusters")
    live = np.any(infl != 0, axis=1)
    codes: dict = {}
    idx = np.array([codes.setdefault(g, len(codes)) for g, ok in zip(labels, live) if ok], dtype=int)
    H = len(codes)
    v = np.zeros((H, infl.shape[1]))
    if H:
        np.add.at(v, idx, infl[live])
    return v.T @ v * (H / max(H - 1, 1)), H


def _profiled_parts(Q, Jq):
    """``(P Jq S^-1, W)``: q's columns of ``J (J^T J)^-1`` and an orthonormal basis of J's columns."""
    Q = np.asarray(Q, float).reshape(len(Jq), -1)
    Jq = np.asarray(Jq, float)
    PJ = Jq - Q @ (Q.T @ Jq)
    S = PJ.T @ PJ
    W = np.column_stack([Q, np.linalg.qr(PJ)[0]])
    return PJ @ np.linalg.inv(S), W


def _cr2_adjusted(W_g, x_g):
    """``(I - H_gg)^{-1/2} x_g`` with ``H_gg = W_g W_g^T`` (through W_g's thin SVD; columns of x_g adjusted alike)."""
    U, s, _ = np.linalg.svd(W_g, full_matrices=False)
    lam = np.clip(1.0 - s ** 2, 1e-12, None)
    x2 = np.asarray(x_g, float).reshape(len(x_g), -1)
    return (x2 + U @ ((lam ** -0.5 - 1.0)[:, None] * (U.T @ x2))).reshape(np.shape(x_g))


def profiled_influence(Q, Jq, r, clusters, cr2: bool = False) -> np.ndarray:
    """Each cluster's influence on the parameters of ``Jq``'s columns, the nuisance parameters profiled out.

    The joint linear least squares of ``r`` on ``J = [X, Jq]``: ``Q`` (n, k) orthonormal columns spanning X
    (the nuisance Jacobian), ``Jq`` (n, m), ``r`` (n,) the residuals at the optimum, ``clusters`` (n,) integer
    codes 0..G-1. With ``P = I - Q Q^T`` and ``S = (P Jq)^T P Jq``, q's rows of ``(J^T J)^-1 J^T`` are
    ``S^-1 (P Jq)^T`` (Frisch-Waugh-Lovell), so cluster g's influence is ``u_g = S^-1 (P Jq)_g^T a_g`` with

    * ``cr2=False``: ``a_g = r_g``; ``G/(G-1) sum_g u_g u_g^T`` is q's block of the CR1 sandwich
      (:func:`grouped_sandwich` of these rows, which also merges clusters by summing rows);
    * ``cr2=True``: ``a_g = (I - H_gg)^{-1/2} r_g``, ``H = W W^T`` the joint hat matrix (``W = [Q, orth(P Jq)]``):
      ``sum_g u_g u_g^T`` (no factor) is the Bell-McCaffrey CR2 covariance.

    Returns U, shape (G, m); a cluster without samples has a row of zeros.
    """
    M, W = _profiled_parts(Q, Jq)
    r = np.asarray(r, float)
    clusters = np.asarray(clusters, int)
    G = int(clusters.max()) + 1 if clusters.size else 0
    U = np.zeros((G, M.shape[1]))
    for g in range(G):
        sel = clusters == g
        if np.any(sel):
            a = _cr2_adjusted(W[sel], r[sel]) if cr2 else r[sel]
            U[g] = M[sel].T @ a
    return U


def bell_mccaffrey_dof(Q, Jq, clusters, c) -> float:
    """Satterthwaite degrees of freedom of the CR2 variance of ``c^T q`` (Bell and McCaffrey 2002, working
    model: independent errors of one variance), arguments as :func:`profiled_influence`.

    With ``b_g = (I - H_gg)^{-1/2} (P Jq S^-1)_g c`` the matrix ``B_gh = delta_gh b_g^T b_g - (W_g^T b_g)^T
    (W_h^T b_h)`` (the Gram matrix of the columns ``(I - H)_{.,g} b_g``) gives ``nu = tr(B)^2 / tr(B^2)``: G - 1
    for a mean over G equal clusters, fewer when a few clusters carry the contrast.
    """
    M, W = _profiled_parts(Q, Jq)
    mc = M @ np.asarray(c, float)
    clusters = np.asarray(clusters, int)
    groups = [g for g in range(int(clusters.max()) + 1) if np.any(clusters == g)]
    bb, D = [], []
    for g in groups:
        sel = clusters == g
        b = _cr2_adjusted(W[sel], mc[sel])
        bb.append(float(b @ b))
        D.append(W[sel].T @ b)
    D = np.array(D)
    B = np.diag(bb) - D @ D.T
    return float(np.trace(B) ** 2 / np.sum(B * B))


def cluster_sandwich(J, w, clusters, sv_scale, svd_rtol, influence=None):
    """Cluster-robust (Huber-White) covariance of the scaled parameters, clustered by run.

    Parameters
    ----------
    J : ndarray, shape (n, p)
        Whitened, scaled Jacobian of the residuals.
    w : ndarray, shape (n,)
        Whitened residuals at the optimum.
    clusters : ndarray of int, shape (n,)
        Cluster (run) index 0..G-1 of every residual.
    sv_scale : ndarray, shape (p,)
        Scales of the parameters (the result is in physical units).
    svd_rtol : float
        Relative singular-value threshold of the identified subspace.
    influence : ndarray, shape (G, p), optional
        :func:`run_influence` of the same arguments, when the caller has it (computed here when None).

    Returns
    -------
    cov : ndarray, shape (p, p)
        ``A^+ (G/(G-1) sum_g s_g s_g^T) A^+ * outer(scale, scale)`` with
        ``A = J^T J`` and ``s_g`` the summed score ``J_g^T w_g`` of cluster g.
    n_clusters : int
        G, the number of clusters with residuals.
    """
    infl = run_influence(J, w, clusters, sv_scale, svd_rtol) if influence is None else influence
    used = np.bincount(clusters, minlength=infl.shape[0]) > 0
    g_eff = int(np.sum(used))
    cov = infl[used].T @ infl[used] * (g_eff / max(g_eff - 1, 1))
    return cov, g_eff


def _embed(cv, p_all, vidx, affected_v):
    """Covariance of the varied entries -> joint matrix (NaN for fixed, inf diagonal for unidentifiable)."""
    c = np.full((p_all, p_all), np.nan)
    c[np.ix_(vidx, vidx)] = cv
    aff = vidx[affected_v]
    c[aff, :] = np.nan
    c[:, aff] = np.nan
    c[aff, aff] = np.inf
    return c


def _directions(Vn, sv, Vt, ident, vidx, sv_scale, names, weak_rtol):
    """Descriptions of the null directions and of the weakly determined ones."""
    combos = []
    if Vn.size:
        q = Vn.shape[1]
        # pivoted QR picks q parameters that span the null space best; express
        # each direction with a unit change of its pivot and zero change of the others
        _, _, piv = qr(Vn.T, pivoting=True, mode="economic")
        pv = piv[:q]
        B = Vn @ np.linalg.inv(Vn[pv, :])
        for j in range(q):
            d = describe_direction(B[:, j], pv[j], vidx, sv_scale, names)
            d["text"] = "predictions unchanged along: " + d["text"]
            combos.append(d)
    weak = []
    rel = sv / sv[0] if sv.size else sv
    for j in np.flatnonzero(ident & (rel < weak_rtol)):
        vec = Vt[j]
        d = describe_direction(vec, int(np.argmax(np.abs(vec))), vidx, sv_scale, names)
        d["relative_singular_value"] = float(rel[j])
        d["text"] = f"weakly determined (relative singular value {rel[j]:.2g}): " + d["text"]
        weak.append(d)
    return combos, weak


def fisher_uncertainty(Jz, r_raw, problem, noise, vidx, sv_scale, theta_hat, varied, names, svd_rtol,
                       weak_rtol) -> Uncertainty:
    """Joint uncertainty, identifiability and information criteria at the optimum.

    Parameters
    ----------
    Jz : ndarray, shape (n_res, n_varied)
        Whitened, scaled Jacobian at the optimum (final noise model).
    r_raw : ndarray
        Residuals [m/s] at the optimum.
    problem : LikelihoodProblem
        For the run and sample index of each residual.
    noise : NoiseModel
        The final noise model.
    vidx, sv_scale : ndarray
        Varied entries of the joint vector and their scales.
    theta_hat : ndarray
        The joint estimate.
    varied : ndarray of bool
    names : list of str
        Joint names.
    svd_rtol, weak_rtol : float
        Relative singular-value thresholds for null and weak directions.
    """
    p_all = len(names)
    run_sel = problem.run_sel
    n_runs = problem.lay.R
    n_res = r_raw.size
    r = noise.W(r_raw)  # residuals decorrelated from the start-speed noise
    rho, f_ar = ar1_factors(r, run_sel, problem.sample_sel, n_runs)

    sv, Vt = singular(Jz)
    thr = svd_rtol * (sv[0] if sv.size else 0.0)
    ident = sv > thr
    Vn = Vt[~ident].T  # (p_var, q) null directions in z
    null_norm = np.sqrt(np.sum(Vn * Vn, axis=1)) if Vn.size else np.zeros(vidx.size)
    affected_v = null_norm > NULL_TOL
    k_ident = int(np.sum(ident))

    cov_plain = _embed(_covariance(Jz, sv_scale, svd_rtol, (sv, Vt)), p_all, vidx, affected_v)
    Jc = Jz / np.sqrt(f_ar[run_sel])[:, None]
    cov_corr = _embed(_covariance(Jc, sv_scale, svd_rtol), p_all, vidx, affected_v)
    se_plain = np.sqrt(np.diag(cov_plain))
    se_corr = np.sqrt(np.diag(cov_corr))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_corr / np.outer(se_corr, se_corr)
    ok = np.isfinite(se_corr)
    corr[~ok, :] = np.nan
    corr[:, ~ok] = np.nan
    nr = np.bincount(run_sel, minlength=n_runs)
    n_eff = float(np.sum(nr / f_ar))
    dof = max(n_eff - k_ident, 1.0)
    tq = float(stats.t.ppf(0.975, dof))
    ci = np.column_stack([theta_hat - tq * se_corr, theta_hat + tq * se_corr])
    ci[~varied] = np.nan
    identifiable = np.zeros(p_all, dtype=bool)
    identifiable[vidx[~affected_v]] = True
    loglik = noise.loglik(r_raw)
    combos, weak = _directions(Vn, sv, Vt, ident, vidx, sv_scale, list(names), weak_rtol)
    w_rob = noise.weighted(r_raw)
    infl_v = run_influence(Jz, w_rob, run_sel, sv_scale, svd_rtol, (sv, Vt))   # Jz's one SVD, for both records
    cov_rob_v, n_clusters = cluster_sandwich(Jz, w_rob, run_sel, sv_scale, svd_rtol, influence=infl_v)
    cov_rob = _embed(cov_rob_v, p_all, vidx, affected_v)
    infl = np.zeros((n_runs, p_all))
    infl[:, vidx] = infl_v[:n_runs]
    infl[:, vidx[affected_v]] = np.nan
    se_rob = np.sqrt(np.diag(cov_rob))
    tq_rob = float(stats.t.ppf(0.975, max(n_clusters - 1, 1)))
    ci_rob = np.column_stack([theta_hat - tq_rob * se_rob, theta_hat + tq_rob * se_rob])
    ci_rob[~varied] = np.nan
    return Uncertainty(
        ar1_rho=rho, ar1_factor=f_ar, singular_values=sv.copy(), cov=cov_corr, cov_fisher=cov_plain,
        stderr=se_corr, stderr_fisher=se_plain, corr=corr, n_eff=n_eff, dof=dof, t_quantile=tq, ci95=ci,
        identifiable=identifiable, k_params=k_ident, loglik=loglik, aic=2 * k_ident - 2 * loglik,
        bic=k_ident * math.log(max(n_res, 1)) - 2 * loglik, unidentifiable=combos, null_space=Vn,
        weak_directions=weak, jac_ar1=Jc, cov_robust=cov_rob, stderr_robust=se_rob, ci95_robust=ci_rob,
        run_influence=infl,
    )


def extra_confounding(unc: Uncertainty, p_theta, vidx, sv_scale, names_all, svd_rtol) -> dict:
    """Confounding of each varied extra parameter with theta.

    Its stderr if theta were known (the other extras still varied) against
    the joint one: ``variance_inflation`` (joint variance / conditional
    variance; inf when only the joint fit cannot determine it),
    ``explained_by_theta`` = 1 - 1/inflation and the three ``most_correlated``
    theta parameters. Returns name -> dict (empty without varied extras).
    """
    p = p_theta
    conf = {}
    xcols = np.flatnonzero(vidx >= p)
    if not xcols.size:
        return conf
    Je = unc.jac_ar1[:, xcols]
    s_, Vt_ = singular(Je)
    keep = s_ > svd_rtol * (s_[0] if s_.size and s_[0] > 0 else 1.0)
    keep &= s_ > 0
    Vr = Vt_[keep].T
    cz = (Vr / s_[keep] ** 2) @ Vr.T
    null_e = np.sqrt(np.sum(Vt_[~keep].T ** 2, axis=1)) if (~keep).any() else np.zeros(xcols.size)
    se_cond = np.sqrt(np.diag(cz)) * sv_scale[xcols]
    se_cond = np.where(null_e > NULL_TOL, np.inf, se_cond)
    for jj, c in enumerate(xcols):
        i = int(vidx[c])
        nm = names_all[i]
        se_j = float(unc.stderr[i])
        sc = float(se_cond[jj])
        with np.errstate(divide="ignore", invalid="ignore"):
            vif = se_j**2 / sc**2 if (np.isfinite(sc) and sc > 0) else float("nan")
        if not np.isfinite(se_j) and np.isfinite(sc):
            vif = float("inf")
        cr = unc.corr[i, :p]
        ok = np.flatnonzero(np.isfinite(cr))
        top = ok[np.argsort(-np.abs(cr[ok]))][:3]
        conf[nm] = {
            "stderr": se_j,
            "stderr_if_theta_known": sc,
            "variance_inflation": float(vif),
            "explained_by_theta": float(1.0 - 1.0 / vif) if np.isfinite(vif) and vif > 0 else (
                1.0 if vif == np.inf else float("nan")),
            "most_correlated": [(names_all[j], float(cr[j])) for j in top],
        }
    return conf


def alternative_optima(results, candidates, best, theta_of, theta_hat, unc: Uncertainty, names_all, alt_tol):
    """Other converged optima of the global search that fit almost as well but lie far away.

    ``results``: start -> OptimizeResult; ``candidates``: the refined starts;
    ``best``: the chosen start; ``theta_of``: z -> joint vector. An optimum
    within ``alt_tol`` log-likelihood units of the best that differs by more
    than 3 stderr (identifiable entries) is reported (discrete
    non-identifiability, e.g. the split of C(s) into P and A').
    """
    alts = []
    for i in candidates:
        if i == best or results[i].status == 0:
            continue
        dll = float(results[i].cost - results[best].cost)
        th_i = theta_of(results[i].x)
        with np.errstate(divide="ignore", invalid="ignore"):
            zd = np.abs(th_i - theta_hat) / unc.stderr
        zd = np.where(unc.identifiable & np.isfinite(zd), zd, 0.0)
        dup = any(np.allclose(th_i, np.asarray(a["theta"]), rtol=1e-3, atol=1e-12) for a in alts)
        if dll < alt_tol and zd.max() > 3.0 and not dup:
            top = np.argsort(-zd)[:6]
            alts.append(
                {
                    "start": int(i),
                    "delta_loglik": dll,
                    "theta": th_i.tolist(),
                    "max_z": float(zd.max()),
                    "differs_most": [(names_all[j], float(th_i[j]), float(zd[j])) for j in top if zd[j] > 3.0],
                }
            )
    return alts
