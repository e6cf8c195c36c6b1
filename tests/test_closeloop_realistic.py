"""Close the loop where Eq. 29 is NOT exact (issue 11): the realistic motor variant, its single effects.

The checks (``tests/realistic_cases.py``), on TEST (never used for fitting or choosing): with an injected effect,
the right regressor among the first traced and ``a^2 <= b0^2 + (b^2 - b0^2)/4`` (b: baseline, a: extended, b0:
baseline of the same seed without the effect); without one (control), the held-out free-run nrmse never more than
2 % (relative) above the baseline, and what was added reported.

Fast set (``make test``): one control seed, a control with a logged constant temperature and the speed-channel
detector, and the slow cases marked ``ci_slow``: one seed of four single effects (the other seeds and kinds, the
logged-temperature case and the measurement-chain case, a strict xfail, with ``make test-slow``). The pairs, the
ten control seeds and the command line's report are in ``test_closeloop_realistic_pairs.py`` and
``test_closeloop_realistic_controls.py``: whole modules are what ``make test``'s two workers share out
(``tests/conftest.py``, ``COSTLY_FIRST``). The cases the loop is known to miss are strict xfails with their
measured reasons, so that a pass is noticed. Each case's figures are recorded (``pytest --junitxml=F``, then
``python bench/case_table.py F``); what was measured, session by session:
``docs/decisions/0005-realistic-world-close-loop-checks.md``.
"""

import numpy as np
import pytest
from l1b2.data.measurements import load_measurements
from realistic_cases import case_dir, check_control, check_effects, machine_borderline, run_case


@pytest.mark.parametrize("seed", [21])
def test_realistic_control_is_never_made_worse(seed, record_property):
    res, _ = run_case((), seed)
    check_control(res, f"clean {seed}", record_property)


def test_realistic_control_with_a_logged_temperature(record_property):
    # reference: issue 11's control rule; the optional temperature_C column of an unheated stator (constant) gives
    # no temperature term and no failure
    res, _ = run_case((), 21, record_temperature=True)
    check_control(res, "clean 21, temperature logged", record_property)
    assert "temperature" not in res.diagnosis["traced_to"]


@pytest.mark.slow    # a logged channel traced (decision 0054); make test-slow (0131)
def test_realistic_logged_temperature_is_traced(record_property):
    # reference: issue 11's check, with the stator temperature logged (data format's temperature_C): the
    # self-heating drift is traced to the temperature among the first two, and the held-out cut in quadrature
    res, truth = run_case(("thermal_drift",), 12, record_temperature=True)
    check_effects(res, truth, 12, 2, record_property, want=["temperature"],
                  case="thermal_drift 12, temperature logged")


#: bar_bump 8's named reading (bar_waviness, 8 parameters) lies at the identifiability threshold: on some BLAS
#: builds its joint covariance has no finite block (no Wald statistic), the reading is refused as not identified
#: and position is not traced (decision 0129); a non-strict xfail, so that both machines' outcomes are accepted
#: and the case still runs
BORDERLINE = machine_borderline("named reading at the identifiability threshold on some BLAS builds (0129)")
#: one seed of four kinds runs in ``make test`` (``ci_slow``); the other seeds and kinds and the borderline bar_bump 8
#: run with ``make test-slow`` (decision 0131: ``make test``'s time on a slower machine)
CI = pytest.mark.ci_slow
SINGLE = [("thermal_drift", 4), pytest.param("direction_asymmetry", 2, marks=CI),
          pytest.param("bar_waviness", 2, marks=CI), pytest.param("pulley_friction", 11, marks=CI),
          pytest.param("drive_saturation", 3, marks=CI), ("thermal_drift", 12), ("direction_asymmetry", 13),
          pytest.param("bar_bump", 8, marks=BORDERLINE),
          ("drive_saturation", 11), ("drive_saturation", 12), ("speed_lowpass", 11)]


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed", SINGLE)
def test_realistic_single_effect(effect, seed, record_property):
    res, truth = run_case((effect,), seed)
    check_effects(res, truth, seed, 2, record_property)


def test_measurement_chain_filter_is_found_from_position_and_speed_alone():
    # reference: issue 11 (measurement chain): a first-order low-pass on the speed column is detected by
    # comparing it with the position's derivative per run, cross-validated over runs; a clean column is not
    from l1b2.closeloop.chain import speed_channel
    from l1b2.rig.experiment import lowpass_speed
    m = load_measurements(case_dir((), 21) / "train.csv")
    mask = np.array(m.mask)
    assert not speed_channel(m.df, mask)["accepted"]
    tau, dt = 5e-3, 1e-3
    ch = speed_channel(lowpass_speed(m.df, tau), mask)
    assert ch["accepted"] and ch["cv_gain"] > 0.9
    assert ch["filter"].a == pytest.approx(np.exp(-dt / tau), abs=0.02)
    assert ch["filter"].to_dict()["dc_gain"] == pytest.approx(1.0, abs=0.02)


@pytest.mark.slow    # decision 0080; make test-slow (0131)
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="the issue's check passes (speed traced first, TEST 3.03 -> 1.98 %), but the filter is "
                   "refused: its cross-validated free-run nrmse 4.19 % vs the baseline's 4.15 %")
def test_realistic_measurement_chain_effect(record_property):
    res, truth = run_case(("speed_lowpass",), 8)
    check_effects(res, truth, 8, 2, record_property)
    assert res.diagnosis["measurement_chain"]["accepted"]
