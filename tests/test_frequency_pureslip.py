"""The pure-slip family with a drive-frequency response: its start, the response's bounds and Jacobian, recovery."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from l1b2.ident.reduced import slip_sigma_start


def test_slip_sigma_start_puts_the_median_slip_ratio_at_k_ref():
    # reference: k = sigma v' / (pi B'(s) V0) written out; B'(x) = 0.004 + 0.001 x (Legendre), x = (s - 0.001)/0.02;
    # samples moving backwards (d v < 0), masked out or without drive (V0 = 0) do not count
    rng = np.random.default_rng(0)
    n = 201
    s = rng.uniform(-0.02, 0.02, n)
    V0 = rng.choice([220.0, 324.0], n)
    d = np.ones(n)
    v = rng.uniform(0.05, 0.3, n)
    mask = np.ones(n, bool)
    d[:20] = -1.0            # moving against the drive direction: v' < 0
    mask[20:40] = False
    V0[40:50] = 0.0
    data = SimpleNamespace(s=s, V0=V0, d=d, v=v, mask=mask)
    Bp = 0.004 + 0.001 * (s - 0.001) / 0.02
    use = slice(50, None)
    ratio = v[use] / (np.pi * Bp[use] * V0[use])
    got = slip_sigma_start(data, [0.004, 0.001], 0.001, 0.02, k_ref=0.4)
    assert got == pytest.approx(0.4 / np.median(ratio), rel=1e-12)
    k = got * ratio
    assert np.median(k) == pytest.approx(0.4, rel=1e-12)
    assert slip_sigma_start(SimpleNamespace(s=s, V0=V0, d=-d, v=np.abs(v), mask=mask & (d < 0) & False),
                            [0.004], 0.0, 0.02) is None


# ---- the pure-slip family's own world with a known response (order 2, 12 short runs) --------------------------

import pandas as pd  # noqa: E402
from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402
from l1b2.ident.frequency import Q_HI, Q_LO, ZETA_B_RANGE, ResponseLinearisation, bounds_hit, response_of  # noqa: E402
from l1b2.predictor.frequency import FrequencyResponse, effective_voltage  # noqa: E402
from l1b2.predictor.model import example_params  # noqa: E402
from l1b2.predictor.simulate import design_grid, simulate_dataset  # noqa: E402

M_S, F_REF = 0.1, 48500.0
FREQS = (48000.0, 48500.0, 49000.0)


def _slip_world(resp, drive_law="pure_slip", noise=3e-4, seed=4):
    """Traverses of the predictor family itself at the drive amplitude V0 g(f) (its frequency response)."""
    prm = example_params(2).replace(sigma=8.0, c_r=5.0, alpha=(0.05, 0.005, 0.0), drive_law=drive_law)
    design = design_grid(voltages=(220.0, 324.0), loads=(-0.05, 0.05))
    design = pd.concat([design.assign(frequency_Hz=f) for f in FREQS], ignore_index=True)
    eff = design.assign(voltage_V=effective_voltage(design["voltage_V"], design["frequency_Hz"], resp))
    df = simulate_dataset(prm, eff, M_S, noise_std=noise, seed=seed, max_duration=0.6)
    df["voltage_V"] = design["voltage_V"].to_numpy()[df["run"].to_numpy()]
    df["frequency_Hz"] = design["frequency_Hz"].to_numpy()[df["run"].to_numpy()]
    return prm, df


def test_bounds_hit_names_the_parameter_and_the_bound():
    inside = np.array([47800.0 / F_REF, math.log(0.0125)])
    assert bounds_hit(inside) == []
    assert bounds_hit([inside[0], Q_LO[1]]) == [f"zeta_b lower bound {ZETA_B_RANGE[0]:g}"]
    assert bounds_hit([Q_HI[0], Q_HI[1]]) == ["f_b0_Hz upper bound 1.2 f_ref", f"zeta_b upper bound {ZETA_B_RANGE[1]:g}"]
    # the physical range of the effective B2 damping contains both motor files' own B2 damping (0.0125, 0.0165)
    assert ZETA_B_RANGE[0] < 0.0125 < 0.0165 < ZETA_B_RANGE[1]


@pytest.mark.parametrize("drive_law", ["pure_slip", "eq29"])
def test_response_jacobian_matches_the_chain_rule_through_the_force_factor(drive_law):
    # reference: a run's residuals depend on the response only through B'(s) V0 g(f_run) (the drive term and, in
    # the pure-slip family, the tip speed of the slip ratio), so dr/dq = (J_beta beta) d ln g(f)/dq, with
    # ln g = ln f - 0.5 ln((1 - r^2)^2 + (2 zeta r)^2) - (the same at f_ref), r = f/(q0 f_ref), zeta = exp(q1),
    # written out here; J_beta is the problem's analytic Jacobian in beta. The identification's central
    # differences in q (ResponseLinearisation.jacobian_q) must agree column by column.
    truth = FrequencyResponse(F_REF, 47800.0, 0.0125)
    prm, df = _slip_world(truth, drive_law)
    q = np.array([47900.0 / F_REF, math.log(0.015)])
    est = PredictorIdentifier(order=2, fixed="recommended", n_starts=1, seed=0, model=drive_law,
                              frequency=response_of(F_REF, q)).fit(df, slider_mass_kg=M_S)
    lin = ResponseLinearisation(est.result_, df, None, F_REF, q)
    prob = lin.problem(q)
    res = est.result_
    n1 = 3
    beta_cols = np.arange(5 + n1, 5 + 2 * n1)
    dr_dlng = (prob.jacobian(res.values, beta_cols) @ res.values[beta_cols]) * lin.w
    f = df["frequency_Hz"].to_numpy()[prob.sample_sel]

    def dlnH(f):
        r, z = f / (q[0] * F_REF), math.exp(q[1])
        D = (1 - r * r) ** 2 + (2 * z * r) ** 2
        dD_dr = -4 * r * (1 - r * r) + 8 * z * z * r
        return np.column_stack([-0.5 * dD_dr * (-r / q[0]) / D, -0.5 * 8 * z * z * r * r / D])
    want = dr_dlng[:, None] * (dlnH(f) - dlnH(np.array([F_REF])))
    got = lin.jacobian_q()
    scale = np.abs(want).max(axis=0)
    assert np.all(scale > 0)
    assert np.abs(got - want).max(axis=0).max() < 2e-3 * scale.max(), np.abs(got - want).max(axis=0) / scale


def _fitted(truth):
    """A one-start pure-slip fit (order 2, recommended pins) on the family's own world with response ``truth``."""
    _, df = _slip_world(truth)
    est = PredictorIdentifier(order=2, fixed="recommended", n_starts=1, seed=0, model="pure_slip").fit(
        df, slider_mass_kg=M_S)
    return est


@pytest.mark.slow
def test_pure_slip_recovers_its_frequency_response():
    # reference: the pure-slip family's own traverses with B2 at 47.8 kHz, zeta 0.0125 over 48.0-49.0 kHz: the
    # joint estimate lies within 4 standard errors of it or within the Gauss-Newton's stopping step (2e-5 f_ref,
    # 0.01 in ln zeta_b; on these nearly exact data the standard errors are smaller), and is not at a bound
    truth = FrequencyResponse(F_REF, 47800.0, 0.0125)
    est = _fitted(truth)
    rec = est.result_.frequency
    got, se = rec["response"], rec["stderr"]
    print("recovered", got, se)
    assert rec["status"] == "estimated" and rec["at_bound"] == []
    assert abs(got["f_b0_Hz"] - 47800.0) <= max(4 * se["f_b0_Hz"], 2e-5 * F_REF)
    assert abs(math.log(got["zeta_b"] / 0.0125)) <= max(4 * se["zeta_b"] / 0.0125, 0.01)


@pytest.mark.slow
def test_a_response_beyond_the_physical_damping_ends_at_its_bound_and_says_so():
    # reference: the same world with zeta_b 0.002 (Q 250, below ZETA_B_RANGE): the estimate stops at the lower
    # bound, the record and the fit report name it, and zeta_b gets no standard error
    truth = FrequencyResponse(F_REF, 47800.0, 0.002)
    est = _fitted(truth)
    rec = est.result_.frequency
    print("at bound", rec["response"], rec["stderr"], rec["at_bound"])
    assert rec["response"]["zeta_b"] == pytest.approx(ZETA_B_RANGE[0], rel=2e-3)
    assert rec["at_bound"] == [f"zeta_b lower bound {ZETA_B_RANGE[0]:g}"]
    assert "zeta_b" not in (rec["stderr"] or {})
    assert "AT A BOUND" in est.fit_report()
