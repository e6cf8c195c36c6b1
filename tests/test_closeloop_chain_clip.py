"""The speed channel's range in the measurement chain: ``y = clip(filter(u), lo, hi)`` (``l1b2.closeloop.chain``).

Fast unit tests on speed columns written out here from a known slider speed: the rails of a clipped column
(different per sign), no clip on a clean or quantised column, no rail behind a low-pass filter alone, the filter
inside the rails, and the prediction path (the clip after the filter, the filter's state unclipped) against numbers
worked out by hand.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from l1b2.closeloop import chain
from l1b2.closeloop.loop import ChainModel, _chain_note
from l1b2.closeloop.report import chain_line
from l1b2.data import measurements as dataio
from l1b2.fmi.export import export_calibrated
from l1b2.predictor.effects import EffectSpecError, apply_output_filter
from l1b2.predictor.effects.model import ExtendedPredictor
from l1b2.predictor.model import example_params
from l1b2.predictor.setup import PredictorSetup

DT = 1e-3           # sample period [s]
LO, HI = -0.18, 0.22   # the rails of the clipped columns [m/s]


def slider_frame(n_runs=40, n=400, seed=0):
    """Runs of a smooth speed profile ``v_peak sin(pi t / T)^2`` [m/s], peaks 0.08-0.34 m/s, directions
    alternating; the position is its exact integral, so the derivative is the profile up to O(dt^2)."""
    rng = np.random.default_rng(seed)
    rows = []
    T = n * DT
    for k in range(n_runs):
        t = np.arange(n) * DT
        d = 1.0 if k % 2 == 0 else -1.0
        vp = d * rng.uniform(0.08, 0.34)
        s = vp * (t / 2 - T / (4 * np.pi) * np.sin(2 * np.pi * t / T))
        rows.append(pd.DataFrame({dataio.TIME: 10.0 * k + t, dataio.RUN: k + 1, dataio.POSITION: s,
                                  "v_true": vp * np.sin(np.pi * t / T) ** 2}))
    return pd.concat(rows, ignore_index=True)


def lowpass(df, x, a):
    """``y(k) = a y(k-1) + (1 - a) x(k)`` per run, ``y(0) = x(0)``."""
    out = np.empty_like(x)
    for _, sl in dataio.run_slices(df[dataio.RUN]):
        y = x[sl.start]
        for i in range(sl.start, sl.stop):
            y = a * y + (1 - a) * x[i] if i > sl.start else x[i]
            out[i] = y
    return out


def with_speed(df, v):
    out = df.copy()
    out[dataio.SPEED] = v
    return out


def test_the_rails_of_a_clipped_column_are_found_per_sign_with_the_samples_at_them():
    df = slider_frame()
    noisy = df["v_true"].to_numpy() + 1e-3 * np.random.default_rng(1).standard_normal(len(df))
    meas = with_speed(df, np.clip(noisy, LO, HI))
    mask = np.ones(len(df), bool)
    out = chain.speed_channel(meas, mask)
    clip = out["clip"]
    assert out["accepted"] and clip["accepted"], clip
    assert clip["lo_m_s"] == pytest.approx(LO, rel=1e-12) and clip["hi_m_s"] == pytest.approx(HI, rel=1e-12)
    assert clip["band_lo_m_s"] == clip["band_hi_m_s"] == 0.0     # the exact rail: one value, no band
    # samples at the rails: those of the noisy speed beyond them, without each run's first sample (the design's rows)
    first = np.r_[True, df[dataio.RUN].to_numpy()[1:] != df[dataio.RUN].to_numpy()[:-1]]
    assert clip["n_hi"] == int(np.sum((noisy >= HI) & ~first))
    assert clip["n_lo"] == int(np.sum((noisy <= LO) & ~first))
    assert clip["n_hi"] > 100 and clip["n_lo"] > 100
    assert clip["cv_gain"] > 0.9 and not clip["inner_filter"]
    f = out["filter"]
    assert (f.a, f.b0, f.b1, f.lo_m_s, f.hi_m_s) == (0.0, 1.0, 0.0, clip["lo_m_s"], clip["hi_m_s"])
    assert f.to_dict()["clip_hi_m_s"] == clip["hi_m_s"]
    line = chain_line({k: v for k, v in out.items() if k != "filter"})
    assert "+0.22 m/s" in line and "-0.18 m/s" in line and f"{clip['n_hi']} samples" in line
    assert "with no filter inside it" in line and "kept: the prediction is clipped after the filter" in line


def test_a_filter_inside_the_rails_is_fitted_on_the_samples_inside():
    df = slider_frame(seed=2)
    a = np.exp(-DT / 4e-3)      # 4 ms time constant; noise small enough for the equation-error fit to be unbiased
    v = lowpass(df, df["v_true"].to_numpy(), a) + 1e-5 * np.random.default_rng(3).standard_normal(len(df))
    out = chain.speed_channel(with_speed(df, np.clip(v, LO, HI)), np.ones(len(df), bool))
    assert out["accepted"] and out["clip"]["accepted"] and out["clip"]["inner_filter"], out["clip"]
    f = out["filter"]
    assert f.a == pytest.approx(a, abs=0.02) and (f.b0 + f.b1) / (1 - f.a) == pytest.approx(1.0, abs=0.02)
    assert (f.lo_m_s, f.hi_m_s) == pytest.approx((LO, HI), rel=1e-12)


@pytest.mark.parametrize("quantum", [0.0, 1e-4])
def test_a_clean_column_gets_no_clip_even_quantised(quantum):
    df = slider_frame(seed=4)
    v = df["v_true"].to_numpy() + 3e-4 * np.random.default_rng(5).standard_normal(len(df))
    if quantum:
        v = quantum * np.round(v / quantum)    # many samples read the extreme code
    out = chain.speed_channel(with_speed(df, v), np.ones(len(df), bool))
    assert out["rel_rms_mismatch"] < 0.01
    assert not out["accepted"] and "clip" not in out and not out["filter"].clipped
    # the rails' own test, asked directly, finds no rail either (the derivative lies below the extreme)
    runs = df[dataio.RUN].to_numpy()
    r = chain.speed_rails(v, df["v_true"].to_numpy(), runs)
    assert r["hi_m_s"] == np.inf and r["lo_m_s"] == -np.inf


def test_a_low_passed_column_keeps_its_filter_and_gets_no_rail():
    df = slider_frame(seed=6)
    a = np.exp(-DT / 5e-3)      # noise small enough for the equation-error fit to be unbiased
    v = lowpass(df, df["v_true"].to_numpy(), a) + 1e-5 * np.random.default_rng(7).standard_normal(len(df))
    out = chain.speed_channel(with_speed(df, v), np.ones(len(df), bool))
    assert out["accepted"] and out["rel_rms_mismatch"] > 0.01
    assert out["clip"]["lo_m_s"] is None and out["clip"]["hi_m_s"] is None and not out["clip"]["accepted"]
    assert not out["filter"].clipped and out["filter"].a == pytest.approx(a, abs=0.02)
    assert set(out["filter"].params()) == {"a", "b0", "b1"}


def test_the_prediction_is_clipped_after_the_filter_whose_state_is_unclipped():
    # y0 = (b0 + b1)/(1 - a) u0 = 0.1; y1 = 0.5*0.1 + 0.3*0.3 + 0.2*0.1 = 0.16; y2 = 0.08 + 0.09 + 0.06 = 0.23;
    # y3 = 0.115 - 0.12 + 0.06 = 0.055; y4 = 0.0275 + 0 - 0.08 = -0.0525; then clip to [-0.03, 0.15].
    # (A clipped state would give y3 = 0.5*0.15 - 0.12 + 0.06 = 0.015.)
    filt = {"a": 0.5, "b0": 0.3, "b1": 0.2, "lo_m_s": -0.03, "hi_m_s": 0.15}
    u = np.array([0.1, 0.3, 0.3, -0.4, 0.0])
    want = np.array([0.1, 0.15, 0.15, 0.055, -0.03])
    np.testing.assert_allclose(apply_output_filter(filt, u), want, rtol=0, atol=1e-15)
    # two runs: each restarts; through the chain's stage and the model around a physics prediction
    df = pd.DataFrame({dataio.RUN: [1] * 5 + [2] * 5, dataio.TIME: np.r_[np.arange(5), 10 + np.arange(5)] * DT,
                       dataio.POSITION: np.zeros(10), dataio.SPEED: np.zeros(10)})
    stage = chain.OutputFilter(0.5, 0.3, 0.2, lo_m_s=-0.03, hi_m_s=0.15)
    np.testing.assert_allclose(stage.apply(df, np.r_[u, u]), np.r_[want, want], rtol=0, atol=1e-15)

    class Physics:
        def predict_free_run(self, frame):
            return np.r_[u, u]
    np.testing.assert_allclose(ChainModel(Physics(), stage).predict_free_run(df), np.r_[want, want], atol=1e-15)
    # without rails the stage is the plain filter (the unclipped values above)
    plain = chain.OutputFilter(0.5, 0.3, 0.2)
    np.testing.assert_allclose(plain.apply(df, np.r_[u, u])[:5], [0.1, 0.16, 0.23, 0.055, -0.0525], atol=1e-15)


def test_the_exported_model_keeps_the_rails_and_predictor_fmu_declares_them(tmp_path):
    setup = PredictorSetup(example_params(3), 0.1, 1e-3)
    filt = {"a": 0.0, "b0": 1.0, "b1": 0.0, "lo_m_s": LO, "hi_m_s": HI}
    model = ExtendedPredictor(setup, setup, output_filter=filt)
    assert ExtendedPredictor.from_dict(model.to_dict()).output_filter == filt
    plain = ExtendedPredictor(setup, setup, output_filter={"a": 0.2, "b0": 0.8, "b1": 0.0})
    assert ExtendedPredictor.from_dict(plain.to_dict()).output_filter == {"a": 0.2, "b0": 0.8, "b1": 0.0}
    from fmpy import read_model_description
    export_calibrated(model, tmp_path)
    var = {v.name: v for v in read_model_description(str(tmp_path / "fmus" / "Predictor.fmu")).modelVariables}
    assert (float(var["speed_rail_lo"].start), float(var["speed_rail_hi"].start)) == (LO, HI)
    assert var["speed_rail_lo"].unit == var["speed_rail_hi"].unit == "m/s"
    only_hi = ExtendedPredictor(setup, setup, output_filter={"a": 0.0, "b0": 1.0, "b1": 0.0, "hi_m_s": HI})
    export_calibrated(only_hi, tmp_path / "hi")
    names = {v.name for v in read_model_description(str(tmp_path / "hi" / "fmus" / "Predictor.fmu")).modelVariables}
    assert "speed_rail_hi" in names and "speed_rail_lo" not in names


def test_the_column_noise_is_the_second_differences_scatter():
    # a smooth profile plus white noise of sd s: v(k+1) - 2 v(k) + v(k-1) has sd sqrt(6) s; quantised to q, the
    # noise's variance is s^2 + q^2 / 12 (q a fifth of s: the quantisation is noise-like)
    df = slider_frame(seed=8)
    runs = df[dataio.RUN].to_numpy()
    e = np.random.default_rng(9).standard_normal(len(df))
    v = df["v_true"].to_numpy() + 1e-3 * e
    assert chain.column_noise(v, runs) == pytest.approx(1e-3, rel=0.03)
    q = 2e-4
    assert chain.column_noise(q * np.round(v / q), runs) == pytest.approx(np.sqrt(1e-6 + q ** 2 / 12), rel=0.05)
    # without noise: the profile's own second difference, at most 2 v_peak (pi / T)^2 dt^2 (v_peak <= 0.34 m/s,
    # T = 0.4 s), bounds the estimate by 1.4826 / sqrt(6) of it
    bound = 1.4826 / np.sqrt(6) * 2 * 0.34 * (np.pi / 0.4) ** 2 * DT ** 2
    assert 0 < chain.column_noise(df["v_true"].to_numpy(), runs) <= bound < 0.03e-3


@pytest.mark.parametrize("quantum", [0.0, 1e-4])
def test_a_noisy_rail_is_found_at_the_centre_of_its_pile(quantum):
    # the analogue stage saturates first, then 1 mm/s noise (and an ADC's quantum) is added: the samples at each
    # rail scatter around it instead of repeating one value
    df = slider_frame()
    sd = 1e-3
    v = np.clip(df["v_true"].to_numpy(), LO, HI) + sd * np.random.default_rng(11).standard_normal(len(df))
    if quantum:
        v = quantum * np.round(v / quantum)
    out = chain.speed_channel(with_speed(df, v), np.ones(len(df), bool))
    clip = out["clip"]
    assert out["accepted"] and clip["accepted"] and clip["cv_gain"] > 0.9, clip
    assert clip["noise_m_s"] == pytest.approx(np.sqrt(sd ** 2 + quantum ** 2 / 12), rel=0.05)
    # the band below each extreme: 2 z sigma, z the normal quantile exceeded with probability 1/n (n: the rows)
    n = len(df) - df[dataio.RUN].nunique()
    band = 2 * stats.norm.isf(1 / n) * clip["noise_m_s"]
    assert clip["band_hi_m_s"] == pytest.approx(band, rel=1e-12) and clip["band_lo_m_s"] == clip["band_hi_m_s"]
    # the rails: the median of the band's samples, within a fifth of the noise's sd of the written-out rails
    first = np.r_[True, df[dataio.RUN].to_numpy()[1:] != df[dataio.RUN].to_numpy()[:-1]]
    rows = v[~first]
    top, bottom = rows[rows >= rows.max() - band], rows[rows <= rows.min() + band]
    assert clip["hi_m_s"] == pytest.approx(np.median(top), abs=1e-15) and clip["n_hi"] == len(top)
    assert clip["lo_m_s"] == pytest.approx(np.median(bottom), abs=1e-15) and clip["n_lo"] == len(bottom)
    assert abs(clip["hi_m_s"] - HI) < 0.2 * sd and abs(clip["lo_m_s"] - LO) < 0.2 * sd
    f = out["filter"]
    assert (f.lo_m_s, f.hi_m_s) == (clip["lo_m_s"], clip["hi_m_s"]) and not clip["inner_filter"]
    line = chain_line({k: v for k, v in out.items() if k != "filter"})
    assert f"{clip['n_hi']} samples in {clip['runs_hi']} runs, within {1e3 * band:.3g} mm/s" in line
    assert "a noisy rail" in line


def test_no_rail_in_a_noisy_column_that_follows_the_speed_filtered_or_not():
    # 1 mm/s noise on the speed itself, and after a 5 ms low-pass: the noisy band below the extreme is tried, and
    # there the derivative lies below the extreme
    df = slider_frame(seed=12)
    runs, vt = df[dataio.RUN].to_numpy(), df["v_true"].to_numpy()
    e = 1e-3 * np.random.default_rng(13).standard_normal(len(df))
    for v in (vt + e, lowpass(df, vt, np.exp(-DT / 5e-3)) + e):
        r = chain.speed_rails(v, vt, runs)
        assert r["band_hi_m_s"] > 0 and r["band_lo_m_s"] > 0
        assert r["hi_m_s"] == np.inf and r["lo_m_s"] == -np.inf, r


@pytest.mark.parametrize("key", ["a", "b0", "b1"])
def test_a_saved_filter_missing_a_coefficient_fails_where_it_is_read(key):
    setup = PredictorSetup(example_params(3), 0.1, 1e-3)
    saved = ExtendedPredictor(setup, setup, output_filter={"a": 0.2, "b0": 0.8, "b1": 0.0}).to_dict()
    del saved["output_filter"][key]
    with pytest.raises(EffectSpecError, match=f"output filter: missing '{key}'"):
        ExtendedPredictor.from_dict(saved)
    saved["output_filter"][key] = "x"
    with pytest.raises(EffectSpecError, match=f"output filter: '{key}' is not a number"):
        ExtendedPredictor.from_dict(saved)


@pytest.mark.parametrize("stage, filtered, note", [
    (chain.OutputFilter(), False, "filtered"),
    (chain.OutputFilter(0.3, 0.7, 0.0), True, "filtered"),
    (chain.OutputFilter(0.0, 1.0, 0.0, lo_m_s=LO, hi_m_s=HI), False, "clipped at its range"),
    (chain.OutputFilter(0.0, 1.0, 0.0, hi_m_s=HI), False, "clipped at its range"),
    (chain.OutputFilter(0.0, 0.9, 0.1, lo_m_s=LO), True, "filtered and clipped at its range"),
])
def test_the_message_names_what_the_kept_stage_does(stage, filtered, note):
    assert stage.filtered is filtered
    assert _chain_note(stage) == f"; speed channel {note} (measurement chain)"
    assert _chain_note(None) == ""
