"""bench/blind_effects_eighth.py: the laws its kinds inject, checked against the formulas written out.

The audit's rows are measurements (its decision record); these checks only hold its physics to its docstring: the
squeeze film's damping of B2 with the chamber's pressure, the drive's start after the previous run's file is
written, the encoder's sub-divisional error and the pulley bracket's strain gauge.
"""

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def audit(load_bench):
    return load_bench("blind_effects_eighth")


def test_b2_damping_follows_the_rarefied_squeeze_film(audit):
    zeta, share, gap = 0.0125, 0.4, 10e-6
    # at the lab's pressure: unchanged
    assert audit.b2_damping(zeta, 1013.25, share, gap) == pytest.approx(zeta, rel=1e-12)
    # Kn = 1 at p = 1013.25 hPa x 68 nm / 10 um = 6.8901 hPa: the film's factor 1 / (1 + 9.638)
    p1 = 1013.25 * 68e-9 / 10e-6
    assert audit.film_factor(p1, gap) == pytest.approx(1 / 10.638, rel=1e-12)
    kn_ref = 68e-9 / 10e-6
    g_ref = 1 / (1 + 9.638 * kn_ref ** 1.159)
    want = zeta * (1 - share + share * (1 / 10.638) / g_ref)
    assert audit.b2_damping(zeta, np.array([p1]), share, gap) == pytest.approx([want], rel=1e-12)
    # a hard vacuum leaves the structure's share only; lower pressure, less damping
    assert audit.b2_damping(zeta, 1e-6, share, gap) == pytest.approx(zeta * (1 - share), rel=1e-6)
    z = audit.b2_damping(zeta, np.array([1.0, 10.0, 100.0, 1000.0]), share, gap)
    assert np.all(np.diff(z) > 0)


def test_start_latency_is_relay_plus_the_previous_files_write(audit):
    got = audit.start_latency_s(np.array([0, 500]), 8e-3, 0.06e-3, np.array([1e-3, 2e-3]))
    assert got == pytest.approx([8e-3 + 0 + 1e-3, 8e-3 + 500 * 0.06e-3 + 2e-3], abs=1e-15)


def test_delayed_samples_rest_then_follow_the_motion(audit):
    t_sim = np.arange(0.0, 0.1 + 1e-12, 2e-4)
    s_sim = -0.02 + 0.05 * t_sim                       # a motion from -20 mm, linear: interpolated exactly
    t, s = audit.delayed_samples(t_sim, s_sim, 0.0153)
    assert t == pytest.approx(np.arange(116) * 1e-3, abs=1e-15)   # floor((0.1 + 0.0153) / 1 ms) + 1 samples
    rest = t < 0.0153
    assert np.all(s[rest] == -0.02)
    assert s[~rest] == pytest.approx(-0.02 + 0.05 * (t[~rest] - 0.0153), abs=1e-15)


def test_cyclic_error_of_the_encoder(audit):
    P, A1, A2, p1, p2 = 1.5e-3, 8e-6, 3e-6, 0.4, 1.1
    s = np.array([0.0, P / 4, P / 2, 0.7e-3])
    want = np.array([A1 * math.sin(p1) + A2 * math.sin(p2),
                     A1 * math.sin(math.pi / 2 + p1) + A2 * math.sin(math.pi + p2),
                     A1 * math.sin(math.pi + p1) + A2 * math.sin(2 * math.pi + p2),
                     A1 * math.sin(2 * math.pi * 0.7 / 1.5 + p1) + A2 * math.sin(4 * math.pi * 0.7 / 1.5 + p2)])
    assert audit.cyclic_error_m(s, P, A1, A2, p1, p2) == pytest.approx(want, abs=1e-18)
    # periodic in the pitch
    assert audit.cyclic_error_m(s + 3 * P, P, A1, A2, p1, p2) == pytest.approx(want, abs=1e-15)


def test_gauge_reads_the_positive_loads_pull_and_the_air(audit):
    k, alpha, A, Pi, phi = 25.0, 8.0, 0.8, 200.0, 0.3
    t = np.array([0.0, 50.0])
    air = alpha * A * np.sin(2 * math.pi * t / Pi + phi)
    assert audit.gauge_strain_ue(0.07, t, k, alpha, A, Pi, phi) == pytest.approx(25 * 9.81 * 0.07 + air, abs=1e-12)
    assert audit.gauge_strain_ue(-0.09, t, k, alpha, A, Pi, phi) == pytest.approx(air, abs=1e-12)


def test_draws_lie_in_their_ranges(audit):
    for seed in (1, 2, 3):
        p = audit.draw("vacuum_squeeze_film", seed, 72)
        assert 0.30 <= p["share"] <= 0.45 and 8e-6 <= p["gap_m"] <= 15e-6
        assert np.all((p["p_hPa"] >= 1.0) & (p["p_hPa"] <= 1000.0))
        p = audit.draw("file_write_latency", seed, 72)
        assert 6e-3 <= p["relay_s"] <= 12e-3 and 0.04e-3 <= p["w_s"] <= 0.08e-3
        assert np.all((p["jitter_s"] >= 0) & (p["jitter_s"] <= 4e-3))
        p = audit.draw("encoder_cyclic_error", seed, 72)
        assert 1e-3 <= p["P_m"] <= 2e-3 and 6e-6 <= p["A1_m"] <= 10e-6 and 2e-6 <= p["A2_m"] <= 4e-6
        p = audit.draw("strain_gauge_decoy", seed, 72)
        assert 20 <= p["k_ue_N"] <= 30 and 5 <= p["alpha_ue_K"] <= 10
        assert 0.5 <= p["A_T_K"] <= 1.0 and 150 <= p["Pi_s"] <= 250


@pytest.fixture(scope="module")
def probe(load_bench):
    return load_bench("blind_effects_eighth_probe")


def test_onset_keeps_each_run_from_its_last_sample_at_rest(probe):
    import pandas as pd
    s = np.concatenate([np.full(5, -0.02), -0.02 + 1e-5 * np.arange(1, 11)])   # 5 samples at rest, then moving
    df = pd.DataFrame({"run": np.repeat([1, 2], 15), "position_m": np.concatenate([s, -s]),
                       "time_s": np.arange(30) * 1e-3})
    out = probe.onset_trimmed(df)
    assert list(out.groupby("run").size()) == [11, 11]            # the 4 samples before the last one at rest dropped
    assert out["time_s"].iloc[0] == pytest.approx(4e-3) and out["time_s"].iloc[11] == pytest.approx(19e-3)


def test_fit_recovers_a_cyclic_error_from_runs_at_steady_speed(probe, audit):
    import pandas as pd
    P, A1, A2, p1, p2 = 1.5e-3, 8e-6, 3e-6, 0.4, 1.1
    frames = []
    for k, v in enumerate((0.05, 0.1, 0.15, 0.2)):
        t = np.arange(0.0, 0.04 / v, 1e-3)
        s = -0.02 + v * t
        pos = s + audit.cyclic_error_m(s, P, A1, A2, p1, p2)
        frames.append(pd.DataFrame({"run": k + 1, "time_s": t, "position_m": pos, "speed_m_s": np.gradient(pos, t)}))
    got = probe.fit_cyclic_error(pd.concat(frames, ignore_index=True))
    assert got["P_m"] == pytest.approx(P, rel=5e-3)
    assert got["A1_m"] == pytest.approx(A1, rel=0.2) and got["A2_m"] == pytest.approx(A2, rel=0.4)
    assert abs((got["phi1"] - p1 + math.pi) % (2 * math.pi) - math.pi) < 0.1
