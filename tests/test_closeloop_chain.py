"""The measurement chain in the closed loop: a low-passed speed column is settled before any physical effect.

The rig writes the speed column through a first-order low-pass (``speed_lowpass``,
a data injection: the motor is untouched). The close-the-loop estimator finds
the filter from position and speed alone, identifies the physics on the
position's derivative and applies the filter to its predictions; the exported
model carries the same filter. Exact (reference) world here; the realistic
world's case is in ``tests/test_closeloop_realistic.py``.
"""

import json

import numpy as np
import pytest
from l1b2.closeloop.chain import with_position_speed
from l1b2.closeloop.loop import close_loop
from l1b2.data import measurements as dataio
from l1b2.data.measurements import load_measurements
from l1b2.data.metrics import report_metrics
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.rig.experiment import RigPlan
from rigcache import assert_round_trips, rig_dir


def test_low_passed_speed_column_is_settled_first_and_carried_by_the_exported_model():
    # reference: rig_truth.json (the filter's time constant), the held-out free-run nrmse before/after, and the
    # estimator's own prediction of TEST for the serialisable model (1e-10 relative)
    seed = 8
    d = rig_dir(f"speed_lowpass_{seed}", injections=["speed_lowpass"], injection_seed=seed,
                plan=RigPlan(step_s=1e-3, seed=seed))
    train, test = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    tau = json.loads((d / "rig_truth.json").read_text())["injections"][0]["parameters"]["DAQ.speed_tau_s"]
    res = close_loop(train, test)
    assert_round_trips(res)
    diag = res.diagnosis
    assert diag["measurement_chain"]["accepted"], diag["measurement_chain"]
    # kept because the chain model predicts held-out runs better than the baseline, both refitted per fold
    mc = diag["measurement_chain"]
    assert mc["cv_free_run_gain"] > 0 and mc["cv_free_run_nrmse_chain"] < mc["cv_free_run_nrmse_baseline"], mc
    assert diag["traced_to"][0] == "speed", diag["traced_to"]
    assert res.rounds[1]["added"] == "speed_channel_filter"
    assert diag["effects"][0]["effect"] == diag["effect"] == "speed_channel_filter"
    dt = float(np.median(np.diff(train.df[dataio.TIME])))
    assert diag["measurement_chain"]["filter"]["a"] == pytest.approx(np.exp(-dt / tau), abs=0.02)
    # the held-out error cut by at least half of the excess over the same world without the filter (b0: the
    # baseline identified and evaluated on the position's derivative), in quadrature
    b = res.before["test"]["free_run"]["nrmse"]
    a = res.after["test"]["free_run"]["nrmse"]
    clean = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=4, seed=0,
                                noise_fit="alternate")  # the loop's baseline search
    clean.fit(with_position_speed(train.df), slider_mass_kg=train.slider_mass_kg, mask=np.array(train.mask))
    te_clean = with_position_speed(test.df)
    b0 = report_metrics(te_clean, clean.predict_one_step(te_clean),
                        clean.predict_free_run(te_clean))["free_run"]["nrmse"]
    assert b > 1.1 * b0, (b0, b)   # the filter is visible in the baseline's error
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a, diag["message"])

    # the exported model: the physics on the slider's speed, then the same output filter
    ep = res.calibrated_model
    assert ep.output_filter == {k: diag["measurement_chain"]["filter"][k] for k in ("a", "b0", "b1")}
    te = test.df
    v_start = with_position_speed(te).groupby(dataio.RUN, sort=False)[dataio.SPEED].first().to_numpy()
    v = ep.free_run(te[dataio.TIME], te[dataio.POSITION], te[dataio.VOLTAGE], te[dataio.LOAD],
                    te[dataio.DIRECTION], v_start, te[dataio.RUN].to_numpy())
    ref = res.extended_model.predict_free_run(te)
    assert np.max(np.abs(v - ref)) <= 1e-10 * np.max(np.abs(ref))
