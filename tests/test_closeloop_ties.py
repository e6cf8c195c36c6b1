"""A tied fold vote is decided over more splits of the same runs (``acceptance.tied``, ``CloseLoop._trials``)."""

from types import SimpleNamespace

import numpy as np
import pytest
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.loop import CloseLoop

SS = np.full(4, 1.0)
CUR = acc.FoldErrors(np.array([0.043046, 0.075053, 0.102513, 0.104179]), SS)


def _trial(ext, label="run_level_category(fixture_id)", failed=0, regressor="fixture_id"):
    c = CandidateForce(label, regressor, "", ("a",), ("N",), features=None)
    return acc.RefitCV(c, CUR, acc.FoldErrors(np.asarray(ext, float), SS, failed=failed))


def test_a_tie_is_every_rule_met_but_the_majority_with_exactly_half_the_folds_improved():
    # reference: 0061's fixture_station 3 refit (folds 1 and 4 rose: 2 of 4, gain 0.117) is the tie
    two = _trial([0.043278, 0.045316, 0.077175, 0.121022])
    assert two.folds_improved == 2 and two.gain == pytest.approx(1 - 0.286791 / 0.324791, abs=1e-6)
    assert acc.tied(two, min_gain=0.03, min_drop=0.0) and not acc.accepts(two, min_gain=0.03, min_drop=0.0)
    three = _trial([0.043, 0.045316, 0.077175, 0.121022])          # 3 of 4: accepted, not a tie
    assert not acc.tied(three, min_gain=0.03, min_drop=0.0) and acc.accepts(three, min_gain=0.03, min_drop=0.0)
    one = _trial([0.05, 0.045316, 0.11, 0.121022])                   # 1 of 4: refused, not a tie
    assert one.folds_improved == 1 and not acc.tied(one, min_gain=-1.0, min_drop=-1.0)
    assert not acc.tied(two, min_gain=0.2, min_drop=0.0)            # the gain rule still holds
    drop = CUR.nrmse - two.extended.nrmse
    assert acc.tied(two, min_gain=0.03, min_drop=0.99 * drop) and not acc.tied(two, min_gain=0.03,
                                                                                 min_drop=1.01 * drop)
    assert not acc.tied(_trial(two.extended.sse, failed=1), min_gain=0.03, min_drop=0.0)


class _Recorder(CloseLoop):
    """``_cross_validate`` replaced by given fold errors per call (each call records its schemes)."""

    def __init__(self, answers, **kw):
        super().__init__(**kw)
        self.answers, self.calls = list(answers), []

    def _cross_validate(self, it, short, cur, cur_err, schemes, *rest):
        self.calls.append({k: len(v) for k, v in schemes.items()})
        errs = self.answers.pop(0)
        for blocked in schemes:
            cur_err[blocked] = CUR if blocked not in cur_err else cur_err[blocked]
        return [errs[i] if acc.time_dependent(s.candidate) in schemes else None for i, s in enumerate(short)]


def _short(*trials):
    return [SimpleNamespace(candidate=t.candidate, cv_gain=0.1, phi=np.zeros(1), origin="screen") for t in trials]


def _frame():
    runs = np.repeat(np.arange(16), 5)
    import pandas as pd
    df = pd.DataFrame({"run": runs, "direction": np.where(runs % 2, 1, -1), "voltage_V": 200.0 + 20 * (runs % 4),
                       "load_kg": 0.0, "time_s": np.arange(len(runs)) * 1e-3})
    return (None, df, None, 0.1, None)


def test_a_tied_round_is_cross_validated_again_over_tie_repeats_splits_run_folds_only():
    tie = _trial([0.043278, 0.045316, 0.077175, 0.121022])
    clock = _trial([0.043278, 0.045316, 0.077175, 0.121022], label="channel_time_s", regressor="time")
    assert acc.time_dependent(clock.candidate) and not acc.time_dependent(tie.candidate)
    again = acc.FoldErrors(np.full(12, 0.01), np.full(12, 1.0), repeats=3)
    short = _short(tie, clock)
    loop = _Recorder([[tie.extended, clock.extended], [again, None]], refit_folds=4, tie_repeats=3)
    out = loop._trials(None, short, None, {}, {False: [None] * 4, True: [None] * 4}, _frame(), lambda *a: None, 1)
    assert loop.calls == [{False: 4, True: 4}, {False: 12}]           # the run folds again, over 3 x 4 folds
    assert out[0].extended is again and out[0].current is CUR and out[1] is not None
    assert out[1].extended is clock.extended                         # the clock's trial is the round's own
    # off when tie_repeats is not above refit_repeats, and no second pass when nothing ties
    for kw, first in (({"tie_repeats": 1}, [tie.extended, clock.extended]),
                      ({"tie_repeats": 3}, [acc.FoldErrors(np.full(4, 0.01), SS), clock.extended])):
        loop = _Recorder([first], refit_folds=4, **kw)
        loop._trials(None, short, None, {}, {False: [None] * 4, True: [None] * 4}, _frame(), lambda *a: None, 1)
        assert loop.calls == [{False: 4, True: 4}]
    # a tie of the clock candidate alone is not re-run (its session folds are one split)
    loop = _Recorder([[acc.FoldErrors(np.full(4, 0.2), SS), clock.extended]], refit_folds=4, tie_repeats=3)
    loop._trials(None, short, None, {}, {False: [None] * 4, True: [None] * 4}, _frame(), lambda *a: None, 1)
    assert loop.calls == [{False: 4, True: 4}]
