"""Close the loop where Eq. 29 is NOT exact (issue 11): the realistic motor variant.

On the realistic motor (``system_models/realistic_motor.toml``) the baseline
itself has a structural error of a few %, so a gate like "removes half of the
held-out residual" cannot work; what is checked instead, on TEST (never used
for fitting or choosing):

* with an injected effect: the right regressor among the first traced, and
  the held-out free-run error cut by at least half of the *excess* over the
  clean world's baseline, in quadrature: ``a^2 <= b0^2 + (b^2 - b0^2)/4``
  (b: baseline, a: extended, b0: baseline of the same seed without the effect);
* without one (control): the held-out free-run nrmse never more than 2 %
  (relative) above the baseline; what was added is reported.

Fast set (``make test``): one control seed, a control with a logged constant temperature and the
speed-channel detector, and the slow cases marked ``ci_slow``: the eleven single effects (decision 0074) and
the logged-temperature case (a logged channel traced, decision 0054). Slow set (``make test-slow``, not in CI:
it does not fit CI's time): ten control seeds, pairs of effects (the pair drive_saturation + bar_waviness 10 included: in CI in decision 0054, out again by its
update, to keep ``make test`` under its budget), the load-path report. The
cases the loop is known to miss are strict xfails with their measured reasons, so that a pass is noticed.
Each case's figures are recorded (``pytest --junitxml=F``, then ``python bench/case_table.py F``); what
was measured, session by session: ``docs/decisions/0005-realistic-world-close-loop-checks.md``.
"""

import dataclasses
import functools
import json

import numpy as np
import pytest
from l1b2.cli import main as cli_main
from l1b2.closeloop.loop import close_loop
from l1b2.data.measurements import load_measurements
from l1b2.data.metrics import report_metrics
from l1b2.ident.estimator import PredictorIdentifier
from rigcache import assert_round_trips, case_row, held_out_nrmse, rig_dir, world_plan

WORLD = "realistic"


def _dir(effects, seed, record_temperature=False):
    name = "+".join(effects) or "clean"
    plan = dataclasses.replace(world_plan(WORLD, seed), record_temperature=record_temperature)
    return rig_dir(f"{WORLD}_{name}_{seed}{'_T' if record_temperature else ''}", injections=list(effects),
                   injection_seed=seed, plan=plan, world=WORLD)


@functools.cache
def _run(effects: tuple, seed: int, record_temperature: bool = False):
    d = _dir(effects, seed, record_temperature)
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    assert_round_trips(res)
    truth = json.loads((d / "rig_truth.json").read_text())
    return res, truth


@functools.cache
def _clean_baseline(seed: int) -> float:
    """b0: the baseline's held-out free-run nrmse on the same seed's data without any effect."""
    d = _dir((), seed)
    tr, te = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=4, seed=0,
                              noise_fit="alternate")  # the loop's baseline search
    est.fit(tr.df, slider_mass_kg=tr.slider_mass_kg, mask=np.array(tr.mask))
    return report_metrics(te.df, est.predict_one_step(te.df), est.predict_free_run(te.df))["free_run"]["nrmse"]


def _check_effects(res, truth, seed, n_first, record, want=None, case=""):
    want = want or [i["regressor"] for i in truth["injections"]]
    d = res.diagnosis
    b, a = held_out_nrmse(res)
    b0 = _clean_baseline(seed)
    record("case", case_row(WORLD, case or "+".join(i["name"] for i in truth["injections"]) + f" {seed}", res, b0))
    assert d["significant"], d["message"]
    for w in want:
        assert w in d["traced_to"][:n_first], (want, d["traced_to"], d["message"])
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a, d["message"])


def _check_control(res, case, record):
    record("case", case_row(WORLD, case, res))
    b, a = held_out_nrmse(res)
    assert a <= 1.02 * b, (b, a, res.diagnosis["message"])
    d = res.diagnosis
    # what was added (if anything) is reported, round by round
    assert len(d["effects"]) == len(res.rounds) - 1
    assert (res.extended is None) == (not d["effects"])


@pytest.mark.parametrize("seed", [21])
def test_realistic_control_is_never_made_worse(seed, record_property):
    res, _ = _run((), seed)
    _check_control(res, f"clean {seed}", record_property)


def test_realistic_control_with_a_logged_temperature(record_property):
    # reference: issue 11's control rule; the optional temperature_C column of an unheated stator (constant) gives
    # no temperature term and no failure
    res, _ = _run((), 21, record_temperature=True)
    _check_control(res, "clean 21, temperature logged", record_property)
    assert "temperature" not in res.diagnosis["traced_to"]


@pytest.mark.slow
@pytest.mark.ci_slow    # a logged channel traced (decision 0054)
def test_realistic_logged_temperature_is_traced(record_property):
    # reference: issue 11's check, with the stator temperature logged (data format's temperature_C): the
    # self-heating drift is traced to the temperature among the first two, and the held-out cut in quadrature
    res, truth = _run(("thermal_drift",), 12, record_temperature=True)
    _check_effects(res, truth, 12, 2, record_property, want=["temperature"],
                   case="thermal_drift 12, temperature logged")


@pytest.mark.slow
def test_realistic_control_ten_seeds(record_property):
    for seed in range(30, 40):
        _check_control(_run((), seed)[0], f"clean {seed}", record_property)


@pytest.mark.slow  # 399 s on the noisy rig (236 s without noise): `make test` took 16 min with it
def test_realistic_load_path_effect_report_rounds(tmp_path, capsys):
    # reference: issue 11: report.json gains diagnosis.effects and rounds; the CLI prints a table per round;
    # report.md shows each round; the held-out error cut in quadrature of the excess over the clean world
    d = _dir(("pulley_friction",), 1)
    out = tmp_path / "cl"
    assert cli_main(["close-loop", "--train", str(d / "train.csv"), "--test", str(d / "test.csv"),
                     "--report-dir", str(out), "--quiet", "--no-plots"]) == 0
    printed = capsys.readouterr().out
    assert "round" in printed and "CV gain" in printed
    rep = json.loads((out / "report.json").read_text())
    eff = rep["diagnosis"]["effects"]
    assert eff and rep["diagnosis"]["effect"] == eff[0]["effect"]
    assert "load" in rep["diagnosis"]["traced_to"][:2]
    for e in eff:
        assert e["regressors"] and e["cv_gain"] >= 0.03 and e["parameters"]
        assert all({"value", "stderr", "ci95", "unit"} <= set(p) for p in e["parameters"].values())
    rounds = rep["rounds"]
    assert rounds[0]["round"] == 0 and rounds[0]["added"] is None and len(rounds) == len(eff) + 1
    assert rep["extended"] == rounds[-1]["metrics"]
    md = (out / "report.md").read_text()
    assert "## Rounds" in md
    b = rep["baseline"]["test"]["free_run"]["nrmse"]
    a = rep["extended"]["test"]["free_run"]["nrmse"]
    b0 = _clean_baseline(1)
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a)


def _known_miss(why: str):
    """A case the loop is known to miss (a detection-power limit, measured): strict, so a pass is noticed too."""
    return pytest.mark.xfail(strict=True, raises=AssertionError, reason=why)


SINGLE = [("thermal_drift", 4), ("direction_asymmetry", 2), ("bar_waviness", 2), ("pulley_friction", 11),
          ("drive_saturation", 3), ("thermal_drift", 12), ("direction_asymmetry", 13), ("bar_bump", 8),
          ("drive_saturation", 11), ("drive_saturation", 12), ("speed_lowpass", 11)]


@pytest.mark.slow
@pytest.mark.ci_slow    # all eleven single effects (decision 0074)
@pytest.mark.parametrize("effect,seed", SINGLE)
def test_realistic_single_effect(effect, seed, record_property):
    res, truth = _run((effect,), seed)
    _check_effects(res, truth, seed, 2, record_property)


PAIRS = [(("pulley_friction", "drive_saturation"), 5),
         pytest.param(("direction_asymmetry", "thermal_drift"), 6, marks=_known_miss("time not traced")),
         (("bar_waviness", "pulley_friction"), 7), (("bar_bump", "direction_asymmetry"), 9),
         (("drive_saturation", "bar_waviness"), 10)]


@pytest.mark.slow
@pytest.mark.parametrize("effects,seed", PAIRS)
def test_realistic_two_effects(effects, seed, record_property):
    res, truth = _run(effects, seed)
    _check_effects(res, truth, seed, 3, record_property)


def test_measurement_chain_filter_is_found_from_position_and_speed_alone():
    # reference: issue 11 (measurement chain): a first-order low-pass on the speed column is detected by
    # comparing it with the position's derivative per run, cross-validated over runs; a clean column is not
    from l1b2.closeloop.chain import speed_channel
    from l1b2.rig.experiment import lowpass_speed
    m = load_measurements(_dir((), 21) / "train.csv")
    mask = np.array(m.mask)
    assert not speed_channel(m.df, mask)["accepted"]
    tau, dt = 5e-3, 1e-3
    ch = speed_channel(lowpass_speed(m.df, tau), mask)
    assert ch["accepted"] and ch["cv_gain"] > 0.9
    assert ch["filter"].a == pytest.approx(np.exp(-dt / tau), abs=0.02)
    assert ch["filter"].to_dict()["dc_gain"] == pytest.approx(1.0, abs=0.02)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="the issue's check passes (speed traced first, TEST 3.03 -> 1.98 %), but the filter is "
                   "refused: its cross-validated free-run nrmse 4.19 % vs the baseline's 4.15 %")
def test_realistic_measurement_chain_effect(record_property):
    res, truth = _run(("speed_lowpass",), 8)
    _check_effects(res, truth, 8, 2, record_property)
    assert res.diagnosis["measurement_chain"]["accepted"]
