"""The realistic world's close-the-loop cases and their checks, shared by the realistic close-loop modules.

On the realistic motor (``system_models/realistic_motor.toml``) the baseline itself has a structural error of a
few %, so a gate like "removes half of the held-out residual" cannot work; what is checked instead, on TEST
(never used for fitting or choosing):

* with an injected effect (:func:`check_effects`): the right regressor among the first traced, and the held-out
  free-run error cut by at least half of the *excess* over the clean world's baseline, in quadrature:
  ``a^2 <= b0^2 + (b^2 - b0^2)/4`` (b: baseline, a: extended, b0: baseline of the same seed without the effect);
* without one (:func:`check_control`): the held-out free-run nrmse never more than 2 % (relative) above the
  baseline; what was added is reported.

The loops and the clean baselines are cached per test process (``functools.cache``), so modules that run on the
same pytest-xdist worker share them.
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


def case_dir(effects, seed, record_temperature=False):
    """The rig folder of a realistic case: ``effects`` injected (none: the clean world) at ``seed``."""
    name = "+".join(effects) or "clean"
    plan = dataclasses.replace(world_plan(WORLD, seed), record_temperature=record_temperature)
    return rig_dir(f"{WORLD}_{name}_{seed}{'_T' if record_temperature else ''}", injections=list(effects),
                   injection_seed=seed, plan=plan, world=WORLD)


@functools.cache
def run_case(effects: tuple, seed: int, record_temperature: bool = False):
    """``(result, truth)``: the close loop on a case's TRAIN and TEST files, and the rig's ``rig_truth.json``."""
    d = case_dir(effects, seed, record_temperature)
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    assert_round_trips(res)
    truth = json.loads((d / "rig_truth.json").read_text())
    return res, truth


@functools.cache
def clean_baseline(seed: int) -> float:
    """b0: the baseline's held-out free-run nrmse on the same seed's data without any effect."""
    d = case_dir((), seed)
    tr, te = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    est = PredictorIdentifier(order=8, criterion="free_run", fixed="recommended", n_starts=4, seed=0,
                              noise_fit="alternate")  # the loop's baseline search
    est.fit(tr.df, slider_mass_kg=tr.slider_mass_kg, mask=np.array(tr.mask))
    return report_metrics(te.df, est.predict_one_step(te.df), est.predict_free_run(te.df))["free_run"]["nrmse"]


def check_effects(res, truth, seed, n_first, record, want=None, case=""):
    """The injected case's checks: significant, each wanted regressor among the first ``n_first`` traced, and
    ``a^2 <= b0^2 + (b^2 - b0^2)/4`` on TEST; the case's row is recorded (``record_property``)."""
    want = want or [i["regressor"] for i in truth["injections"]]
    d = res.diagnosis
    b, a = held_out_nrmse(res)
    b0 = clean_baseline(seed)
    record("case", case_row(WORLD, case or "+".join(i["name"] for i in truth["injections"]) + f" {seed}", res, b0))
    assert d["significant"], d["message"]
    for w in want:
        assert w in d["traced_to"][:n_first], (want, d["traced_to"], d["message"])
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a, d["message"])


def check_control(res, case, record):
    """The control's checks: TEST free-run nrmse at most 2 % (relative) above the baseline's, and what was added
    reported round by round; the case's row is recorded (``record_property``)."""
    record("case", case_row(WORLD, case, res))
    b, a = held_out_nrmse(res)
    assert a <= 1.02 * b, (b, a, res.diagnosis["message"])
    d = res.diagnosis
    assert len(d["effects"]) == len(res.rounds) - 1
    assert (res.extended is None) == (not d["effects"])


def known_miss(why: str):
    """A case the loop is known to miss (a detection-power limit, measured): strict, so a pass is noticed too."""
    return pytest.mark.xfail(strict=True, raises=AssertionError, reason=why)


def machine_borderline(why: str):
    """A case whose verdict differs between machines' BLAS builds with the same packages (decision 0129): it
    passes on some and misses on others, so both are accepted (non-strict) and the case still runs."""
    return pytest.mark.xfail(strict=False, raises=AssertionError, reason=why)
