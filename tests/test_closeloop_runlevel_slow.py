"""Realistic world, the run-level rig injections (issue 28): an effect through an auxiliary logged channel and an
effect that differs between runs but not along the stroke, each at three seeds and three sizes of the plan.

``supply_sag``: the drive's DC bus differs from run to run and the amplifier's output follows it; the rig logs the
bus as ``supply_V``, a column whose physics no part of the loop names. ``preload_settling``: the clamp's preload
falls traverse by traverse (not logged), constant along each stroke. The checks are the realistic world's
(``tests/realistic_cases.py``): the right regressor (``supply_V``; the session clock, ``time``) among the
first two traced, and on TEST ``a^2 <= b0^2 + (b^2 - b0^2)/4`` (b: baseline, a: final, b0: the same seed and plan
without the effect). Sizes: the paper's four voltages (72 runs), three (54 runs) and five (90 runs). Measured
figures: ``docs/decisions/0018-run-level-evidence.md``. Slow: ``make test-slow`` runs it (decision 0095).
"""

import dataclasses
import functools
import json

import numpy as np
import pytest
from l1b2.closeloop.loop import close_loop
from l1b2.data.measurements import load_measurements
from l1b2.data.metrics import report_metrics
from l1b2.ident.estimator import PredictorIdentifier
from rigcache import assert_round_trips, case_row, held_out_nrmse, rig_dir, world_plan

WORLD = "realistic"
SIZES = {72: (220.0, 255.0, 290.0, 324.0), 54: (220.0, 290.0, 324.0), 90: (220.0, 255.0, 290.0, 307.0, 324.0)}


def _dir(effects, seed, runs):
    plan = dataclasses.replace(world_plan(WORLD, seed), voltages_V=SIZES[runs])
    name = "+".join(effects) or "clean"
    return rig_dir(f"{WORLD}_{name}_{seed}_{runs}", injections=list(effects), injection_seed=seed, plan=plan,
                   world=WORLD)


@functools.cache
def _clean_baseline(seed: int, runs: int) -> float:
    d = _dir((), seed, runs)
    tr, te = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=4, seed=0,
                              noise_fit="alternate")  # the loop's baseline search
    est.fit(tr.df, slider_mass_kg=tr.slider_mass_kg, mask=np.array(tr.mask))
    return report_metrics(te.df, est.predict_one_step(te.df), est.predict_free_run(te.df))["free_run"]["nrmse"]


def _known_miss(why: str):
    """A case the loop is known to miss (measured): strict, so a pass is noticed too."""
    return pytest.mark.xfail(strict=True, raises=AssertionError, reason=why)


CASES = [("supply_sag", 41, 72), ("supply_sag", 42, 54), ("supply_sag", 43, 90),
         ("preload_settling", 41, 72),
         pytest.param("preload_settling", 42, 54, marks=_known_miss(
             "time not traced: the settling's excess over the clean world is small (b 3.54 % vs b0 3.35 %); only "
             "run_level_voltage_V added (3.54 -> 1.94 %, the error check holds)")),
         ("preload_settling", 43, 90)]


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed,runs", CASES)
def test_realistic_run_level_injection(effect, seed, runs, record_property):
    d = _dir((effect,), seed, runs)
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    assert_round_trips(res)
    truth = json.loads((d / "rig_truth.json").read_text())
    want = truth["injections"][0]["regressor"]
    b, a = held_out_nrmse(res)
    b0 = _clean_baseline(seed, runs)
    dg = res.diagnosis
    record_property("case", case_row(WORLD, f"{effect} {seed} ({runs} runs)", res, b0))
    considered = {c["channel"] for c in dg["channels_considered"]}
    assert {"time_s", "voltage_V", "load_kg", "direction"} <= considered
    if effect == "supply_sag":
        assert "supply_V" in considered
    assert dg["significant"], dg["message"]
    assert want in dg["traced_to"][:2], (want, dg["traced_to"], dg["message"])
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a, dg["message"])
