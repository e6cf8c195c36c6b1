#!/usr/bin/env python
"""Diagnosis: where a fit of ``bench_identify_realistic.py``'s data differs from the long reference fit.

Fits the same cached data (``bench_identify_realistic.py`` makes it) with several searches, one of which is the
reference (``--reference``, default the bracketed drive-offset search, the best point this tree finds on these
data), and compares every fit with it:

* the parameters in the identifiable coordinates of :mod:`l1b2.ident.identifiable` (``K``, ``beta_s``, the
  Legendre coefficients ``d_j`` of D(s), ``mu_sd``, ``beta_j``, ``p_j``): the paper's (c_r, sigma, mu, k0, alpha)
  hold two exact null directions, so their differences say nothing; the difference of each coordinate in
  standard errors of the reference (the Fisher one, white residuals, and the AR(1)-corrected one the fit report
  prints), from the covariance of the varied parameters mapped by the Jacobian of y(theta) (finite differences);
* the whole difference as a quadratic form ``dy' F dy / 2`` in the reference's Fisher information (the gain the
  reference's quadratic model predicts for the move; equal to the log-likelihood gap if the fit lies in the
  reference's basin), and the same with the AR(1)-corrected information;
* the log-likelihood gap split over runs (each run's share of ``-N/2 log(S_fit / S_ref)``, S the whitened sum of
  squares; common noise), the runs grouped by direction, voltage and load;
* the free-run speed of the fit against the reference's on TRAIN and TEST (rms difference [m/s] over the samples of
  the evaluation mask) and each fit's free-run nrmse.

Prints a table; ``--json FILE`` writes every figure. The identification code is not changed: the Jacobian at each
optimum is the one the estimator's uncertainty step receives (captured by wrapping
``l1b2.ident.estimator.fisher_uncertainty``).

Usage: python bench/bench_identify_gap.py [--fits default,varpro,varpro4,varpro_long] [--reference offset_bracket]
                                         [--init FILE] [--json FILE]
"""
import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

import bench_identify_realistic as realistic  # noqa: E402
from l1b2.data.metrics import speed_metrics  # noqa: E402
from l1b2.ident import estimator as est_mod  # noqa: E402
from l1b2.ident.identifiable import admissible, y_of_theta  # noqa: E402
from l1b2.ident.offset import d_coefficients, drive_offset, multiplier, omega_of_offset  # noqa: E402
from l1b2.ident.uncertainty import _covariance  # noqa: E402
from l1b2.workflows import load_train_test  # noqa: E402

#: the fits (name -> PredictorIdentifier settings); "varpro_long" is bench_identify_realistic's long varpro fit
FITS = {"default": {}, "varpro": {"solver": "varpro", "n_starts": 1}, "varpro4": {"solver": "varpro", "n_starts": 4},
        "offset_bracket": {"solver": "offset_bracket"}, "varpro_long": dict(realistic.REFERENCE_VARPRO)}
#: a vector given by ``--init FILE`` (JSON with "values", Eq. 35 order) is continued by this search (the
#: continuation of bench_identify_worlds.py's strict reference) and named "from_init"
CONTINUATION = {"solver": "varpro", "n_starts": 1, "stat_tol": 1e-4, "tol": 1e-12, "max_nfev": 600, "max_outer": 10}


def y_names(names, n1):
    out = list(names)
    out[0], out[2] = "K", "beta_s"
    out[1], out[3] = "sigma (gauge)", "k0 (gauge)"
    for j in range(n1):
        out[5 + j] = f"d_{j}"
    return out


def y_jacobian(theta, n1, rel=1e-7):
    """dy/dtheta by central differences (y_of_theta is smooth where sigma, mu, G(k0) are non-zero)."""
    theta = np.asarray(theta, float)
    T = np.empty((theta.size, theta.size))
    for k in range(theta.size):
        h = rel * max(abs(theta[k]), 1e-3)
        tp, tm = theta.copy(), theta.copy()
        tp[k] += h
        tm[k] -= h
        T[:, k] = (y_of_theta(tp, n1) - y_of_theta(tm, n1)) / (2 * h)
    return T


def run_fit(train, settings):
    """Fit; returns the estimator and what its uncertainty step received (Jacobian, residuals, noise model)."""
    seen = {}
    orig = est_mod.fisher_uncertainty

    def capture(Jz, r, problem, noise, vidx, sv_scale, theta_hat, *a, **k):
        unc = orig(Jz, r, problem, noise, vidx, sv_scale, theta_hat, *a, **k)
        seen.update(Jz=np.array(Jz), Jc=np.array(unc.jac_ar1), r=np.array(r), w=np.array(noise.weighted(r)),
                    run_sel=np.array(problem.run_sel), vidx=np.array(vidx), sv_scale=np.array(sv_scale),
                    theta=np.array(theta_hat))
        return unc

    est_mod.fisher_uncertainty = capture
    try:
        est = est_mod.PredictorIdentifier(**settings)
        c0 = time.process_time()
        est.fit(train)
        cpu = time.process_time() - c0
    finally:
        est_mod.fisher_uncertainty = orig
    return est, seen, cpu


def y_covariance(seen, n1, J):
    """Covariance of y at the fit (pseudo-inverse on the identified subspace, mapped by dy/dtheta)."""
    cov_v = _covariance(J, seen["sv_scale"], 1e-8)
    T = y_jacobian(seen["theta"], n1)[:, seen["vidx"]]
    return T @ cov_v @ T.T


def nrmse_of(est, d):
    """Free-run nrmse of a fit on a data set (the benchmark's and the report's figure)."""
    return speed_metrics(est.predict_free_run(d), d.df["speed_m_s"].to_numpy(), est_mod.evaluation_mask(d.df))["nrmse"]


def drive_terms(theta, n1, kappa):
    """The offset omega, admissibility (sigma, b > 0, K < 0), D(s) and the moving slider's drive term
    C(s) = P(s) (a - b A'(s)) on the stroke grid of :mod:`l1b2.ident.offset` [N s/m, N]."""
    th = np.asarray(theta, float)
    dco = d_coefficients(th, n1)
    x = np.linspace(-1.0, 1.0, 401)
    P = np.polynomial.legendre.legval(x, th[5 + 2 * n1:5 + 3 * n1])
    return {"omega": omega_of_offset(drive_offset(th, n1, kappa), dco), "admissible": admissible(th, n1),
            "D": np.polynomial.legendre.legval(x, dco), "C": P * multiplier(th, n1, kappa)}


def run_groups(train, labels):
    """Per run of the fit's layout (``labels``: ``runs_``): label, direction, voltage, load (first sample's)."""
    df = train.df
    key = df["run"].astype(str)
    out = []
    for i, label in enumerate(labels):
        g = df[key == str(label)]
        out.append({"run": i, "label": str(label), "direction": int(np.sign(g["direction"].iloc[0])),
                    "V0": float(g["voltage_V"].iloc[0]), "load_kg": float(g["load_kg"].iloc[0])})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--fits", default="default,varpro,varpro4,varpro_long",
                    help=f"the fits compared, names of {sorted(FITS)} or from_init, separated by commas")
    ap.add_argument("--reference", default="offset_bracket",
                    help="the fit the others are compared with (default offset_bracket: the best point this tree "
                         "finds on this data, where bench_identify_worlds.py's strict reference ends too)")
    ap.add_argument("--init", help="JSON file with 'values' (Eq. 35 order): the fit 'from_init' continues it")
    ap.add_argument("--json")
    ap.add_argument("--cache", default=str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
                                         / "l1b2" / "bench"))
    args = ap.parse_args(argv)
    data = realistic.dataset(Path(args.cache))
    train, test, _ = load_train_test(data / "train.csv", data / "test.csv")
    if args.init:
        FITS["from_init"] = {**CONTINUATION, "init": json.loads(Path(args.init).read_text())["values"]}
    fits = {}
    for name in [args.reference] + [f for f in args.fits.split(",") if f and f != args.reference]:
        est, seen, cpu = run_fit(train, FITS[name])
        fits[name] = (est, seen, cpu)
        print(f"{name}: loglik {est.loglik_:.3f}, CPU {cpu:.1f} s, evaluations {est.convergence_['nfev_total']}",
              flush=True)
    ref, rs, _ = fits[args.reference]
    n1 = ref.order + 1
    names = y_names(ref.param_names_all_, n1)
    y_ref = y_of_theta(rs["theta"], n1)
    cov_f, cov_c = y_covariance(rs, n1, rs["Jz"]), y_covariance(rs, n1, rs["Jc"])
    se_f, se_c = np.sqrt(np.maximum(np.diag(cov_f), 0)), np.sqrt(np.maximum(np.diag(cov_c), 0))
    live = se_f > 1e-12 * np.max(se_f)
    live[[1, 3]] = False   # the gauge (sigma, k0): not determined by the data
    N = rs["w"].size
    S_ref = np.bincount(rs["run_sel"], weights=rs["w"] ** 2)
    runs = run_groups(train, ref.runs_)
    t_ref = drive_terms(rs["theta"], n1, ref.kappa)
    print(f"reference: offset omega {t_ref['omega']:.4f}, admissible (sigma, b > 0, K < 0): {t_ref['admissible']}")
    v_ref = {k: ref.predict_free_run(d) for k, d in (("train", train), ("test", test))}
    out = {"reference": {"name": args.reference, "loglik": float(ref.loglik_), "y": dict(zip(names, y_ref.tolist())),
                         "se_fisher": dict(zip(names, se_f.tolist())), "se_ar1": dict(zip(names, se_c.tolist())),
                         "n_eff": float(ref.n_eff_), "n_obs": int(ref.n_obs_),
                         "omega": t_ref["omega"], "admissible": t_ref["admissible"]}, "fits": {}}
    print(f"reference ({args.reference}): loglik {ref.loglik_:.3f}, n_obs {ref.n_obs_}, n_eff {ref.n_eff_:.1f}, "
          f"AR(1) factor median {np.median(ref.ar1_factor_):.0f}")
    for name, (est, seen, cpu) in fits.items():
        if name == args.reference:
            continue
        y = y_of_theta(seen["theta"], n1)
        dy = y - y_ref
        z_f = np.where(live, dy / np.where(live, se_f, 1), np.nan)
        z_c = np.where(live, dy / np.where(live, se_c, 1), np.nan)
        q_f = 0.5 * float(dy[live] @ np.linalg.pinv(cov_f[np.ix_(live, live)], rcond=1e-10) @ dy[live])
        q_c = 0.5 * float(dy[live] @ np.linalg.pinv(cov_c[np.ix_(live, live)], rcond=1e-10) @ dy[live])
        S = np.bincount(seen["run_sel"], weights=seen["w"] ** 2)
        share = -0.5 * N * (S - S_ref) / S_ref.sum()   # first-order split of -N/2 log(S/S_ref) over runs
        dv = {k: float(np.sqrt(np.mean((est.predict_free_run(d) - v_ref[k])[est_mod.evaluation_mask(d.df)] ** 2)))
              for k, d in (("train", train), ("test", test))}
        nrmse = {k: nrmse_of(est, d) for k, d in (("train", train), ("test", test))}
        gap = float(est.loglik_ - ref.loglik_)
        tf = drive_terms(seen["theta"], n1, ref.kappa)
        rel = {k: float(np.sqrt(np.mean((tf[k] - t_ref[k]) ** 2)) / np.sqrt(np.mean(t_ref[k] ** 2))) for k in "DC"}
        print(f"\n== {name}: loglik {est.loglik_:.3f} (gap {gap:+.3f}), CPU {cpu:.1f} s; quadratic model of the "
              f"reference: 0.5 dy'F dy = {q_f:.2f} (Fisher), {q_c:.3f} (AR(1)-corrected); free-run rms difference "
              f"TRAIN {1e3 * dv['train']:.3f} mm/s, TEST {1e3 * dv['test']:.3f} mm/s "
              f"(residual rms {1e3 * est.residual_rms_:.3f} mm/s, reference {1e3 * ref.residual_rms_:.3f}); free-run "
              f"nrmse TRAIN {100 * nrmse['train']:.2f} % (reference {100 * nrmse_of(ref, train):.2f} %), TEST "
              f"{100 * nrmse['test']:.2f} % (reference {100 * nrmse_of(ref, test):.2f} %)")
        print(f"offset omega {tf['omega']:.4f} (reference {t_ref['omega']:.4f}), admissible {tf['admissible']}; "
              f"rms difference over the stroke relative to the reference's rms: D(s) {rel['D']:.4f}, "
              f"drive term C(s) {rel['C']:.4f}")
        order = np.argsort(-np.nan_to_num(np.abs(z_f)))
        print(f"{'coordinate':>14} {'fit':>12} {'reference':>12} {'diff':>11} {'/se Fisher':>10} {'/se AR(1)':>9}")
        for k in order:
            if not live[k]:
                continue
            print(f"{names[k]:>14} {y[k]:12.5g} {y_ref[k]:12.5g} {dy[k]:11.3g} {z_f[k]:10.2f} {z_c[k]:9.3f}")
        top = np.argsort(share)[:8]
        print("runs losing most (share of the gap, log-likelihood units): " + ", ".join(
            f"{runs[i]['label']} (dir {runs[i]['direction']}, V0 {runs[i]['V0']:g}, load {runs[i]['load_kg']:g}) "
            f"{share[i]:.2f}" for i in top))
        groups = {}
        for i, rr in enumerate(runs):
            for key in (f"direction {rr['direction']}", f"V0 {rr['V0']:g}", f"load {rr['load_kg']:g}"):
                groups[key] = groups.get(key, 0.0) + float(share[i])
        print("by group: " + ", ".join(f"{k} {v:.2f}" for k, v in sorted(groups.items())))
        out["fits"][name] = {"loglik": float(est.loglik_), "gap": gap, "cpu_s": cpu, "q_fisher": q_f, "q_ar1": q_c,
                             "y": dict(zip(names, y.tolist())), "z_fisher": dict(zip(names, z_f.tolist())),
                             "z_ar1": dict(zip(names, z_c.tolist())), "run_share": share.tolist(),
                             "groups": groups, "free_run_rms_diff_m_s": dv, "nrmse": nrmse,
                             "omega": tf["omega"], "admissible": tf["admissible"], "rel_rms_diff": rel,
                             "convergence_stages": est.convergence_.get("stages", [])}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
