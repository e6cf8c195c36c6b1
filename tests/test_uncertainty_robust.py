"""Robust (cluster-by-run sandwich) uncertainty beside the Fisher one (issue 14).

* :func:`l1b2.ident.uncertainty.cluster_sandwich` is the textbook cluster-robust
  covariance (checked against the formula written out for least squares);
* in a world where the model misses an effect (runs share a random offset
  the model does not have), the Fisher intervals are far too narrow while
  the sandwich ones cover - for plain least squares (cheap, many
  repetitions) and for the predictor's identification itself.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest
from l1b2.ident.uncertainty import cluster_sandwich
from scipy import stats


def _clustered_world(rng, n_clusters=30, per=40, tau=1.0, sigma=0.3):
    """y = 1 + 2 x + u_g + e: a random offset u_g per cluster (the model y = a + b x lacks it)."""
    g = np.repeat(np.arange(n_clusters), per)
    x_level = rng.normal(0.0, 1.0, n_clusters)           # the regressor varies mostly between clusters
    x = x_level[g] + 0.1 * rng.normal(0.0, 1.0, g.size)
    y = 1.0 + 2.0 * x + rng.normal(0.0, tau, n_clusters)[g] + rng.normal(0.0, sigma, g.size)
    return x, y, g


def test_cluster_sandwich_is_the_textbook_formula():
    # reference: Cameron & Miller (2015), cluster-robust variance with the G/(G-1) correction,
    # V = (X'X)^-1 (G/(G-1) sum_g X_g' e_g e_g' X_g) (X'X)^-1, in the parameters' physical scale
    rng = np.random.default_rng(1)
    x, y, g = _clustered_world(rng, n_clusters=12, per=15)
    X = np.column_stack([np.ones_like(x), x])
    b = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ b
    scale = np.array([2.0, 0.5])                 # the estimator works in scaled coordinates z = theta / scale
    cov, G = cluster_sandwich(-X * scale, e, g, scale, 1e-12)
    bread = np.linalg.inv(X.T @ X)
    meat = sum(np.outer(X[g == k].T @ e[g == k], X[g == k].T @ e[g == k]) for k in range(12)) * 12 / 11
    np.testing.assert_allclose(cov, bread @ meat @ bread, rtol=1e-10)
    assert G == 12


def test_sandwich_covers_where_fisher_does_not_least_squares():
    # reference: a misspecified world - the cluster offsets make the samples of a cluster share an error;
    # 95 % Fisher intervals (sigma^2 (X'X)^-1) cover far less than 95 %, the sandwich ones about 95 %
    rng = np.random.default_rng(7)
    cover = {"fisher": [], "sandwich": []}
    for _ in range(400):
        x, y, g = _clustered_world(rng)
        X = np.column_stack([np.ones_like(x), x])
        b = np.linalg.lstsq(X, y, rcond=None)[0]
        e = y - X @ b
        fisher = np.linalg.inv(X.T @ X) * (e @ e) / (e.size - 2)
        robust, G = cluster_sandwich(-X, e, g, np.ones(2), 1e-12)
        for name, cov, q in (("fisher", fisher, stats.norm.ppf(0.975)),
                             ("sandwich", robust, stats.t.ppf(0.975, G - 1))):
            cover[name].append(abs(b[1] - 2.0) <= q * np.sqrt(cov[1, 1]))
    fisher, sandwich = np.mean(cover["fisher"]), np.mean(cover["sandwich"])
    assert fisher < 0.5, fisher
    assert 0.90 <= sandwich <= 0.99, sandwich
