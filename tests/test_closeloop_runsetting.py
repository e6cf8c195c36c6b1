"""The run's setting a response column carries (:mod:`l1b2.closeloop.runsetting`), on a voice coil's current written
out here: ``i = u_r / R - K v / R`` (the setting ``u_r`` per run, the back-EMF of the signed speed), with a per-run
trend and a term along the stroke; the settings against the injected ``u_r / R`` (up to a constant shared by the runs:
the stroke term's mean), TRAIN's law on another frame, the derivation's record and its name."""

import numpy as np
import pandas as pd
import pytest
from scipy.signal import lfilter
from scipy.stats import chi2

from l1b2.closeloop.candidates import channels_of, is_along_stroke
from l1b2.closeloop.derived import is_derivable_name, with_protocol_channels
from l1b2.closeloop.events import session as session_of
from l1b2.closeloop.report import run_setting_lines
from l1b2.closeloop.responses import response_tests, speed_rate
from l1b2.closeloop.runsetting import (PLAN_SHARE_MAX, fit_motion_law, plan_share, scatter_p,
                                       with_run_settings)
from l1b2.units import SETTING_SUFFIX, column_unit

DT = 1e-3
STROKE = 0.02   # half stroke [m]
K_N_A, R_OHM = 0.5, 4.0


def _runs(seed, n_runs, top_speed_m_s=0.2, noise_A=0.0):
    """Runs from rest at alternating ends (a 16 ms rise, a ripple along the stroke), each with its coil voltage ``u``
    [V]; the logged current ``vcm_current_A = (u - K v) / R`` plus a trend in the run's time, a term along the
    stroke and ``noise_A``."""
    rng = np.random.default_rng(seed)
    frames, t0 = [], 0.0
    u = rng.uniform(-0.45, 0.45, n_runs)
    for r in range(n_runs):
        d = 1 if r % 2 == 0 else -1
        top = top_speed_m_s * rng.uniform(0.5, 1.0)
        n = int(2 * STROKE / top / DT) + 15
        tr = np.arange(n) * DT
        x = (tr + DT) / 0.008
        v = top * (1.0 - (1.0 + x) * np.exp(-x))   # a second-order rise (a first-order one's way gone is its speed)
        s = -d * STROKE + d * np.cumsum(v) * DT
        v = v * (1.0 + 0.03 * np.sin(2 * np.pi * s / 0.013))    # and a ripple along the stroke
        keep = np.abs(s) <= STROKE
        tr, v, s = tr[keep], d * v[keep], s[keep]
        current = ((u[r] - K_N_A * v) / R_OHM + rng.normal(0.0, 0.01) * (tr - tr.mean())
                   + 0.003 * (s / STROKE) ** 2 + rng.normal(0.0, noise_A, len(tr)))
        frames.append(pd.DataFrame({"time_s": t0 + tr, "run": r, "position_m": s, "voltage_V": 200.0,
                                    "direction": d, "load_kg": 0.05, "speed_m_s": v, "vcm_current_A": current}))
        t0 += tr[-1] + 0.5
    return pd.concat(frames, ignore_index=True), u / R_OHM


def _run_means(df, column):
    return df.groupby("run", sort=False)[column].mean().to_numpy()


def _offset(got, level):
    """The settings less the injected levels, less their mean: zero when they agree up to a shared constant."""
    d = np.asarray(got) - level
    return d - d.mean()


def test_the_settings_are_the_injected_run_levels_without_noise():
    df, level = _runs(1, 24)
    law = fit_motion_law(df, "vcm_current_A", "signed", 0.0)
    got = law.run_settings(df)
    np.testing.assert_allclose(_offset(_run_means(df.assign(g=got), "g"), level), 0.0, atol=1e-9)
    # constant within each run
    assert df.assign(g=got).groupby("run")["g"].nunique().max() == 1
    # the back-EMF's coefficient on the signed speed over its largest magnitude: -K / R times that magnitude
    assert law.beta[0] == pytest.approx(-K_N_A / R_OHM * law.scale[0], rel=1e-9)
    np.testing.assert_allclose(law.beta[1:], 0.0, atol=1e-9)


def test_the_setting_is_the_runs_mean_of_what_the_law_leaves():
    # a course within each run that no law of the speed or the position holds (a skewed one, exp of the run's
    # clock): the setting is the run's mean of the column less the law's echo, written out here
    df, _ = _runs(10, 12)
    t_run = df["time_s"] - df.groupby("run")["time_s"].transform("min")
    df["vcm_current_A"] += 1e-3 * np.exp(t_run / 0.02)
    law = fit_motion_law(df, "vcm_current_A", "signed", 0.0)
    want = (df["vcm_current_A"] - law.echo(df)).groupby(df["run"]).transform("mean").to_numpy()
    np.testing.assert_allclose(law.run_settings(df), want, rtol=1e-12, atol=1e-15)


def test_with_noise_the_settings_stay_within_a_fiftieth_of_their_range():
    # 2 mA of noise: each run's mean carries ~0.1 mA, the law's coefficients an error shared by the runs of one
    # direction (the position's polynomials and the speed are nearly collinear within runs)
    df, level = _runs(2, 30, noise_A=0.002)
    got = _run_means(df.assign(g=fit_motion_law(df, "vcm_current_A", "signed", 0.0).run_settings(df)), "g")
    assert np.max(np.abs(_offset(got, level))) < 0.002 < np.ptp(level) / 50


def test_another_frame_is_read_with_trains_law_scale_and_span():
    train, _ = _runs(3, 24, top_speed_m_s=0.25)
    test, level = _runs(4, 10, top_speed_m_s=0.12)   # slower runs: another largest speed than TRAIN's
    law = fit_motion_law(train, "vcm_current_A", "signed", 0.0)
    np.testing.assert_allclose(_offset(_run_means(test.assign(g=law.run_settings(test)), "g"), level), 0.0, atol=1e-9)
    # the same law refitted on TEST's own scale has other coefficients: the scale is carried, not recomputed
    assert fit_motion_law(test, "vcm_current_A", "signed", 0.0).scale != law.scale


def test_the_run_level_is_not_explained_by_the_law_when_the_echo_is_dropped():
    # the law of a column with no echo: the settings are the runs' means less the stroke's term
    df, level = _runs(5, 20)
    df["vcm_current_A"] = df["vcm_current_A"] + K_N_A * df["speed_m_s"] / R_OHM
    law = fit_motion_law(df, "vcm_current_A", "signed", 0.0)
    np.testing.assert_allclose(law.beta, 0.0, atol=1e-9)
    np.testing.assert_allclose(_offset(_run_means(df.assign(g=law.run_settings(df)), "g"), level), 0.0, atol=1e-9)


@pytest.fixture(scope="module")
def frames():
    train, _ = _runs(6, 30, noise_A=0.0002)
    test, level = _runs(7, 8, noise_A=0.0002)
    return train, test, level


def test_the_classed_current_gets_its_setting_in_both_frames(frames):
    train, test, level = frames
    tests = response_tests(train)
    (rec,) = [r for r in tests if r["channel"] == "vcm_current_A"]
    assert rec["response"]
    tr, te, record = with_run_settings(train, test, tests, ("vcm_current_A",))
    name = "vcm_current_A" + SETTING_SUFFIX
    assert record == [{**record[0], "channel": name, "from": "vcm_current_A", "source": "response", "derived": True}]
    assert record[0]["scatter_p"] < 1e-12
    # the settings' spread is the levels' (uniform over +-0.1125 A), the echo's that of the runs' mean speed
    assert record[0]["run_spread"] == pytest.approx(np.std(_run_means(tr, name)), rel=1e-12)
    assert 0.03 < record[0]["run_spread"] < 0.1
    assert np.max(np.abs(_offset(_run_means(te, name), level))) < 0.0005   # TRAIN's law on TEST: 0.2 mA noise
    assert column_unit(name) == "A"


def test_no_setting_for_a_column_not_applied_or_constant_in_some_runs_or_missing_in_test(frames):
    train, test, _ = frames
    tests = response_tests(train)
    # the user's setting names no response: the classed column is a candidate as logged, no setting derived
    assert with_run_settings(train, test, tests, ())[2] == []
    # a column the user names a response that the test does not class one: no law fitted, none derived
    unclassed = [{**r, "response": False} for r in tests]
    assert with_run_settings(train, test, unclassed, ("vcm_current_A",))[2] == []
    rec = [{**r, "runs_constant": 3} if r["channel"] == "vcm_current_A" else r for r in tests]
    tr, te, record = with_run_settings(train, test, rec, ("vcm_current_A",))
    assert not record[0]["derived"] and "constant within 3" in record[0]["note"]
    assert tr is train and te is test
    tr, te, record = with_run_settings(train, test.drop(columns="vcm_current_A"), tests, ("vcm_current_A",))
    assert not record[0]["derived"] and "TEST does not log it" in record[0]["note"]


def test_the_protocol_channels_carry_the_setting_as_a_derived_column(frames):
    train, test, _ = frames
    tests = response_tests(train)
    tr, te, rec = with_protocol_channels(train, test, ("vcm_current_A",), session_of(train, test), tests)
    name = "vcm_current_A" + SETTING_SUFFIX
    assert name in tr.attrs["l1b2_derived_columns"] and name in te.columns
    assert [r["channel"] for r in rec["run_settings"]] == [name]
    # a logged column that a derivation could produce is set aside: its name is derivable
    assert is_derivable_name(name, train.columns) and not is_derivable_name("fan_setting", train.columns)


def test_a_setting_that_only_follows_the_plan_is_a_relabel_not_a_candidate(frames):
    # a run setting that is, run by run, a function of the drive amplitude (what a law's misfit of the speed's
    # echo would leave) is read as the plan's input, as a logged setting would be; a derived history is not tested
    train, _, _ = frames
    df = train.assign(voltage_V=np.where(train["run"] % 3 == 0, 180.0, np.where(train["run"] % 3 == 1, 220.0, 260.0)))
    df = df.assign(x_setting=df["voltage_V"] ** 2 / 1e4, x_lag3r=df["voltage_V"] ** 2 / 1e4)
    df.attrs["l1b2_derived_columns"] = ("x_setting", "x_lag3r")
    kinds = {c["name"]: c["kind"] for c in channels_of(df)}
    assert kinds["x_setting"] == "relabel" and kinds["x_lag3r"] == "logged"


def _with_plan(df):
    """``df`` with the drive amplitude and the load set per run from three and five levels."""
    r = df["run"].to_numpy()
    return df.assign(voltage_V=200.0 + 40.0 * (r % 3), load_kg=-0.1 + 0.05 * ((r // 3) % 5))


def test_the_plans_share_of_run_levels_against_a_fit_written_out():
    df = _with_plan(_runs(8, 30)[0])
    runs = df.groupby("run", sort=False).first()
    V, L, d = (runs[c].to_numpy(float) for c in ("voltage_V", "load_kg", "direction"))
    zv, zl = (V - V.mean()) / V.std(), (L - L.mean()) / L.std()
    fixed = 3.0 + zv ** 2 - 2.0 * d * zl + 0.5 * zl   # a function of the plan in the fit's columns
    per_sample = pd.Series(fixed, index=runs.index).loc[df["run"]].to_numpy()
    assert plan_share(df, per_sample) == pytest.approx(1.0, abs=1e-12)
    own = np.random.default_rng(3).normal(size=len(runs))   # the runs' own: R^2 of 8 columns on 30 runs
    X = np.column_stack([np.ones(30), d, zv, zv ** 2, zl, zl ** 2, d * zl])
    e = own - X @ np.linalg.lstsq(X, own, rcond=None)[0]
    expect = 1.0 - e @ e / np.sum((own - own.mean()) ** 2)
    assert plan_share(df, pd.Series(own, index=runs.index).loc[df["run"]].to_numpy()) == pytest.approx(expect)
    assert plan_share(df, np.ones(len(df))) == 1.0


def test_a_response_whose_levels_the_plan_fixes_gets_no_setting():
    # a current whose run level follows the drive amplitude (a supply's share), not a setting of its own
    train = _with_plan(_runs(9, 30, noise_A=0.0002)[0])
    level = train.groupby("run")["vcm_current_A"].transform("mean")
    own = np.random.default_rng(9).uniform(-0.04, 0.04, 30)[train["run"].to_numpy()]   # and a little of its own
    train["vcm_current_A"] += 1e-3 * (train["voltage_V"] - 240.0) + own - level + level.mean()
    tests = response_tests(train)
    assert [r["response"] for r in tests if r["channel"] == "vcm_current_A"] == [True]
    tr, _, record = with_run_settings(train, None, tests, ("vcm_current_A",))
    assert tr is train and not record[0]["derived"] and PLAN_SHARE_MAX < record[0]["plan_share"] < 0.8
    assert "the plan's inputs explain" in record[0]["note"]


def test_report_md_names_each_setting_derived_or_not_and_why(frames):
    train, test, _ = frames
    tests = response_tests(train)
    (rec,) = with_run_settings(train, test, tests, ("vcm_current_A",))[2]
    refused = {"channel": "mic_setting", "from": "mic", "source": "response", "derived": False, "run_spread": 2.0,
               "echo_spread": 1.0, "plan_share": 0.99, "scatter_p": 0.0,
               "note": "the plan's inputs explain 99% of its run levels: they fix them"}
    lines = run_setting_lines([rec, refused, {"channel": "x_setting", "from": "x", "source": "along_stroke",
                                              "derived": False, "note": "TEST does not log it"}])
    assert lines[0] == "" and "less than half" in lines[1] and "beyond their noise" in lines[1]
    assert lines[3].startswith("- `vcm_current_A` (a response) -> `vcm_current_A_setting`: spread over TRAIN's runs ")
    assert lines[3].endswith(f"the plan explains {rec['plan_share']:.0%}, scatter p {rec['scatter_p']:.2g}; "
                             "derived, a candidate")
    assert lines[4].endswith("scatter p 0; the plan's inputs explain 99% of its run levels: they fix them")
    assert lines[5] == "- `x` (read along the stroke) -> `x_setting`: TEST does not log it"
    assert run_setting_lines([]) == []


def _preload_runs(seed, n_runs=30, noise_N=0.005, set_N=None, phi=0.0):
    """Runs (as :func:`_runs`) with a load cell under a preload spring: the preload set per run (5-7.7 N, or
    ``set_N``) plus the spring's deflection along the stroke, ``0.8 (s / STROKE)^2`` N, and ``noise_N`` of noise
    (``phi``: first-order autoregressive, ``e_k = phi e_(k-1) + w_k``, across the samples)."""
    df, _ = _runs(seed, n_runs)
    rng = np.random.default_rng(seed + 100)
    preload = rng.uniform(5.0, 7.7, n_runs) if set_N is None else np.full(n_runs, set_N)
    z = df["position_m"].to_numpy() / STROKE
    noise = lfilter([1.0], [1.0, -phi], rng.normal(0.0, noise_N, len(df)))
    cell = preload[df["run"].to_numpy()] + 0.8 * z ** 2 + noise
    return df.drop(columns="vcm_current_A").assign(preload_cell_N=cell), preload


def test_a_column_read_along_the_stroke_gets_the_runs_preload_as_its_setting():
    train, preload = _preload_runs(11)
    test, preload_te = _preload_runs(12, n_runs=8)
    assert is_along_stroke(train, "preload_cell_N")
    tr, te, (rec,) = with_run_settings(train, test, [], (), ["preload_cell_N"])
    assert rec["source"] == "along_stroke" and rec["derived"] and rec["history"] is None and rec["scatter_p"] < 1e-12
    np.testing.assert_allclose(_offset(_run_means(tr, "preload_cell_N_setting"), preload), 0.0, atol=2e-3)
    np.testing.assert_allclose(_offset(_run_means(te, "preload_cell_N_setting"), preload_te), 0.0, atol=2e-3)


def test_a_column_of_the_position_alone_scatters_by_its_noise_and_gets_no_setting():
    # one preload for every run: the run levels differ by the noise of their means only
    train, _ = _preload_runs(13, set_N=6.0, noise_N=0.02)
    law = fit_motion_law(train, "preload_cell_N")
    assert 1e-3 < scatter_p(train, law)
    tr, _, (rec,) = with_run_settings(train, None, [], (), ["preload_cell_N"])
    assert tr is train and not rec["derived"] and "scatter by its noise only" in rec["note"]


def test_the_scatter_test_against_a_chi_square_written_out():
    # one preload for every run, autoregressive noise: Q = sum w (a - abar)^2 with w = n / (s^2 (1+rho)/(1-rho))
    train, _ = _preload_runs(14, n_runs=12, noise_N=0.05, set_N=6.0, phi=0.6)
    law = fit_motion_law(train, "preload_cell_N")
    rest = train["preload_cell_N"].to_numpy() - law.echo(train)
    g = pd.Series(rest).groupby(train["run"].to_numpy(), sort=False)
    e = pd.Series(rest - g.transform("mean").to_numpy())   # a law read along the stroke: each run's mean only
    eg = e.groupby(train["run"].to_numpy(), sort=False)
    n = g.size().to_numpy(float)
    rho = max(sum(float(x.to_numpy()[1:] @ x.to_numpy()[:-1]) for _, x in eg) / float(e @ e), 0.0)
    se2 = eg.apply(lambda x: float(x @ x)).to_numpy() / (n - 1) / n * (1 + rho) / (1 - rho)
    a, w = g.mean().to_numpy(), 1.0 / se2
    q = float(np.sum(w * (a - np.sum(w * a) / np.sum(w)) ** 2))
    assert 0.3 < rho < 0.9 and 1e-3 < chi2.sf(q, 11) < 0.999
    assert scatter_p(train, law) == pytest.approx(chi2.sf(q, 11), rel=1e-9)


def test_a_reading_of_the_speeds_rate_gets_its_runs_offset_with_trains_scale_on_test():
    # an accelerometer through a 3 ms filter (a column of the rate's bank) plus an offset per run, noise-free
    def with_accel(seed, n_runs):
        df, _ = _runs(seed, n_runs)
        offset = np.random.default_rng(seed + 200).uniform(-0.5, 0.5, n_runs)
        rate = speed_rate(df["speed_m_s"], df["time_s"], df["run"].to_numpy(), 0.003)
        return df.assign(accel_m_s2=0.1 * rate + offset[df["run"].to_numpy()]), offset
    train, level = with_accel(15, 24)
    test, level_te = with_accel(16, 8)
    law = fit_motion_law(train, "accel_m_s2", "rate")
    assert law.history == "rate" and len(law.scale) == len(law.beta) == 4
    np.testing.assert_allclose(_offset(_run_means(train.assign(g=law.run_settings(train)), "g"), level), 0.0,
                               atol=1e-9)
    np.testing.assert_allclose(_offset(_run_means(test.assign(g=law.run_settings(test)), "g"), level_te), 0.0,
                               atol=1e-9)


def test_the_protocol_channels_seek_a_setting_in_a_column_read_along_the_stroke_not_in_a_model_input():
    # a drive that tracks the resonance along the stroke logs a frequency read along the stroke: a model input, read
    # per sample, no setting sought; the preload cell's is derived
    train, _ = _preload_runs(17)
    train["frequency_Hz"] = 48500.0 + 200.0 * (train["position_m"] / STROKE) ** 2 + np.random.default_rng(17).choice(
        [-100.0, 100.0], 30)[train["run"].to_numpy()]
    assert is_along_stroke(train, "frequency_Hz") and is_along_stroke(train, "preload_cell_N")
    tr, _, rec = with_protocol_channels(train, None, (), session_of(train, None), [])
    assert [(r["from"], r["derived"]) for r in rec["run_settings"]] == [("preload_cell_N", True)]
    assert "preload_cell_N_setting" in tr.attrs["l1b2_derived_columns"]
