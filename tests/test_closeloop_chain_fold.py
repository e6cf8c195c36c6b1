"""One fold of the measurement chain's cross-validation (``l1b2.closeloop.acceptance.fold_error`` with ``chain_k``):
the held-out speed is predicted through the stage that the fold's own speed-channel test keeps.

The fold's refit and its channel test are replaced by fixed answers, so the held-out sum of squares is written out
here from the prediction and the stage.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import chain
from l1b2.data import measurements as dataio
from l1b2.predictor.effects import apply_output_filter

DT = 1e-3


def _frame(n_runs=4, n=30):
    rng = np.random.default_rng(0)
    return pd.DataFrame({dataio.RUN: np.repeat(np.arange(1, n_runs + 1), n),
                         dataio.TIME: np.concatenate([10.0 * k + DT * np.arange(n) for k in range(n_runs)]),
                         dataio.POSITION: np.tile(1e-4 * np.arange(n), n_runs),
                         dataio.SPEED: rng.uniform(-0.1, 0.2, n_runs * n)})


@pytest.mark.parametrize("accepted", [False, True])
def test_a_fold_predicts_through_the_stage_its_own_test_keeps(monkeypatch, accepted):
    df = _frame()
    held = np.array([2, 4])
    test = df[df[dataio.RUN].isin(held)]
    pred = 0.15 * np.sin(np.arange(len(test)) / 5.0)      # the physics' free run on the held-out runs [m/s]

    class Physics:
        convergence_ = {"nfev_total": 11}

        def predict_free_run(self, frame):
            assert np.allclose(frame[dataio.SPEED].to_numpy(), chain.position_derivative(frame))  # the derivative
            return pred

    stage = chain.OutputFilter(0.5, 0.3, 0.2, hi_m_s=0.1)
    monkeypatch.setattr(acc, "refit", lambda *a, **k: Physics())
    monkeypatch.setattr(acc.chain, "speed_channel", lambda *a, **k: {"accepted": accepted, "filter": stage})
    sse, ss_meas, failed, nfev, run_sse = acc.fold_error(df, np.ones(len(df), bool), 0.1, held, None,
                                                         acc.EffectSet(), acc.RefitSettings(), chain_k=3)
    # accepted: the stage's filter and clip run on each held-out run; rejected: no stage, the free run itself
    starts = [0, len(test) // 2]
    want = apply_output_filter(stage.params(), pred, starts) if accepted else pred
    v = test[dataio.SPEED].to_numpy()
    assert sse == pytest.approx(float(np.sum((v - want) ** 2)), rel=1e-12)
    assert ss_meas == pytest.approx(float(np.sum(v ** 2)), rel=1e-12) and not failed and nfev == 11
    assert set(run_sse) == {2, 4}
