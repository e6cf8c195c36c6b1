"""The sensor stages' one skeleton (:mod:`l1b2.closeloop.stagefit`): the physics behind a stage, one fold of a
stage's model and the screen, checked with a stage written out here (a constant gain ``v_rec = k u``) against
the least squares written out."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import stagefit
from l1b2.closeloop.acceptance import RefitSettings
from l1b2.data import measurements as dataio
from l1b2.errors import IdentificationError
from l1b2.predictor.model import example_params


class Gain:
    """A stage ``v_rec = k u``: the frame behind it has the speed over ``k``."""

    def __init__(self, k):
        self.k = float(k)

    def frame(self, df):
        out = df.copy()
        out[dataio.SPEED] = df[dataio.SPEED].to_numpy() / self.k
        return out

    def apply(self, df, u):
        return self.k * np.asarray(u, float)

    def refit(self, df, mask, v_model):
        return fit_gain(df, mask, v_model)


def fit_gain(df, mask, v_model):
    """``k`` of the least squares of the recorded speed on ``k v_model`` (masked samples)."""
    m = np.asarray(mask, bool)
    y, v = df[dataio.SPEED].to_numpy()[m], np.asarray(v_model, float)[m]
    return Gain(v @ y / (v @ v))


class Affine:
    """A physics model whose free run is ``2 v + 0.01`` of a frame's speed ``v`` [m/s]."""
    convergence_ = {"nfev_total": 7}

    def predict_free_run(self, df):
        return 2.0 * df[dataio.SPEED].to_numpy() + 0.01


def frame(n_runs=4, n=40, seed=0):
    """Runs at 1 ms with speeds of alternating direction (data convention: signed speed)."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        v = d * (0.05 + 0.02 * r) * (1 + 0.2 * np.sin(np.linspace(0, 3, n))) + 1e-3 * rng.standard_normal(n)
        rows.append(pd.DataFrame({dataio.RUN: r, dataio.TIME: np.arange(n) * 1e-3,
                                  dataio.POSITION: np.cumsum(v) * 1e-3, dataio.SPEED: v,
                                  dataio.VOLTAGE: 220.0 + 20 * r, dataio.LOAD: 0.0, dataio.DIRECTION: d}))
    return pd.concat(rows, ignore_index=True)


def test_the_physics_is_identified_behind_the_stage_and_the_stage_refitted_to_its_free_run():
    df = frame()
    y = df[dataio.SPEED].to_numpy()
    mask = np.arange(len(df)) % 3 != 0
    v_base = 0.9 * y + 0.002
    seen = []

    def identify(f):
        seen.append(f[dataio.SPEED].to_numpy())
        return Affine()
    model, stage = stagefit.physics_behind(df, mask, v_base, fit_gain, identify)
    k0 = (v_base[mask] @ y[mask]) / (v_base[mask] @ v_base[mask])
    np.testing.assert_allclose(seen[0], y / k0, rtol=1e-13)       # identified on the frame behind the first fit
    m1 = 2.0 * y / k0 + 0.01                                       # that model's free run on that frame
    assert isinstance(model, Affine) and len(seen) == 1
    assert stage.k == pytest.approx((m1[mask] @ y[mask]) / (m1[mask] @ m1[mask]), rel=1e-12)


def test_a_fold_fits_the_stage_on_the_training_runs_and_predicts_the_held_out_ones(monkeypatch):
    df = frame()
    y = df[dataio.SPEED].to_numpy()
    runs = df[dataio.RUN].to_numpy()
    mask = np.ones(len(df), bool)
    mask[::5] = False
    v_base = 0.9 * y + 0.002
    refits = []

    def fake_refit(f, m, m_s, init, effects, settings):
        refits.append((set(f[dataio.RUN]), m_s, init))
        return Affine()
    monkeypatch.setattr(stagefit, "refit", fake_refit)
    sse, ss_meas, failed, nfev, run_sse = stagefit.stage_fold_error(df, mask, 0.1, [1], "start", RefitSettings(),
                                                                     v_base, fit_gain)
    tr, te = runs != 1, runs == 1
    k0 = (v_base[tr & mask] @ y[tr & mask]) / (v_base[tr & mask] @ v_base[tr & mask])
    m1 = (2.0 * y / k0 + 0.01)[tr & mask]
    k1 = (m1 @ y[tr & mask]) / (m1 @ m1)
    pred = k1 * (2.0 * y[te] / k1 + 0.01)                         # the stage on the physics behind it
    e = (y[te] - pred)[mask[te]]
    assert refits == [({0, 2, 3}, 0.1, "start")]
    assert sse == pytest.approx(e @ e, rel=1e-12) and run_sse == {1: pytest.approx(e @ e, rel=1e-12)}
    assert ss_meas == pytest.approx(y[te & mask] @ y[te & mask], rel=1e-12)
    assert (failed, nfev) == (False, 7)

    def failing(*a, **k):
        raise IdentificationError("no fit")
    monkeypatch.setattr(stagefit, "refit", failing)
    out = stagefit.stage_fold_error(df, mask, 0.1, [1], "start", RefitSettings(), v_base, fit_gain)
    assert out[0] == np.inf and out[2] is True and out[4] == {1: np.inf}


def test_the_screen_takes_one_column_or_many_and_scores_rivals_on_the_same_folds():
    """A residual that is the stage's response times 0.3 (plus noise) is removed by it (held-out gain near 1 in
    every run); a rival with the same columns gains as much, one of noise nothing; a column given flat or as
    ``(n, 1)`` is the same screen."""
    df = frame(n_runs=6, n=60)
    params = example_params(3)
    folds = [[0, 1], [2, 3], [4, 5]]
    v = df[dataio.SPEED].to_numpy()
    d = df[dataio.DIRECTION].to_numpy()
    rng = np.random.default_rng(1)
    S = np.sin(40 * df[dataio.POSITION].to_numpy()) * np.abs(v)
    v_pred = v - d * (0.3 * S + 1e-6 * rng.standard_normal(len(v)))
    mask = np.ones(len(df), bool)
    noise = rng.standard_normal(len(v))
    got = stagefit.screen(df, mask, v_pred, params, 0.1, folds, S, {"same": S[:, None], "noise": noise})
    assert got["cv_gain"] > 0.9 and got["runs_improved"] == 1.0 and got["p_value"] < 0.05
    assert got["same_cv_gain"] == pytest.approx(got["cv_gain"], rel=1e-12)
    assert got["noise_cv_gain"] < 0.1
    flat = stagefit.screen(df, mask, v_pred, params, 0.1, folds, S[:, None])
    assert flat == {k: got[k] for k in ("cv_gain", "p_value", "runs_improved")}


def test_columns_that_diverge_or_vanish_score_no_gain_and_do_not_break_the_screen():
    """A stage or rival whose linearised response is not finite somewhere (or is all zero) scores as the candidates'
    screen scores it, no gain and p-value 1, and the other columns keep their scores."""
    df = frame(n_runs=6, n=60)
    params = example_params(3)
    folds = [[0, 1], [2, 3], [4, 5]]
    v = df[dataio.SPEED].to_numpy()
    d = df[dataio.DIRECTION].to_numpy()
    S = np.sin(40 * df[dataio.POSITION].to_numpy()) * np.abs(v)
    v_pred = v - d * 0.3 * S
    mask = np.ones(len(df), bool)
    bad = np.column_stack([S, S])
    bad[7, 1] = np.nan
    inf = np.full((len(df), 2), np.inf)
    got = stagefit.screen(df, mask, v_pred, params, 0.1, folds, S, {"nan": bad, "inf": inf, "zero": 0 * S})
    assert got["cv_gain"] > 0.9
    assert got["nan_cv_gain"] == 0.0 and got["inf_cv_gain"] == 0.0 and got["zero_cv_gain"] == 0.0
    assert stagefit.screen(df, mask, v_pred, params, 0.1, folds, bad) == {"cv_gain": 0.0, "p_value": 1.0,
                                                                          "runs_improved": 0.0}
    # a value that is not finite on a sample the mask leaves out is not read
    m2 = mask.copy()
    m2[7] = False
    assert stagefit.screen(df, m2, v_pred, params, 0.1, folds, bad)["cv_gain"] > 0.9
