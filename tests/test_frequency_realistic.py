"""The drive frequency on the realistic world: held-out error of data spread over +-500 Hz (slow).

Three seeds of the realistic motor's rig (1 mm/s speed noise, 2 % run scatter) recorded at 48.0, 48.25,
48.5, 48.75 and 49.0 kHz with a +-50 Hz per-run offset (a drive that tracks resonance), against the same
plan at 48.5 kHz only. Measured figures: docs/decisions/0017-drive-frequency-input.md and
docs/decisions/0024-frequency-response-form-and-joint-estimation.md.
"""

import dataclasses

import pytest
from l1b2.data.measurements import load_measurements
from l1b2.data.metrics import report_metrics
from l1b2.ident.estimator import PredictorIdentifier
from rigcache import rig_dir, world_plan

FREQS = (48000.0, 48250.0, 48500.0, 48750.0, 49000.0)
SEEDS = (1, 2, 3)


def _held_out(seed: int, multi: bool, frequency="auto") -> tuple[float, dict | None]:
    plan = world_plan("realistic", seed)
    if multi:
        plan = dataclasses.replace(plan, frequencies_Hz=FREQS, frequency_jitter_Hz=50.0)
    d = rig_dir(f"realistic_freq_{'multi' if multi else 'single'}_{seed}", plan=plan, world="realistic")
    tr, te = load_measurements(d / "train.csv"), load_measurements(d / "test.csv")
    est = PredictorIdentifier(order=8, fixed="recommended", n_starts=4, seed=0, frequency=frequency).fit(tr)
    m = report_metrics(te.df, est.predict_one_step(te), est.predict_free_run(te))
    return m["free_run"]["nrmse"], est.result_.frequency


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
def test_frequency_response_recovers_most_of_the_held_out_error(seed):
    # reference: the same identification without the response (frequency="off") on the multi-frequency data,
    # and the single-frequency figure of the same seed; measured (seeds 1-3): off 97 / 14 / 34 %, estimated
    # 3.7 / 5.2 / 4.2 %, single 3.0 / 2.8 / 3.2 %
    single, rec1 = _held_out(seed, False)
    multi, rec = _held_out(seed, True)
    off, _ = _held_out(seed, True, frequency="off")
    assert rec1["status"] == "fixed" and rec["status"] == "estimated"
    assert multi < off / 2
    assert multi < 2.0 * single


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured held-out ratios multi/single 1.22, 1.84, 1.29 (seeds 1-3, joint "
                   "estimate): in the coupled physics the frequency acts on the B2 drive only, Eq. 29's V0 g(f) "
                   "scales the contact's share of V0 too, and Eq. 29 refitted at each frequency is itself 3.7 % "
                   "(5.4 % near L1) off the physics (decision 0024); the pure-slip family with its response reaches "
                   "3.10 / 2.66 / 3.34 % but 1.53 / 1.33 / 2.11 x its own single figure (decision 0029). Its TEST "
                   "error is a frequency x V0 shape (too slow at 48.25 kHz, too fast at 48.75 kHz and at 220 V); "
                   "against the physics' steady speeds the L1 contact law lowers the law's error from 2.60 to "
                   "2.05 %, but the pure-slip form fitted at each frequency alone is already 2.2-2.5 % off near "
                   "49 kHz against 0.7-1.0 % at 48.5 kHz (decision 0034). Wired into the identification "
                   "(frequency='contact', V0- and frequency-dependent contact angle, decision 0038) the law lowers "
                   "the held-out error to 2.53 / 2.50 / 3.22 %, ratios 1.25 / 1.24 / 2.03: still above 1.2")
def test_held_out_error_within_1_2_of_the_single_frequency_figure():
    ratios = [_held_out(s, True)[0] / _held_out(s, False)[0] for s in SEEDS]
    assert max(ratios) <= 1.2
