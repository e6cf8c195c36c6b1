"""A logged channel that is a function of the position is read along the stroke only: its share written out, the
flag, its levels and no run-level signal."""

import numpy as np
import pandas as pd
import pytest


def _runs(n_runs=8, n=200, seed=0):
    """Runs alternating in direction across a 40 mm stroke at speeds that differ per run."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_runs):
        d = 1.0 if r % 2 == 0 else -1.0
        s = np.linspace(-0.02, 0.02, n)[:: int(d)]
        v = 0.05 + 0.02 * r
        rows.append(pd.DataFrame({"run": r + 1, "time_s": 10.0 * r + np.abs(s + 0.02 * d) / v, "position_m": s,
                                  "voltage_V": 200.0 + 10 * r, "direction": d, "load_kg": 0.0, "speed_m_s": d * v,
                                  "noise": rng.standard_normal(n), "level": float(r)}))
    return pd.concat(rows, ignore_index=True)


def test_the_share_is_the_within_run_least_squares_written_out():
    from l1b2.closeloop.candidates import ALONG_STROKE_DEGREE, along_stroke_share
    df = _runs()
    s, d, run = df["position_m"].to_numpy(), df["direction"].to_numpy(), df["run"].to_numpy()
    rng = np.random.default_rng(1)
    c = np.exp(-(s / 0.008) ** 2) + 0.3 * (d > 0) * s / 0.02 + 0.2 * rng.standard_normal(len(s)) + df["level"]
    df = df.assign(probe=c)
    x = (2 * s - s.min() - s.max()) / (s.max() - s.min())
    cols = [np.polynomial.legendre.Legendre.basis(k)(x) for k in range(1, ALONG_STROKE_DEGREE + 1)]
    B = np.column_stack([p * (d > 0) for p in cols] + [p * (d <= 0) for p in cols])
    demean = lambda a: a - pd.DataFrame(a).groupby(run).transform("mean").to_numpy().reshape(a.shape)
    cw, Bw = demean(c), demean(B)
    coef = np.linalg.lstsq(Bw, cw, rcond=None)[0]
    want = 1 - np.sum((cw - Bw @ coef) ** 2) / np.sum(cw ** 2)
    assert along_stroke_share(df, "probe")[0] == pytest.approx(want, rel=1e-9)
    assert 0.5 < want < 1.0
    # the same least squares on the time since each run's first sample
    t = df["time_s"].to_numpy()
    tr = t - pd.Series(t).groupby(run).transform("min").to_numpy()
    xt = (2 * tr - tr.min() - tr.max()) / (tr.max() - tr.min())
    cols = [np.polynomial.legendre.Legendre.basis(k)(xt) for k in range(1, ALONG_STROKE_DEGREE + 1)]
    Bt = demean(np.column_stack([p * (d > 0) for p in cols] + [p * (d <= 0) for p in cols]))
    coef = np.linalg.lstsq(Bt, cw, rcond=None)[0]
    want_t = 1 - np.sum((cw - Bt @ coef) ** 2) / np.sum(cw ** 2)
    assert along_stroke_share(df, "probe")[1] == pytest.approx(want_t, rel=1e-9)
    assert want_t < want - 0.05                                    # runs at different speeds: the clock holds less
    assert np.isnan(along_stroke_share(df, "level")).all()         # constant within every run
    assert along_stroke_share(df, "noise")[0] < 0.05
    # fewer samples within runs than ALONG_STROKE_SAMPLES per coefficient: not read (152 < 160 here)
    assert np.isnan(along_stroke_share(df.groupby("run").head(20), "probe")).all()
    assert np.isfinite(along_stroke_share(df.groupby("run").head(21), "probe")).all()


def test_a_position_channel_is_flagged_offered_at_the_sample_level_and_has_no_run_signal():
    from l1b2.closeloop.candidates import channels_of
    from l1b2.closeloop.runlevel import run_signals
    from l1b2.predictor.effects.channels import levels_of
    df = _runs()
    s = df["position_m"].to_numpy()
    df = df.assign(hall_mT=5.0 * np.exp(-(s / 0.006) ** 2) + 0.01 * df["noise"] + 0.1 * df["level"],
                   temp_C=25.0 + df["level"] + 0.05 * df["noise"])
    ch = {c["name"]: c for c in channels_of(df)}
    assert ch["hall_mT"]["along_stroke"] and levels_of(ch["hall_mT"]) == ("sample",)
    assert not ch["temp_C"]["along_stroke"] and set(levels_of(ch["temp_C"])) == {"sample", "run"}
    assert not ch["level"]["along_stroke"] and levels_of(ch["level"]) == ("run",)
    names = {sg["channel"] for sg in run_signals(df, channels_of(df))}
    assert "temp_C" in names and "level" in names and "hall_mT" not in names


def test_a_channel_of_the_runs_clock_is_not_read_along_the_stroke():
    from l1b2.closeloop.candidates import along_stroke_share, is_along_stroke
    df = _runs()
    t = df["time_s"].to_numpy()
    t_run = t - df.groupby("run")["time_s"].transform("min").to_numpy()
    df = df.assign(sag_V=24.0 - 0.5 * (1 - np.exp(-t_run / 0.1)) + 0.001 * df["noise"])
    pos, clock = along_stroke_share(df, "sag_V")
    assert clock > 0.99 and pos < clock and not is_along_stroke(df, "sag_V")
    # every run moving alike: the position and the clock are one variable, the runs' weights equal
    same = df.assign(time_s=df["run"] * 10.0 + (df["position_m"] * df["direction"] + 0.02) / 0.1)
    same = same.assign(hall_mT=5.0 * np.exp(-(same["position_m"] / 0.006) ** 2))
    pos, clock = along_stroke_share(same, "hall_mT")
    assert pos == pytest.approx(clock, abs=1e-6) and not is_along_stroke(same, "hall_mT")
