"""The closed loop's cross-validated refits as tasks of the Dask engine: the answer does not depend on where they ran."""

import numpy as np
import pytest
from l1b2.closeloop import residuals as res
from l1b2.closeloop.acceptance import EffectSet, RefitSettings, cv_errors, fold_error, fold_start_phi
from l1b2.closeloop.folds import stratified_folds
from l1b2.closeloop.candidates import full_library
from l1b2.closeloop.loop import analyse_residuals, candidate_context
from l1b2.closeloop.selection import design
from l1b2.cluster import optional_client
from l1b2.data.measurements import load_measurements
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.rig.experiment import RigPlan
from rigcache import rig_dir


def test_cv_refits_on_a_local_cluster_equal_the_serial_ones():
    # reference: the same refits run one by one in this process (fold_error), to rounding (1e-12 relative: the
    # worker processes' BLAS may sum in another order)
    d = rig_dir("pulley_friction_1", injections=["pulley_friction"], injection_seed=1,
                plan=RigPlan(step_s=1e-3, seed=1))
    m = load_measurements(d / "train.csv")
    df, mask, m_s = m.df, np.array(m.mask), m.slider_mass_kg
    base = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=1, seed=0,
                               max_nfev=20, noise_fit="alternate").fit(df, slider_mass_kg=m_s, mask=mask)
    v = base.predict_free_run(df)
    a = analyse_residuals(df, v, mask, alpha=0.01, k=3, seed=0)
    pool = {c.family: c for c in full_library()(candidate_context(base.predict_free_run, m_s, df, mask, a.peak), df)}
    c = pool["load_path_friction"]
    r = res.drive_residual(df, v)
    y, A, S, runs_m = design(c, r, df, mask, base.params_, m_s, v_pred=v)
    folds = stratified_folds(df, 3, 0)
    fphi = fold_start_phi(S, A, y, runs_m, folds)
    jobs = [(EffectSet(), None), (EffectSet().add(c, np.zeros(c.n_params)), fphi)]
    settings = RefitSettings(order=8, seed=0, max_nfev=3)
    serial = cv_errors(df, mask, m_s, folds, base.params_, jobs, settings)
    with optional_client(2, serial_up_to=1) as client:
        assert len(client.nthreads()) == 2
        parallel = cv_errors(df, mask, m_s, folds, base.params_, jobs, RefitSettings(8, 0, 3, client=client))
    for s, p in zip(serial, parallel):
        np.testing.assert_allclose(p.sse, s.sse, rtol=1e-12, atol=0)
        np.testing.assert_array_equal(s.ss_meas, p.ss_meas)
        assert s.failed == p.failed == 0
    # each entry is the one-fold refit; the candidate lowers the held-out error (pulley friction is in the data)
    one = fold_error(df, mask, m_s, folds[1], base.params_, jobs[1][0].with_phi(fphi[1]), settings)
    assert one[0] == pytest.approx(serial[1].sse[1], rel=1e-12) and one[1] == serial[1].ss_meas[1]
    # the same held-out sums of squares per run: every run of the fold, adding up to the fold's
    assert sorted(one[4]) == sorted(folds[1].tolist()) and sum(one[4].values()) == pytest.approx(one[0], rel=1e-12)
    for s, p in zip(serial, parallel):
        assert sorted(s.run_sse) == sorted(np.concatenate(folds).tolist()) and p.run_sse.keys() == s.run_sse.keys()
        for f, fold in enumerate(folds):
            assert sum(s.run_sse[r] for r in fold) == pytest.approx(s.sse[f], rel=1e-12)
            assert sum(p.run_sse[r] for r in fold) == pytest.approx(p.sse[f], rel=1e-12)
    assert serial[1].sse.sum() < serial[0].sse.sum()


@pytest.mark.parametrize("workers,serial_up_to", [(0, 0), (0, 1), (1, 1)])
def test_no_cluster_is_started_for_the_in_process_worker_counts(workers, serial_up_to):
    # reference: the callers' rule (a sweep runs in process with 0 workers, the close-loop refits with 0 or 1)
    with optional_client(workers, serial_up_to=serial_up_to) as client:
        assert client is None
