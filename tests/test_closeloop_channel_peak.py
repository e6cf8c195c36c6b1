"""A channel's peaked shape: a Lorentzian bump of its standardised run value, centre and width chosen on a grid.

References: the bump written out (its centring by numerical quadrature, not the closed form), the grid's rule
(both ends of TRAIN's range, centres at most one width apart), a residual made from a known grid point's response,
the screen's p-value of the same candidate scored with and without its grid's size, and the Predictor block's force
at one step (the FMU's call sequence) against the formula.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import selection as sel
from l1b2.closeloop.candidates import Context, candidate, channels_of
from l1b2.closeloop.evidence import peak_profile
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import channels as ch


def _bump_written_out(z, z0, w, z_lo, z_hi):
    """``1 / (1 + ((zc - z0)/w)^2)`` of the clipped value, minus its mean over [z_lo, z_hi] by the trapezoid rule."""
    zc = np.clip(z, z_lo, z_hi)
    grid = np.linspace(z_lo, z_hi, 200001)
    mean = np.trapezoid(1.0 / (1.0 + ((grid - z0) / w) ** 2), grid) / (z_hi - z_lo)
    return 1.0 / (1.0 + ((zc - z0) / w) ** 2) - mean


def test_the_peak_columns_are_the_centred_lorentzian_of_the_clipped_value_times_the_form():
    c = np.array([1.0, 2.2, 2.5, 3.0, 6.0, 9.0])              # 9 beyond TRAIN's hi = 6: flat there
    run = c.copy()
    V0, d = np.array([300.0, 150.0, 240.0, 330.0, 200.0, 280.0]), np.array([1.0, -1.0, 1.0, -1.0, 1.0, 1.0])
    v_base = np.array([0.1, -0.05, 0.2, -0.1, 0.15, 0.02])
    spec = {"kind": "channel", "channel": "aux", "mean": 2.0, "sd": 0.5, "lo": 1.0, "hi": 6.0, "level": "run",
            "shape": "peak", "z0": 1.0, "w": 0.5, "grid_points": 7}
    z_lo, z_hi = -2.0, 8.0
    p = _bump_written_out((run - 2.0) / 0.5, 1.0, 0.5, z_lo, z_hi)
    assert p[2] == pytest.approx(1.0 - 0.5 * (np.arctan(14.0) + np.arctan(6.0)) / 10.0, rel=1e-9)
    assert p[4] == p[5] and p.max() == p[2]                    # the top at z0 (c = 2.5), flat beyond hi
    x = {"V0": V0, "d": d, "v_base": v_base, "run:aux": run}
    want = {"friction": -p, "force_factor": V0 / 300.0 * p, "force": d * p, "damping": -d * v_base / 0.2 * p}
    for form, F in want.items():
        got = fx.effect_features({**spec, "form": form}, x)
        assert got.shape == (6, 1)
        np.testing.assert_allclose(got[:, 0], F, rtol=1e-9, atol=1e-12)
    assert fx.family("channel").width({**spec, "form": "force"}) == 1
    # no native kernel: the shape is not one of the Hermite shapes the C kernels have (a Python FMU evaluates it)
    from l1b2.predictor.effects import kernels as ek
    with pytest.raises(fx.EffectSpecError, match="shape 'peak'"):
        ek.spec_scalars({**spec, "channel": "temperature_C", "form": "force", "run_spread": 0.0})


def test_the_grid_spans_trains_range_with_both_ends_and_centres_at_most_one_width_apart():
    z_lo, z_hi = -1.3, 2.1
    grid = ch.peak_grid(z_lo, z_hi)
    for w in ch.PEAK_WIDTHS:
        z0 = np.array([g[0] for g in grid if g[1] == w])
        assert z0[0] == pytest.approx(z_lo) and z0[-1] == pytest.approx(z_hi)
        assert np.all(np.diff(z0) > 0) and np.max(np.diff(z0)) <= w + 1e-12
        assert len(z0) == int(np.ceil((z_hi - z_lo) / w)) + 1
    assert sorted({g[1] for g in grid}) == [0.25, 0.5, 1.0] and ch.peak_grid(1.0, 1.0) == []


def _summary(df):
    return fx.TrainingSummary(0.1, (0.0, 100.0), (-0.02, 0.02), 300.0, {"load_abs": 0.03},
                              channels=channels_of(df), damping_N_s_per_m=2.0)


def test_the_channel_lists_the_peak_at_the_run_level_in_its_forms_with_the_grids_size():
    rng = np.random.default_rng(4)
    runs = np.repeat(np.arange(12), 5)
    vals = {"aux": rng.uniform(0.0, 4.0, 12), "few": np.arange(12) % 7}  # 12 and 7 distinct run values
    # the loop's derived histories of a setting (a low-pass over run periods, a step), 12 run values each
    vals.update({"aux_lag3r": rng.uniform(0.0, 4.0, 12), "aux_step": rng.uniform(-2.0, 2.0, 12)})
    df = pd.DataFrame({"time_s": np.arange(60) * 0.1 + runs, "run": runs, "position_m": 0.0, "voltage_V": 300.0,
                       "direction": 1.0, "load_kg": 0.0, "speed_m_s": 0.1,
                       **{k: v[runs].astype(float) for k, v in vals.items()}})
    train = _summary(df)
    rec = {c["name"]: c for c in train.channels}
    assert rec["aux"]["run_values"] == 12 and rec["few"]["run_values"] == 7
    hyps = fx.family("channel").grid(train)
    peaks = [h for h in hyps if h.spec.get("shape") == "peak"]
    assert {h.spec["channel"] for h in peaks} == {"aux"}       # 7 distinct run values, or a history: not listed
    assert rec["aux_lag3r"]["run_values"] == rec["aux_step"]["run_values"] == 12
    assert {h.spec["channel"] for h in hyps} >= {"aux_lag3r", "aux_step"}    # their Hermite shapes stay
    z_lo, z_hi = ((rec["aux"]["lo"] - rec["aux"]["mean"]) / rec["aux"]["sd"],
                  (rec["aux"]["hi"] - rec["aux"]["mean"]) / rec["aux"]["sd"])
    n = len(ch.peak_grid(z_lo, z_hi))
    assert sorted({h.spec["form"] for h in peaks}) == sorted(ch.PEAK_FORMS) and len(peaks) == n * len(ch.PEAK_FORMS)
    assert {h.spec["level"] for h in peaks} == {"run"} and {h.family for h in peaks} == {"channel_aux"}
    for h in peaks:
        assert h.spec["grid_points"] == n and len(h.names) == 1 and not h.spec.get("by")
        assert f"of {n}" in h.shape and "chosen on a grid" in h.description
    labels = [f"{h.family}[{h.shape}]" for h in hyps]
    assert len(labels) == len(set(labels))
    # the damping form is bounded so that the total damping stays non-negative over TRAIN's range
    for h in (h for h in peaks if h.spec["form"] == "damping"):
        (lo, hi), = h.bounds
        zz = np.linspace(z_lo, z_hi, 401)
        for a in (lo, hi):
            col = ch.peak_column(zz, h.spec["z0"], h.spec["w"], z_lo, z_hi)
            assert np.min(2.0 + a * col / 0.2) >= -1e-9
            assert np.min(2.0 + 1.01 * a * col / 0.2) < 0


def _peak_case(amplitude, seed=2):
    """A simulated world of 40 runs, a logged run setting ``aux`` (a value per run) and a residual made of a known
    grid point's free-run response (force factor form) plus noise."""
    from l1b2.predictor.model import example_params
    from l1b2.predictor.simulate import design_grid, free_run, simulate_dataset
    p = example_params(2).replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0))
    df = simulate_dataset(p, design_grid(voltages=tuple(np.linspace(200.0, 320.0, 10)), loads=(0.0, 0.03)), 0.1)
    cols = [df[c].to_numpy(float) for c in ("position_m", "voltage_V", "load_kg", "direction", "time_s")]
    base = free_run(p, *cols[:4], cols[4], df["speed_m_s"].to_numpy(float), 0.1, df["run"].to_numpy())
    rng = np.random.default_rng(seed)
    runs = pd.unique(df["run"])
    df["aux"] = df["run"].map(dict(zip(runs, rng.uniform(10.0, 20.0, len(runs))))).to_numpy(float)
    ctx = Context(lambda d: base if len(d) == len(df) else None, 0.1, (0.0, 1e3), (-0.02, 0.02))
    peaks = [h for h in fx.family("channel").grid(_summary(df)) if h.spec.get("shape") == "peak"]
    return p, df, base, rng, ctx, peaks


def test_the_grids_choice_recovers_a_known_centre_and_width_and_its_p_value_counts_the_grid():
    p, df, base, rng, ctx, peaks = _peak_case(1.0)
    ff = [h for h in peaks if h.spec["form"] == "force_factor"]
    true = next(h for h in ff if h.spec["w"] == 0.5 and abs(h.spec["z0"] - 0.3) <= 0.25)
    F = np.asarray(candidate(ctx, true).features(df))
    S = sel.linear_response(p, df, 0.1, F.copy(), v_pred=base)[:, 0]
    r = 0.5 * S / np.std(S) * 1e-3 + rng.normal(0.0, 1e-4, len(df))
    mask = np.abs(base) > 0.01
    cands = [candidate(ctx, h) for h in peaks]
    scores = sel.score_candidates(cands, r, df, mask, p, 0.1, v_pred=base)
    crossed = [s for s in scores if s.cv_gain != 0.0]
    assert len(crossed) == len(ch.PEAK_FORMS)                    # one cross-validated point per form
    best = sel.best_per_family(scores, key=lambda c: (c.family, sel.shape_of(c)))[0]
    assert (best.candidate.spec["form"], best.candidate.spec["z0"], best.candidate.spec["w"]) == (
        "force_factor", true.spec["z0"], true.spec["w"])
    prof = peak_profile(scores, "channel_aux")
    assert prof["z0_sd"] == true.spec["z0"] and prof["w_sd"] == true.spec["w"]
    sd, mean = true.spec["sd"], true.spec["mean"]
    lo, hi = prof["profile_95"]["centre"]
    assert lo <= mean + true.spec["z0"] * sd <= hi and hi - lo < 2.0 * sd
    assert prof["grid_points"] == true.spec["grid_points"] > 20
    # the same candidate scored alone as one hypothesis: the p-value the grid's size times smaller
    one = dataclasses.replace(best.candidate, spec={**best.candidate.spec, "grid_points": 1})
    alone = sel.score_candidates([one, best.candidate], r, df, mask, p, 0.1, v_pred=base)
    assert alone[0].cv_gain == pytest.approx(best.cv_gain, rel=1e-9)
    assert alone[1].p_value == pytest.approx(min(1.0, alone[0].p_value * true.spec["grid_points"]), rel=1e-9)
    assert 0 < alone[0].p_value < alone[1].p_value
    assert sel.search_count(best.candidate) == true.spec["grid_points"] and sel.search_count(one) == 1


def test_a_noise_world_finds_no_significant_peak():
    # the residual is noise alone: with the grid counted no peak passes the screen at alpha 0.01 (uncorrected over
    # families), whereas the best grid point's p-value taken alone is far smaller than its corrected one
    p, df, base, rng, ctx, peaks = _peak_case(0.0, seed=7)
    r = rng.normal(0.0, 1e-4, len(df))
    mask = np.abs(base) > 0.01
    scores = sel.score_candidates([candidate(ctx, h) for h in peaks], r, df, mask, p, 0.1, v_pred=base)
    assert not sel.significant(scores, level=0.01, min_gain=0.0)


def test_the_peak_is_the_simplest_only_when_its_searched_parameters_are_counted():
    spec = {"kind": "channel", "shape": "peak", "grid_points": 9}
    peak = sel.CandidateForce("f", "x", "p", ("a",), ("N",), lambda d: None, spec=spec)
    quad = sel.CandidateForce("f", "x", "q", ("a", "b"), ("N", "N"), lambda d: None,
                              spec={"kind": "channel", "shape": "quadratic"})
    assert sel.searched_params(peak) == 2 and sel.searched_params(quad) == 0
    assert peak.n_params + sel.searched_params(peak) > quad.n_params + sel.searched_params(quad)


def test_predictor_fmu_evaluates_the_peak_as_the_loop_fitted_it():
    # reference: the force written out, F = a V0/300 (1/(1 + ((zc - z0)/w)^2) - mean over TRAIN's range), zc the
    # input's standardised value clipped to TRAIN's range, read from the logged channel's own input; the block's
    # force after one step (the FMU's call sequence) and the loop's own features of the same spec
    from test_predictor_fmu_channels import _effect, _setups, _stepped_force
    from l1b2.predictor.effects import ExtendedPredictor
    base, refit = _setups()
    rec = {"name": "line_pressure_bar", "kind": "logged", "mean": 2.3, "sd": 0.4, "lo": 1.6, "hi": 3.1,
           "within_run": False, "run_values": 9, "run_spread": 0.0}
    summary = fx.TrainingSummary(1.0, (0.0, 10.0), (-0.02, 0.02), 300.0, {}, channels=(rec,))
    h = next(h for h in fx.family("channel").grid(summary) if h.spec.get("shape") == "peak"
             and h.spec["form"] == "force_factor" and h.spec["w"] == 0.5 and h.spec["z0"] > 0)
    a = 0.8
    ep = ExtendedPredictor(base, refit, (_effect(h, (a,)),), None, {})
    z_lo, z_hi = (1.6 - 2.3) / 0.4, (3.1 - 2.3) / 0.4
    V0 = 280.0
    for value in (2.0, 2.3 + h.spec["z0"] * 0.4, 3.5):        # 3.5 beyond TRAIN's hi: clipped
        want = a * V0 / 300.0 * _bump_written_out((value - 2.3) / 0.4, h.spec["z0"], 0.5, z_lo, z_hi)
        got = _stepped_force(ep, V0=V0, line_pressure_bar=value)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
        x = {"V0": np.array([V0]), "d": np.array([1.0]), "run:line_pressure_bar": np.array([value])}
        assert got == pytest.approx(float(fx.effect_features(h.spec, x)[0, 0] * a), rel=1e-12)
    assert abs(_stepped_force(ep, V0=V0, line_pressure_bar=2.3 + h.spec["z0"] * 0.4)) > 0.3 * a


def test_the_exported_fmu_reproduces_the_free_run_of_the_loops_peak(tmp_path, isolated):
    # reference: the identification's own free run (l1b2.predictor.simulate.free_run with the candidate's force, the
    # run-level pressure each run's mean by groupby) of a peak of a logged run setting; the Predictor.fmu exported
    # from it, driven through fmpy with the channel as its input, within 1e-10 relative
    import test_predictor_fmu_channels as tf
    from l1b2.data import measurements as dataio
    from l1b2.fmi.export import export_calibrated
    from l1b2.predictor.effects import ExtendedPredictor
    from l1b2.predictor.simulate import free_run
    base, refit = tf._setups()
    df = tf._frame()
    rec = next(c for c in channels_of(df) if c["name"] == "line_pressure_bar")
    summary = fx.TrainingSummary(1.0, (0.0, 10.0), (-0.02, 0.02), 300.0, {},
                                 channels=({**rec, "run_values": ch.PEAK_MIN_RUN_VALUES},))
    h = next(h for h in fx.family("channel").grid(summary) if h.spec.get("shape") == "peak"
             and h.spec["form"] == "force_factor" and h.spec["w"] == 0.5 and abs(h.spec["z0"]) < 0.5)
    F = np.asarray(candidate(tf._ctx(base), h).features(df))[:, 0]
    phi = 0.1 / np.sqrt(np.mean(F ** 2))
    run = df[dataio.RUN].to_numpy()
    v_start = [0.1 * d for d, *_ in tf.RUN_TABLE]
    args = (df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD], df[dataio.DIRECTION], df[dataio.TIME], v_start,
            refit.slider_mass_kg, run)
    want = free_run(refit.params, *args, extra_force=F * phi)
    assert np.max(np.abs(want - free_run(refit.params, *args))) > 1e-4   # not vacuous
    ep = ExtendedPredictor(base, refit, (tf._effect(h, (phi,)),), None, {"train": "synthetic"})
    man = export_calibrated(ep, tmp_path / "out")
    assert man["inputs"] == ["V0", "s", "load", "direction", "line_pressure_bar"]
    assert man["native"]["Predictor"]["included"] is False
    path = tmp_path / "out" / "fmus" / "Predictor.fmu"
    names = ["V0", "s", "load", "direction", "line_pressure_bar"]
    runs = []
    for i, v0 in enumerate(v_start):
        sel_ = df[dataio.RUN] == i
        r = {"t": df.loc[sel_, dataio.TIME].tolist(), "v_start": v0}
        for name, col in zip(names, (dataio.VOLTAGE, dataio.POSITION, dataio.LOAD, dataio.DIRECTION,
                                     "line_pressure_bar")):
            r[name] = df.loc[sel_, col].tolist()
        runs.append(r)
    got = np.concatenate(isolated(tf.__file__, "worker_fmpy", str(path), runs, names).value)
    np.testing.assert_allclose(got[:, 0], want, rtol=1e-10, atol=1e-14)


def test_the_profile_region_is_the_grid_points_near_the_best_widened_to_their_cells():
    # reference: a grid on [-1.5, 1.5] (sd 2, mean 10), run-counted log-likelihoods written by hand: the best point
    # (z0 -0.25, w 0.25), a neighbour 4 below the 5.99 limit, the rest far; the region spans both points' cells
    # (centre +- half the spacing 0.25 of its width's centres; half width / sqrt 2 .. * sqrt 2), in channel units
    spec = {"kind": "channel", "form": "force", "mean": 10.0, "sd": 2.0, "lo": 7.0, "hi": 13.0, "shape": "peak"}
    grid = ch.peak_grid(-1.5, 1.5)
    ll = {(-0.25, 0.25): -50.0, (0.0, 0.25): -46.0}

    def score(i, z0, w):
        c = sel.CandidateForce("channel_aux", "aux", str(i), ("a",), ("N",), lambda d: None,
                               spec={**spec, "z0": z0, "w": w, "grid_points": len(grid)})
        return sel.Score(c, 0.2 if (z0, w) == (-0.25, 0.25) else 0.0, 0.5, 0.0, 0.0, np.zeros(1), 0.0,
                         ll.get((z0, w), 0.0))
    prof = peak_profile([score(i, z0, w) for i, (z0, w) in enumerate(grid)], "channel_aux")
    assert (prof["z0_sd"], prof["w_sd"], prof["centre"], prof["half_width"]) == (-0.25, 0.25, 9.5, 0.5)
    assert prof["profile_95"]["grid_points"] == 2
    np.testing.assert_allclose(prof["profile_95"]["centre"], [10.0 + 2.0 * -0.375, 10.0 + 2.0 * 0.125])
    np.testing.assert_allclose(prof["profile_95"]["half_width"], [0.5 / np.sqrt(2.0), 0.5 * np.sqrt(2.0)])
    assert peak_profile([score(0, 0.0, 0.25)], "channel_other") is None


def test_between_families_the_parsimony_rule_counts_the_peaks_centre_and_width():
    # reference: prefer's rule, fewest parameters within the parsimony of the best gain: a peak (1 amplitude + centre
    # and width on a grid = 3) loses to a two-parameter quadratic of another channel whose gain is within it, and wins
    # against a four-parameter one
    from types import SimpleNamespace
    from l1b2.closeloop.loop import prefer

    def trial(fam, shape, k, gain):
        c = sel.CandidateForce(fam, fam, shape, tuple(f"p{i}" for i in range(k)), ("N",) * k, lambda d: None,
                               generic=True, spec={"kind": "channel", "level": "run", "shape": shape})
        return SimpleNamespace(candidate=c, gain=gain)
    peak = trial("channel_a", "peak", 1, 0.50)
    assert prefer([peak, trial("channel_b", "quadratic", 2, 0.48)], 0.9).candidate.family == "channel_b"
    assert prefer([peak, trial("channel_b", "quadratic", 4, 0.48)], 0.9).candidate.family == "channel_a"
