"""The rest before each run's onset (l1b2.data.onset): detected against the columns' noise, cut on reading,
counted in the checks and named in the close loop's trace."""
import numpy as np
import pandas as pd
import pytest

from l1b2.closeloop.evidence import with_onset
from l1b2.data import onset
from l1b2.data.coverage import data_check_lines, input_checks
from l1b2.data.measurements import load_measurements, split_by_load, write_measurements

DT = 1e-3          # s
Q = 5e-8           # m, one encoder count
SIGMA_V = 1e-3     # m/s, the speed column's noise
ACC = 20.0         # m/s^2, the slider's acceleration at the drive's start
V_MAX = 0.2        # m/s


def motion(n: int, k: int, direction: int = 1):
    """Positions [m] and noise-free speeds [m/s] of a run at rest at 0 for samples 0..k that then accelerates at
    ACC up to V_MAX from t_k on (quantised to one count)."""
    tau = np.clip(np.arange(n) * DT - k * DT, 0.0, None)
    t_up = V_MAX / ACC
    v = np.minimum(ACC * tau, V_MAX)
    s = np.where(tau <= t_up, 0.5 * ACC * tau ** 2, 0.5 * ACC * t_up ** 2 + V_MAX * (tau - t_up))
    return direction * np.round(s / Q) * Q, direction * v


def frame(rests, n=400, seed=0, stalled=(), voltage_at_rest=None):
    """A file of runs (run i at rest for samples 0..rests[i], then moving; the runs in ``stalled`` never move),
    speeds with SIGMA_V white noise; ``voltage_at_rest``: the voltage logged at the samples before the onset
    (default: the run's 200 V)."""
    rng = np.random.default_rng(seed)
    parts = []
    for i, k in enumerate(rests):
        s, v = motion(n, k, 1 if i % 2 == 0 else -1)
        if i in stalled:
            s, v = np.zeros(n), np.zeros(n)
        volt = np.full(n, 200.0)
        if voltage_at_rest is not None:
            volt[:k] = voltage_at_rest
        parts.append(pd.DataFrame({"time_s": 10.0 * i + np.arange(n) * DT, "run": i + 1, "position_m": s,
                                   "voltage_V": volt, "direction": 1 if i % 2 == 0 else -1,
                                   "load_kg": 0.05 if i >= 4 else 0.0,
                                   "speed_m_s": v + SIGMA_V * rng.standard_normal(n)}))
    return pd.concat(parts, ignore_index=True)


def test_a_run_at_rest_then_moving_has_its_onset_at_the_last_sample_at_rest():
    # at rest at 0 for samples 0..30 (the motion starts at t_30), then 0.5 ACC (t - t_30)^2: sample 31 is 10 um on
    s, v = motion(200, 30)
    assert onset.onset_index(s, v, 3 * Q, 5e-3) == 30
    # moving from the start: the first sample is the onset, nothing before it
    s, v = motion(200, 0)
    assert onset.onset_index(s, v, 3 * Q, 5e-3) == 0
    # the speed alone says moving at sample 5 (a position column frozen while the slider moves)
    v_frozen = np.where(np.arange(200) >= 5, 0.05, 0.0)
    assert onset.onset_index(np.zeros(200), v_frozen, 3 * Q, 5e-3) == 4
    # never out of the bands: the slider never moves
    assert onset.onset_index(np.zeros(50), np.full(50, 1e-3), 3 * Q, 5e-3) is None


def test_the_noise_of_a_column_is_read_through_a_smooth_motion():
    # a cubic motion plus white noise of 2 um: the fourth differences hold the noise only, sqrt(70) sigma
    rng = np.random.default_rng(3)
    t = np.arange(20000) * DT
    x = 0.01 + 0.2 * t - 3.0 * t ** 2 + 40.0 * t ** 3 + 2e-6 * rng.standard_normal(t.size)
    assert onset.noise_sd(x, t, np.ones(t.size)) == pytest.approx(2e-6, rel=0.03)
    # the motion alone, noise-free: nothing
    assert onset.noise_sd(0.2 * t - 3.0 * t ** 2, t, np.ones(t.size)) == pytest.approx(0.0, abs=1e-12)
    # the bands: z at alpha / (4 N) for N = 1000 samples is 4.5648 (the normal table), band_v = z sigma_v + q/dt
    df = pd.DataFrame({"time_s": t[:1000], "run": 1, "position_m": 0.0,
                       "speed_m_s": 1e-3 * rng.standard_normal(1000)})
    b = onset.rest_bands(df, Q)
    assert b["z"] == pytest.approx(4.5648, abs=1e-4)
    assert b["band_position_m"] == pytest.approx(Q)
    assert b["band_speed_m_s"] == pytest.approx(4.5648 * b["sigma_speed_m_s"] + Q / DT, rel=1e-4)


def test_the_rest_is_cut_a_stalled_run_kept_whole_and_noise_alone_cuts_nothing():
    df = frame([30, 0, 0, 0, 45, 0, 0, 0], stalled=(3,))
    out, rec = onset.from_onset(df, Q)
    # run 1 loses samples 0..29 (its onset at 30 is kept), run 5 loses 0..44; the stalled run 4 stays whole
    assert rec["runs"] == 2 and rec["of_runs"] == 8 and rec["samples"] == 30 + 45
    assert rec["still_runs"] == 1 and rec["inputs_differ"] == 0
    assert rec["median_delay_s"] == pytest.approx((0.030 + 0.045) / 2) and rec["max_delay_s"] == pytest.approx(0.045)
    assert rec["first_row"] == 1 and rec["per_run"][1][:2] == [5, 45] and rec["per_run"][1][3] == 4 * 400 + 1
    assert len(out) == len(df) - 75
    assert out.index[0] == 30 and (out["run"] == 4).sum() == 400   # the index is the file's, the stalled run kept
    # noise only: the same runs moving at once and the stalled one: nothing cut
    out0, rec0 = onset.from_onset(frame([0] * 8, stalled=(3,)), Q)
    assert rec0["runs"] == 0 and rec0["still_runs"] == 1 and len(out0) == 8 * 400
    # a rest of one step (the onset at sample 1) is the sample clock's own uncertainty of the start: not cut
    s, v = motion(400, 1)
    assert onset.onset_index(s, v, Q, 5e-3) == 1
    one = frame([1, 0, 0, 0, 0, 0, 0, 0])
    out2, rec2 = onset.from_onset(one, Q)
    assert onset.onset_index(one["position_m"][:400], one["speed_m_s"][:400], rec2["band_position_m"],
                             rec2["band_speed_m_s"]) == 1
    assert rec2["runs"] == 0 and len(out2) == len(one)
    # counted, not cut
    out1, rec1 = onset.from_onset(df, Q, cut=False)
    assert rec1["runs"] == 2 and rec1["cut"] is False and len(out1) == len(df)


def test_a_rest_under_other_drive_inputs_is_the_models_and_is_kept():
    # the voltage logged at 0 V before the onset: the model itself predicts the rest (no drive, static friction)
    df = frame([30, 0, 0, 0, 45, 0, 0, 0], voltage_at_rest=0.0)
    out, rec = onset.from_onset(df, Q)
    assert rec["runs"] == 0 and rec["inputs_differ"] == 2 and len(out) == len(df)


def test_the_loader_cuts_the_rest_counts_it_and_the_checks_name_it(tmp_path):
    df = frame([30, 0, 0, 0, 45, 0, 0, 0])
    path = write_measurements(df, tmp_path / "d.csv", {"slider_mass_kg": 0.12, "encoder_resolution_m": Q})
    m = load_measurements(path)
    rec = m.meta["rest_before_onset"]
    assert rec["runs"] == 2 and m.n_samples == len(df) - 75 and m.df.index[0] == 30
    whole = load_measurements(path, cut_rest_before_onset=False)
    assert whole.n_samples == len(df) and whole.meta["rest_before_onset"]["runs"] == 2
    # the paper's split: each part's record holds its own runs (run 5 is a TEST run, |load| 0.05 kg)
    tr, te = split_by_load(m, (0.05,))
    assert tr.meta["rest_before_onset"]["runs"] == 1 and tr.meta["rest_before_onset"]["samples"] == 30
    assert te.meta["rest_before_onset"]["runs"] == 1 and te.meta["rest_before_onset"]["max_delay_s"] == pytest.approx(0.045)
    checks = input_checks(tr, te)
    assert checks["rest_before_onset"]["train"]["of_runs"] == 4
    lines = data_check_lines(checks)
    b = rec["band_position_m"] * 1e9, rec["band_speed_m_s"] * 1e3
    assert lines == [
        f"TRAIN: 1 of 4 runs rest at their start position before they move (first at row 1; 30 samples, onset "
        f"after 30 ms median, 30 ms at most; position within {b[0]:.3g} nm, speed within {b[1]:.3g} mm/s) under "
        "the drive inputs of their motion: the recording began before the drive; the free run and the "
        "identification start at each run's onset",
        f"TEST: 1 of 4 runs rest at their start position before they move (first at row 1601; 45 samples, onset "
        f"after 45 ms median, 45 ms at most; position within {b[0]:.3g} nm, speed within {b[1]:.3g} mm/s) under "
        "the drive inputs of their motion: the recording began before the drive; the free run and the "
        "identification start at each run's onset"]


def test_the_close_loop_names_the_cut_first_in_its_trace():
    rec = onset.from_onset(frame([30, 0, 0, 0, 45, 0, 0, 0]), Q)[1]
    d = {"traced_to": ["voltage", "load"], "message": "missing effects: x"}
    out = with_onset(d, rec)
    assert out["traced_to"] == ["rest_before_onset", "voltage", "load"]
    assert out["message"] == ("missing effects: x; 2 of 8 TRAIN runs rest at their start before the drive (onset "
                              "after 37.5 ms median, 45 ms at most: a fact of the recording, cut on reading; every "
                              "run's free run starts at its onset)")
    assert out["rest_before_onset"] is rec
    # report.json keeps the record
    from l1b2.closeloop.report import Diagnosis
    full = {**out, "significant": True, "effect": None, "effect_shape": None, "effect_description": None,
            "effects": []}
    assert Diagnosis.from_dict(full).to_dict()["rest_before_onset"] == rec
    # nothing cut, or only counted: the diagnosis as it was
    assert with_onset(d, {**rec, "runs": 0}) is d and with_onset(d, {**rec, "cut": False}) is d
    assert with_onset(d, None) is d


def _fast_daq_file(seed=0):
    """Eight runs sampled at 5 kHz: slow starts (0.6 m/s^2, a low V0 against a heavy load) from the first sample in
    runs 1-7, and run 8 at rest for 20 ms first (a drive that starts late), 1 mm/s speed noise, 50 nm counts."""
    dt, n, acc = 2e-4, 1500, 0.6
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(8):
        k = 100 if i == 7 else 0
        tau = np.clip(np.arange(n) * dt - k * dt, 0.0, None)
        d = 1 if i % 2 == 0 else -1
        s = d * np.round(0.5 * acc * tau ** 2 / Q) * Q
        parts.append(pd.DataFrame({"time_s": 10.0 * i + np.arange(n) * dt, "run": i + 1, "position_m": s,
                                   "voltage_V": 200.0, "direction": d, "load_kg": 0.0,
                                   "speed_m_s": d * acc * tau + SIGMA_V * rng.standard_normal(n)}))
    return pd.concat(parts, ignore_index=True)


def test_at_a_fast_daq_a_slow_start_is_not_cut_and_a_rest_of_milliseconds_is():
    # property: the rest is cut by its duration, not its sample count: a slow start stays within the position band
    # for about 0.8 ms (0.5 a t^2 = 0.19 um at 0.6 m/s^2), 4 steps at 5 kHz, under MIN_REST_S; a 20 ms rest is cut
    df = _fast_daq_file()
    bands = onset.rest_bands(df, Q)
    ks = [onset.onset_index(g["position_m"].to_numpy(), g["speed_m_s"].to_numpy(), bands["band_position_m"],
                            bands["band_speed_m_s"]) for _, g in df.groupby("run")]
    assert all(onset.MIN_REST_STEPS <= k < onset.MIN_REST_S / 2e-4 for k in ks[:7]), ks   # rests of 2+ steps
    cut, rec = onset.from_onset(df, Q)
    assert rec["runs"] == 1 and rec["per_run"][0][0] == 8 and rec["per_run"][0][1] >= 100, rec["per_run"]
    assert len(df) - len(cut) == rec["samples"]
