"""The consequence test of logged columns (:mod:`l1b2.closeloop.responses`) on synthetic columns written out here:
a response of the speed, a per-run cause, a drifting cause, a supply that sags with the load and the drive (one with
a transient at the drive's switching on), a temperature the drive heats, a cause along the stroke; the low-pass,
the drive's course and the sign test against formulas."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom

from l1b2.cli import build_parser
from l1b2.closeloop.evidence import with_response_test
from l1b2.closeloop.report import response_test_lines
from l1b2.closeloop.settings import response_setting
from l1b2.closeloop.responses import (POSITION_DEGREE, RATE_TAUS_S, SHARE_MIN, TAUS_S, _nuisance_residual, active_runs,
                                      _per_run_share, _share, _sign_test_p,
                                      classed_responses, drive_course, history_columns,
                                      response_statistic, response_tests, speed_histories, speed_history, speed_rate,
                                      with_applied)
from l1b2.errors import L1B2Error

DT = 1e-3
TAU_MECH = 0.015    # the slider's rise from rest [s]
STROKE = 0.021      # half stroke [m]


def _session(seed=0, n_runs=40):
    """A session of runs from rest at alternating ends: ``|v| = V (1 - exp(-t/TAU_MECH))`` (V set per run by the
    voltage and the load), 1 mm/s speed noise, position the integral of the true speed, 1 s pauses."""
    rng = np.random.default_rng(seed)
    rows, t0 = [], 0.0
    for r in range(n_runs):
        d = 1 if r % 2 == 0 else -1
        V0 = rng.choice([150.0, 200.0, 250.0])
        load = rng.choice([0.0, 0.05, 0.1])
        V = 0.2 * V0 / 200.0 * (1.0 - 1.5 * load) * rng.normal(1.0, 0.02)
        n = int(2 * STROKE / V / DT) + int(TAU_MECH / DT)
        tr = np.arange(n) * DT
        v = V * (1.0 - np.exp(-(tr + DT) / TAU_MECH))
        s = -d * STROKE + d * np.cumsum(v) * DT
        keep = np.abs(s) <= STROKE
        rows.append(pd.DataFrame({"time_s": t0 + tr[keep], "run": r, "position_m": s[keep], "voltage_V": V0,
                                  "direction": d, "load_kg": load,
                                  "speed_m_s": d * v[keep] + rng.normal(0, 1e-3, keep.sum()),
                                  "true_speed": v[keep], "t_run": tr[keep]}))
        t0 += tr[keep][-1] + 1.0
    return pd.concat(rows, ignore_index=True), rng


def _lowpass_from_rest(x, t_run, tau):
    """A first-order low-pass of ``x`` from 0 at each run's start, written out sample by sample."""
    y, out = 0.0, np.empty_like(x)
    for i in range(len(x)):
        if t_run[i] == 0.0:
            y = 0.0
        y += (1.0 - math.exp(-DT / tau)) * (x[i] - y)
        out[i] = y
    return out


def _with_columns():
    """The session with its logged columns: one response and six causes."""
    df, rng = _session()
    n = len(df)
    v2 = _lowpass_from_rest(df["true_speed"].to_numpy() ** 2 / 0.04, df["t_run"].to_numpy(), 0.125)
    run_force = rng.uniform(15, 90, df["run"].max() + 1)
    cols = {
        # a sound level meter: power ~ v^2 through the meter's 125 ms time weighting, over a background
        "mic_dB": 10 * np.log10(10 ** 4.0 + 10 ** 5.8 * v2) + rng.normal(0, 0.1, n),
        # a clamp force set per run, read with noise
        "clamp_N": run_force[df["run"]] + rng.normal(0, 0.2, n),
        # a room temperature drifting over the session
        "room_C": 22 + 0.5 * np.sin(2 * np.pi * df["time_s"] / 600.0) + rng.normal(0, 0.01, n),
        # a supply that sags with the load's current and the drive switched on at the run's start (2 ms)
        "supply_V": (24 - 0.8 * df["load_kg"] - 0.02 * df["voltage_V"] / 200
                     - 0.1 * (1 - np.exp(-(df["t_run"] + DT) / 2e-3)) + rng.normal(0, 0.01, n)),
        # a supply that sags by a share of the drive amplitude within 5 ms of the drive switching on, read with
        # 1 mV of noise: a transient at the run's start far above its noise, ahead of the slider's 15 ms rise
        "bus_V": 48 - 0.1 * df["voltage_V"] / 200 * (1 - np.exp(-(df["t_run"] + DT) / 5e-3)) + rng.normal(0, 1e-3, n),
        # a heat sink the drive heats while it runs (time constant 3 s, longer than a run)
        "sink_C": 30 + 0.8 * (1 - np.exp(-df["t_run"] / 3.0)) + 0.01 * df["time_s"] + rng.normal(0, 0.02, n),
        # a preload along the stroke, a cause that is a function of the position
        "preload_N": 6 + 0.8 * df["position_m"] / STROKE + 0.3 * (df["position_m"] / STROKE) ** 2
                     + rng.normal(0, 0.01, n),
    }
    return df.drop(columns=["true_speed", "t_run"]).assign(**cols)


@pytest.fixture(scope="module")
def session():
    return _with_columns()


def test_a_response_of_the_speed_is_classed_a_response(session):
    (rec,) = [r for r in response_tests(session) if r["channel"] == "mic_dB"]
    assert rec["response"] and rec["share"] >= SHARE_MIN
    assert rec["runs_above"] > 30 and rec["p_value"] < 1e-4


@pytest.mark.parametrize("name", ["clamp_N", "room_C", "supply_V", "sink_C", "preload_N"])
def test_causes_stay_candidates(session, name):
    (rec,) = [r for r in response_tests(session) if r["channel"] == name]
    assert not rec["response"]
    assert rec["share"] < SHARE_MIN / 2


def test_a_transient_of_the_drive_ahead_of_the_speed_stays_a_candidate(session):
    (rec,) = [r for r in response_tests(session) if r["channel"] == "bus_V"]
    # the speed's history explains most of it (its course is tied to the run's start as the speed's is) ...
    assert rec["share"] >= SHARE_MIN and rec["p_value"] < 0.01
    # ... but the drive's own course from the run's start explains more: the column moves ahead of the speed
    assert rec["drive_share"] > rec["share"] and rec["drive_tau_s"] is not None and not rec["response"]
    (mic,) = [r for r in response_tests(session) if r["channel"] == "mic_dB"]
    assert mic["share"] > mic["drive_share"] > 0


def test_every_column_is_tested_against_the_frames_histories_computed_once(session):
    # reference: the histories depend on the motion only: the frame's shared set (every history at every time
    # constant, the rate once, in the test's order) gives each column the record of its own computation
    args = (session["speed_m_s"], session["time_s"], session["position_m"], session["run"])
    hist = speed_histories(*args)
    assert [(h, tau) for h, tau, _ in hist] == ([("magnitude", tau) for tau in TAUS_S]
                                                 + [("signed", tau) for tau in TAUS_S] + [("rate", None)])
    own = {name: response_statistic(session[name].to_numpy(float), *args) for name in ("mic_dB", "room_C")}
    for rec in response_tests(session):
        assert rec["runs_constant"] == 0                             # every column varies in every run
        if rec["channel"] in own:
            assert {k: v for k, v in rec.items() if k not in ("channel", "runs_constant")} == own[rec["channel"]]
    assert own["mic_dB"]["response"] and not own["room_C"]["response"]


def test_drive_course_is_the_first_order_rise_from_each_runs_first_sample():
    t = np.r_[np.arange(5), 10 + np.arange(3)] * DT
    run = np.r_[np.zeros(5), np.ones(3)]
    expected = np.r_[1 - np.exp(-(np.arange(5) + 1) * DT / 0.01), 1 - np.exp(-(np.arange(3) + 1) * DT / 0.01)]
    assert np.allclose(drive_course(t, run, 0.01), expected)


def test_the_per_run_amplitude_fit_equals_the_dense_least_squares():
    rng = np.random.default_rng(3)
    run = np.repeat(np.arange(6), [30, 41, 25, 50, 33, 27])
    t = np.arange(len(run)) * DT
    P = rng.normal(size=(len(run), 3))
    x = rng.normal(size=len(run))
    c = rng.normal(size=len(run)) + 2 * x + P @ [1.0, -0.5, 0.2]
    zero = np.zeros((len(run), 0))
    cr = _nuisance_residual(c[:, None], run, t, P)[:, 0]
    b = np.r_[0, np.flatnonzero(np.diff(run)) + 1, len(run)]
    blocks = [slice(i0, i1) for i0, i1 in zip(b[:-1], b[1:])]
    dense = np.zeros((len(run), 6))
    for j in range(6):
        dense[run == j, j] = x[run == j]
    X = _nuisance_residual(dense, run, t, P)
    e = cr - X @ np.linalg.lstsq(X, cr, rcond=None)[0]
    expected = 1 - (e @ e) / (cr @ cr)
    got = _per_run_share(_nuisance_residual(x[:, None], run, t, zero)[:, 0], cr,
                         _nuisance_residual(P, run, t, zero), blocks, float(cr @ cr))
    assert got == pytest.approx(expected, rel=1e-9)


def test_a_column_exactly_a_polynomial_of_the_speed_is_explained_whole_and_noise_not_at_all(session):
    v = np.abs(session["speed_m_s"].to_numpy()) / np.abs(session["speed_m_s"]).max()
    args = (session["speed_m_s"], session["time_s"], session["position_m"], session["run"])
    exact = response_statistic(2 * v - 3 * v ** 3, *args)
    assert exact["share"] == pytest.approx(1.0, abs=1e-9) and exact["tau_s"] == 0.0 and exact["response"]
    noise = response_statistic(np.random.default_rng(5).normal(size=len(v)), *args)
    # white noise: of the order of the cubic's 3 parameters over the samples (3 / 9674), far below the rule
    assert noise["share"] < 0.01 and not noise["response"] and noise["runs_above"] == 0


def test_a_signed_echo_of_the_speed_is_a_response_through_the_signed_history(session):
    # reference: a controller's own velocity estimate from the same decoder, logged beside the speed (gain 1.02,
    # offset 10 mm/s, 0.1 mm/s of its own noise): odd in the speed, it changes sign with the direction, which no
    # function of the magnitude shared by the runs follows; an exact odd polynomial of the signed speed is
    # explained whole by the signed history
    v = session["speed_m_s"].to_numpy()
    echo = 1.02 * v + 0.01 + np.random.default_rng(7).normal(0, 1e-4, len(v))
    (rec,) = [r for r in response_tests(session.assign(echo_m_s=echo)) if r["channel"] == "echo_m_s"]
    assert rec["response"] and rec["signed"] and rec["share"] >= 0.95 and rec["p_value"] < 1e-4
    magnitude = response_statistic(np.abs(echo), session["speed_m_s"], session["time_s"], session["position_m"],
                                   session["run"])
    assert magnitude["response"] and magnitude["signed"] is False    # its magnitude: the magnitude's history
    vs = v / np.abs(v).max()
    exact = response_statistic(2 * vs - 3 * vs ** 3, session["speed_m_s"], session["time_s"], session["position_m"],
                               session["run"])
    assert exact["share"] == pytest.approx(1.0, abs=1e-9) and exact["signed"] and exact["tau_s"] == 0.0


def test_a_sensor_silent_in_some_runs_is_tested_on_the_runs_where_it_reads(session):
    # reference: a tachometer gated by the load (it reads only in the runs with a load of 0.1 kg, 0 in the others)
    # echoes the speed through its 125 ms filter where it reads. Judged on those runs alone its record is the one
    # response_statistic gives on that sub-frame; a law shared with the silent runs would have to give a constant
    # from a moving speed there
    gated = session["load_kg"].to_numpy() == 0.1
    df = session.assign(tach=np.where(gated, session["mic_dB"], 0.0))
    (rec,) = [r for r in response_tests(df) if r["channel"] == "tach"]
    runs = df.loc[gated, "run"].unique()
    sub = df[df["run"].isin(runs)]
    own = response_statistic(sub["tach"].to_numpy(float), sub["speed_m_s"], sub["time_s"], sub["position_m"],
                             sub["run"])
    assert {k: v for k, v in rec.items() if k not in ("channel", "runs_constant")} == own
    assert rec["n_runs"] == len(runs) and rec["runs_constant"] == df["run"].nunique() - len(runs) > 0
    assert rec["response"]
    whole = response_statistic(df["tach"].to_numpy(float), df["speed_m_s"], df["time_s"], df["position_m"], df["run"])
    assert whole["share"] < rec["share"] and not whole["response"]   # the silent runs pull the law off the echo
    assert active_runs(df, "tach").tolist() == list(runs)
    (line,) = [x for x in response_test_lines(with_applied([rec], None, ("tach",))) if "`tach`" in x]
    assert f"above half in {rec['runs_above']} of {len(runs)} runs" in line
    assert f"constant in {rec['runs_constant']} other runs (not tested there)" in line and "a response" in line
    # a cause that is held in some runs stays a cause on the runs where it moves
    held = session.assign(room=np.where(gated, session["room_C"], 22.0))
    (c,) = [r for r in response_tests(held) if r["channel"] == "room"]
    assert not c["response"] and c["runs_constant"] > 0


def test_a_column_constant_within_runs_is_not_tested(session):
    df = session.assign(setting=session["run"] * 1.0)
    assert "setting" not in [r["channel"] for r in response_tests(df)]
    assert "mic_dB" not in [r["channel"] for r in response_tests(df, named=("mic_dB",))]
    assert "frequency_Hz" not in [r["channel"] for r in response_tests(df.assign(frequency_Hz=df["mic_dB"]))]


def test_speed_history_is_the_first_order_step_response():
    t = np.arange(50) * DT
    y = speed_history(np.full(50, -0.2), t, np.zeros(50), 0.01)
    assert np.allclose(y, 0.2 * (1 - np.exp(-(np.arange(50) + 1) * DT / 0.01)))
    y2 = speed_history(np.full(100, 0.2), np.r_[t, t + 5.0], np.r_[np.zeros(50), np.ones(50)], 0.01)
    assert np.allclose(y2[50:], y2[:50])                      # from rest again at the next run
    assert np.array_equal(speed_history([-0.1, 0.2], [0, DT], [0, 0], 0.0), [0.1, 0.2])


def test_speed_rate_is_the_derivative_of_the_first_order_step_response():
    # a step of the signed speed from rest: the low-pass is V (1 - exp(-(k+1) dt/tau)), its rate V exp(-(k+1) dt/tau)
    # / tau, the same sign as the speed, from rest again at each run's start
    t = np.arange(40) * DT
    k = np.arange(40)
    for V, tau in ((-0.2, 0.003), (0.15, 0.01)):
        assert np.allclose(speed_rate(np.full(40, V), t, np.zeros(40), tau), V * np.exp(-(k + 1) * DT / tau) / tau)
    two = speed_rate(np.full(80, 0.1), np.r_[t, t + 3.0], np.r_[np.zeros(40), np.ones(40)], 0.003)
    assert np.allclose(two[40:], two[:40])
    with pytest.raises(ValueError, match="not positive"):
        speed_rate([0.1, 0.1], [0, DT], [0, 0], 0.0)


def test_the_rate_history_is_the_bank_of_scaled_rates():
    rng = np.random.default_rng(11)
    run = np.repeat([0, 1], 60)
    t = np.arange(120) * DT
    v = np.r_[np.linspace(0, 0.2, 60), -np.linspace(0, 0.1, 60)] + rng.normal(0, 1e-3, 120)
    X = history_columns(v, t, run, "rate")
    assert X.shape == (120, len(RATE_TAUS_S))
    for j, tau in enumerate(RATE_TAUS_S):
        r = speed_rate(v, t, run, tau)
        assert np.allclose(X[:, j], r / np.abs(r).max())
    u = np.abs(v) / np.abs(v).max()
    assert np.allclose(history_columns(v, t, run, "magnitude", 0.0), np.column_stack([u, u ** 2, u ** 3]))
    with pytest.raises(ValueError, match="not one of"):
        history_columns(v, t, run, "jerk", 0.0)


def test_an_accelerometer_on_the_slider_is_a_response_through_the_rate(session):
    # reference: a MEMS accelerometer on the slider (the acceleration of the true speed through its 60 Hz
    # anti-alias filter, a bias, 0.005 g of noise, in g), written out sample by sample: the rate's bank takes it
    df, rng = _session(seed=2)
    v = df["true_speed"].to_numpy() * df["direction"].to_numpy()
    acc = np.empty_like(v)
    for r in np.unique(df["run"]):
        i = np.flatnonzero(df["run"].to_numpy() == r)
        acc[i] = np.r_[v[i[0]] / DT, np.diff(v[i]) / DT]          # from rest at the run's start
    tau = 1.0 / (2 * np.pi * 60.0)
    filtered = _lowpass_from_rest(acc, df["t_run"].to_numpy(), tau)
    accel_g = filtered / 9.81 + 0.01 + rng.normal(0, 0.005, len(v))
    args = (df["speed_m_s"], df["time_s"], df["position_m"], df["run"])
    rec = response_statistic(accel_g, *args)
    assert rec["response"] and rec["history"] == "rate" and rec["tau_s"] is None and rec["share"] >= 0.8
    assert rec["share"] > rec["drive_share"]
    # in this session the slider's rise is a first-order lag, so within a run a = (V_r - v) / tau_mech: the signed
    # speed's cubic explains much of it too, but less than the rate's bank
    t, run, s_m = (df[c].to_numpy() for c in ("time_s", "run", "position_m"))
    P = np.polynomial.legendre.legvander(2 * (s_m - s_m.min()) / np.ptp(s_m) - 1, POSITION_DEGREE)[:, 1:]
    cr = _nuisance_residual(accel_g[:, None], run, t, P)[:, 0]
    cubic = max(_share(_nuisance_residual(history_columns(df["speed_m_s"].to_numpy(), t, run, h, tau), run, t, P),
                       cr, float(cr @ cr))[0] for h in ("magnitude", "signed") for tau in TAUS_S)
    assert cubic < rec["share"] - 0.1
    report = response_test_lines(with_applied([{"channel": "accel_g", **rec}], None, ("accel_g",)))
    assert any("`accel_g`" in line and "rate" in line and "a response" in line for line in report)


def test_sign_test_is_the_binomial_tail():
    for k, n in ((0, 10), (37, 56), (56, 56), (20, 40)):
        assert _sign_test_p(k, n) == pytest.approx(binom.sf(k - 1, n, 0.5), rel=1e-12)


def test_an_explicit_setting_wins_over_the_test():
    tests = [{"channel": "mic", "response": True, "share": 0.9, "runs_above": 50, "n_runs": 56, "p_value": 1e-9},
             {"channel": "force", "response": False, "share": 0.0, "runs_above": 0, "n_runs": 56, "p_value": 1.0}]
    assert classed_responses(None, ("tip",), tests) == ("tip", "mic")
    assert classed_responses((), ("tip",), tests) == ()
    assert classed_responses(("force",), ("tip",), tests) == ("force",)
    applied = with_applied(tests, None, ("tip", "mic"))
    assert [a["applied"] for a in applied] == [True, False] and applied[0]["decided_by"] == "test"
    rows = [{"channel": "mic", "kind": "response", "note": ""}, {"channel": "force", "kind": "logged", "note": ""},
            {"channel": "time_s", "kind": "protocol", "note": ""}]
    out = with_response_test(rows, applied)
    assert "classed a response of the motion" in out[0]["note"] and "90%" in out[0]["note"]
    assert out[1]["note"] == "" and out[1]["response_test"]["share"] == 0.0 and out[2]["response_test"] is None
    overridden = with_response_test(rows, with_applied(tests, (), ()))
    assert overridden[0]["note"] == "" and overridden[0]["response_test"]["decided_by"] == "setting"


def test_the_command_line_can_set_no_response_columns():
    base = ["close-loop", "--train", "a.csv", "--out", "o"]

    def setting(extra):
        args = build_parser().parse_args(base + extra)
        return response_setting(args.response_columns, args.no_response_columns)
    assert setting([]) == {}
    assert setting(["--no-response-columns"]) == {"response_columns": ()}
    assert setting(["--response-column", "x"]) == {"response_columns": ("x",)}
    with pytest.raises(L1B2Error):
        setting(["--no-response-columns", "--response-column", "x"])


def test_report_lines_name_each_tested_column_and_who_decided():
    assert response_test_lines([]) == []
    rec = {"channel": "mic", "share": 0.962, "tau_s": 0.03, "runs_above": 56, "n_runs": 56, "p_value": 1.4e-17,
           "response": True, "applied": True, "decided_by": "test"}
    (line,) = response_test_lines([rec])[3:]
    assert line == ("- `mic`: share 96% (sensor lag 0.03 s), above half in 56 of 56 runs (p 1.4e-17): a response; "
                    "not a candidate")
    (line,) = response_test_lines([{**rec, "drive_share": 0.88}])[3:]
    assert "(p 1.4e-17), the drive's course from the run's start 88%: a response" in line
    (line,) = response_test_lines([{**rec, "applied": False, "decided_by": "setting"}])[3:]
    assert line.endswith("a response (the response_columns setting decides); a candidate")
