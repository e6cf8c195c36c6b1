"""A lag's accepted refit is checked on the session's blocks (``acceptance.session_curve``, ``block_checked``,
``CloseLoop._trials``)."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.loop import CloseLoop
from l1b2.predictor import effects as fx

SS = np.full(4, 1.0)
CUR = acc.FoldErrors(np.array([0.04, 0.07, 0.10, 0.10]), SS)
RULES = {"min_gain": 0.03, "min_drop": 0.0}


def _train():
    chan = [{"name": n, "kind": "logged", "mean": 1.0, "sd": 0.3, "within_run": False}
            for n in ("aux", "aux_lag10r", "lag3r_aux", "aux_since_s")]
    return fx.TrainingSummary(m_s=0.12, time_range=(0.0, 300.0), position_range=(-0.012, 0.012),
                              voltage_median=270.0, ranges={"t_lo": 0.0, "t_hi": 300.0, "s_lo": -0.012,
                                                            "s_hi": 0.012, "V_lo": 220.0, "V_hi": 324.0,
                                                            "load_abs": 0.09, "v_lo": 0.0, "v_hi": 0.3},
                              channels=tuple(chan))


def _cands(kind):
    return [CandidateForce(h.family, h.regressor, h.shape, h.names, h.units, None, also=h.also, spec=h.spec)
            for h in fx.family(kind).grid(_train())]


def test_a_session_curve_is_a_lags_form_and_not_a_clocks():
    chan = {}
    for c in _cands("channel") + _cands("run_level"):
        chan.setdefault(c.spec["channel"], set()).add(acc.session_curve(c))
    # every form of the lag, none of a plain channel, of a name that only holds the word, or of the clocks
    assert chan["aux_lag10r"] == {True} and chan["aux"] == {False} and chan["lag3r_aux"] == {False}
    assert chan["aux_since_s"] == {False} and chan["time_s"] == {False}        # already on the blocks
    assert not any(acc.session_curve(c) for c in _cands("smooth") + _cands("load_path_friction"))
    assert not acc.session_curve(CandidateForce("x", "aux_lag3r", "", ("a",), ("N",), None))   # no spec


def _trial(cand, ext, failed=0):
    return acc.RefitCV(cand, CUR, acc.FoldErrors(np.asarray(ext, float), SS, failed=failed))


GOOD = [0.03, 0.05, 0.08, 0.09]      # 4 of 4 folds, gain ~0.3: accepted
BAD = [0.05, 0.08, 0.09, 0.12]       # 1 of 4 folds: refused


def _lag(form="run_level"):
    return next(c for c in _cands(form) if c.spec["channel"] == "aux_lag10r")


def _plain():
    return next(c for c in _cands("run_level") if c.spec["channel"] == "aux")


def test_block_checked_replaces_only_an_accepted_lag_trial_that_fails_on_the_blocks():
    lag, refused_lag, plain = _trial(_lag(), GOOD), _trial(_lag("channel"), BAD), _trial(_plain(), GOOD)
    assert acc.accepts(lag, **RULES) and not acc.accepts(refused_lag, **RULES) and acc.accepts(plain, **RULES)
    trials = [plain, lag, None, refused_lag]
    asked = []

    def on_blocks(which, ext):
        asked.append(list(which))
        return [_trial(trials[i].candidate, ext) for i in which]
    out = acc.block_checked(trials, lambda t: RULES, lambda w: on_blocks(w, BAD))
    assert asked == [[1]]                                # the accepted lag only
    assert out[0] is plain and out[2] is None and out[3] is refused_lag
    assert out[1] is not lag and not acc.accepts(out[1], **RULES)     # refused, recorded with its blocks' errors
    assert np.array_equal(out[1].extended.sse, BAD)
    kept = acc.block_checked(trials, lambda t: RULES, lambda w: on_blocks(w, GOOD))
    assert kept[1] is lag                                # passes on the blocks: the run folds' trial stays
    assert acc.block_checked([plain, None], lambda t: RULES, lambda w: pytest.fail("no lag to check")) == [plain, None]


class _Recorder(CloseLoop):
    """``_cross_validate`` answering from given fold errors by candidate label, recording each call's schemes."""

    def __init__(self, answers, **kw):
        super().__init__(**kw)
        self.answers, self.calls = answers, []

    def _cross_validate(self, it, short, cur, cur_err, schemes, r, dtr, mask, m_s, v_cur, say, n_rnd,
                        key=acc.time_dependent):
        self.calls.append(({k: len(v) for k, v in schemes.items()}, [s.candidate.label for s in short]))
        for blocked in schemes:
            cur_err.setdefault(blocked, CUR)
        return [acc.FoldErrors(np.asarray(self.answers[(s.candidate.label, key(s.candidate))], float), SS)
                if key(s.candidate) in schemes else None for s in short]


def _run_trials(short, on_blocks):
    """``(loop, trials)``: ``CloseLoop._trials`` on ``short`` (the plain channel and the lag) over four run folds
    and three session blocks, both accepted over the run folds and the lag's blocks' errors ``on_blocks``."""
    plain, lag = (s.candidate for s in short)
    runs = np.repeat(np.arange(16), 5)
    df = pd.DataFrame({"run": runs, "direction": np.where(runs % 2, 1, -1), "voltage_V": 200.0,
                       "load_kg": 0.0, "time_s": np.arange(len(runs)) * 1e-3})
    answers = {(plain.label, False): GOOD, (lag.label, False): GOOD, (lag.label, True): on_blocks}
    loop = _Recorder(answers, refit_folds=4, tie_repeats=1)
    out = loop._trials(None, short, None, {}, {False: [None] * 4, True: [None] * 3}, (None, df, None, 0.1, None),
                       lambda *a: None, 1)
    return loop, out


def test_the_loop_checks_a_lags_accepted_refit_on_the_session_blocks():
    lag, plain = _lag(), _plain()
    short = [SimpleNamespace(candidate=c, cv_gain=0.1, phi=np.zeros(1), origin="screen") for c in (plain, lag)]
    for on_blocks, accepted in ((BAD, False), (GOOD, True)):
        loop, out = _run_trials(short, on_blocks)
        assert loop.calls == [({False: 4, True: 3}, [plain.label, lag.label]), ({True: 3}, [lag.label])]
        assert acc.accepts(out[0], **loop._rules(out[0]))
        assert acc.accepts(out[1], **loop._rules(out[1])) == accepted


def test_each_trial_records_why_the_round_refit_it_also_when_the_blocks_replace_it():
    # the score's origin (selection.ORIGINS) goes to its trial and to report.json's offered_by, whichever folds
    # the trial was last refit on
    from l1b2.closeloop.selection import ORIGINS
    lag, plain = _lag(), _plain()
    short = [SimpleNamespace(candidate=plain, cv_gain=0.1, phi=np.zeros(1), origin="carried"),
             SimpleNamespace(candidate=lag, cv_gain=0.1, phi=np.zeros(1), origin="run_level")]
    for on_blocks in (BAD, GOOD):
        _, out = _run_trials(short, on_blocks)
        assert [t.origin for t in out] == ["carried", "run_level"]
        assert [t.to_dict()["offered_by"] for t in out] == ["carried", "run_level"]
    assert acc.RefitCV(plain, CUR, CUR).to_dict()["offered_by"] == "screen" and set(ORIGINS) >= {"screen", "carried"}
