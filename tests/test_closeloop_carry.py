"""What a round accepted and did not add, pointing elsewhere, is offered again in the next round
(``selection.to_carry``, ``selection.carried``)."""

import numpy as np
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.selection import Score, carried, refit_list, to_carry
from l1b2.predictor import effects as fx

SS = np.full(4, 1.0)
CUR = acc.FoldErrors(np.array([0.04, 0.07, 0.10, 0.10]), SS)


def _cand(family, *regressors):
    return CandidateForce(family, regressors[0], "", ("a",), ("N",), None, also=tuple(regressors[1:]))


def _trial(cand, ext):
    return acc.RefitCV(cand, CUR, acc.FoldErrors(np.asarray(ext, float), SS))


def _gain(t):
    # written out: 1 - sum(SSE_refit) / sum(SSE_current) over the folds
    return 1.0 - float(np.sum(t.extended.sse)) / float(np.sum(CUR.sse))


def test_to_carry_keeps_the_accepted_trials_that_share_no_regressor_with_the_pick_best_first():
    # the loop passes the round's accepted trials (``accepts``); to_carry chooses among them
    voltage = _trial(_cand("run_level_voltage_V", "voltage"), [0.02, 0.03, 0.05, 0.05])
    load_voltage = _trial(_cand("smooth_load_x_voltage", "load", "voltage"), [0.01, 0.02, 0.04, 0.04])
    dither = _trial(_cand("run_level_rail_dither_um", "rail_dither_um"), [0.03, 0.05, 0.07, 0.08])
    temp = _trial(_cand("channel_temp_C", "temp_C"), [0.02, 0.04, 0.06, 0.07])
    accepted = [load_voltage, voltage, dither, temp]
    assert {t.candidate.regressors for t in accepted} >= {("voltage",), ("load", "voltage")}
    out = to_carry(accepted, voltage)
    # load_voltage shares "voltage" with the pick; the rest by decreasing gain
    assert [c.family for c in out] == ["channel_temp_C", "run_level_rail_dither_um"]
    assert _gain(temp) > _gain(dither) > 0
    # the pick's own family is never carried, even with other regressors
    other_form = _trial(_cand("run_level_voltage_V", "load"), [0.01, 0.02, 0.03, 0.03])
    assert to_carry([other_form, dither], voltage) == [dither.candidate]
    assert to_carry([voltage], voltage) == [] and to_carry([], voltage) == []


def NO_RUN_P(c):
    return None


def _scores(evidence):
    """A stand-in for the linearised screen: each candidate's ``(gain, p, delta_aic)`` from ``evidence`` by family,
    recording which candidates it was asked to score."""
    asked = []

    def score(cands):
        asked.append([c.family for c in cands])
        return [Score(c, *evidence[c.family][:2], 30.0, -1.0, np.zeros(1), evidence[c.family][2]) for c in cands]
    return score, asked


def _carried(carry, allowed, score, run_p=NO_RUN_P):
    return [s.candidate for s in carried(carry, allowed, score, run_p, level=0.01, min_gain=0.05)]


def test_carried_refits_the_first_allowed_candidate_that_the_screen_still_shows():
    a, b, c = _cand("fam_a", "x"), _cand("fam_b", "y"), _cand("fam_c", "z")
    strong = {"fam_a": (0.2, 1e-4, -50.0), "fam_b": (0.3, 1e-3, -80.0), "fam_c": (0.1, 5e-3, -20.0)}
    score, asked = _scores(strong)
    assert _carried([a, b, c], lambda k: True, score) == [a]
    assert asked == [["fam_a", "fam_b", "fam_c"]]
    [s] = carried([a, b, c], lambda k: True, score, NO_RUN_P, level=0.01, min_gain=0.05)
    assert s.origin == "carried" and (s.cv_gain, s.p_value) == strong["fam_a"][:2]     # the report's offered_by
    assert _carried([a, b, c], lambda k: k is not a, score) == [b]           # added, collinear or in conflict
    assert _carried([a, b, c], lambda k: k is c, score) == [c]
    # what the added effect explained is not offered: the screen's gain, p-value and AIC each decide
    for weak in ((0.04, 1e-4, -50.0), (0.2, 0.01, -50.0), (0.2, 1e-4, 0.0)):
        score, _ = _scores({**strong, "fam_a": weak})
        assert _carried([a, b], lambda k: True, score) == [b], weak
    score, asked = _scores(strong)
    assert _carried([], lambda k: True, score) == [] and asked == []
    assert _carried([a], lambda k: False, score) == [] and asked == []


def test_a_run_level_candidate_is_carried_by_its_signals_run_level_p_not_by_the_screen():
    a, b = _cand("run_level_aux", "aux"), _cand("fam_b", "y")
    weak_screen = {"run_level_aux": (0.26, 0.25, -2600.0), "fam_b": (0.3, 1e-3, -80.0)}
    score, _ = _scores(weak_screen)
    for p, first in ((0.00076, a), (0.0099, a), (0.01, b), (0.041, b)):
        assert _carried([a, b], lambda k: True, score, lambda c: p if c is a else None) == [first], p


def _analysis(entries):
    ev = [rl.SignalEvidence(channel=ch, transform=tr, label=ch, regressor=ch, mean=0.0, sd=1.0, p_value=pv)
          for ch, tr, pv in entries]
    return rl.RunLevelAnalysis(None, None, float("nan"), 1.0, ev, 0.001)


def test_signal_p_reads_the_candidates_own_signal_and_transform():
    fam = fx.family("run_level")
    (h_none,), (h_abs,) = (fam.hypotheses([{"channel": "aux", "transform": t, "mean": 0.0, "sd": 1.0}])
                           for t in ("none", "abs"))
    c_none, c_abs = (CandidateForce(h.family, h.regressor, h.shape, h.names, h.units, None, spec=h.spec)
                     for h in (h_none, h_abs))
    ana = _analysis([("aux", "none", 0.004), ("aux", "abs", 0.3), ("other", "none", 1e-9)])
    assert ana.signal_p(c_none) == 0.004 and ana.signal_p(c_abs) == 0.3
    assert _analysis([("other", "none", 1e-9)]).signal_p(c_none) == 1.0     # not tested in this round
    assert ana.signal_p(_cand("fam_b", "y")) is None                         # not a run-level form


def _refit_list(short, offered, carry, scores=(), share=lambda n, g: 0.0, run_p=NO_RUN_P, allowed=lambda c: True):
    score, asked = _scores(EVIDENCE)
    out = refit_list(list(short), offered, carry, list(scores), allowed=allowed, score=score, run_p=run_p,
                     share=share, level=0.01, screen=0.01, min_gain=0.05)
    return [(s.candidate.family, s.origin) for s in out], asked


EVIDENCE = {"fam_a": (0.2, 1e-4, -50.0), "run_level_aux": (0.3, 0.2, -80.0), "gen_g": (0.1, 1e-3, -20.0),
            "named_n": (0.15, 2e-3, -30.0)}


def test_a_rounds_refit_list_carries_only_when_neither_the_screen_nor_the_run_level_analysis_offers():
    a, rl_aux, g = _cand("fam_a", "x"), _cand("run_level_aux", "aux"), _cand("gen_g", "y")
    screen_a = Score(a, 0.2, 1e-4, 30.0, -1.0, np.zeros(1), -50.0)
    # the screen's shortlist first, then the offered run-level form, scored and tagged; carry is not asked
    out, asked = _refit_list([screen_a], [rl_aux], [g])
    assert out == [("fam_a", "screen"), ("run_level_aux", "run_level")] and asked == [["run_level_aux"]]
    out, asked = _refit_list([], [rl_aux], [g])                     # an offered run-level form alone: no carry
    assert out == [("run_level_aux", "run_level")] and asked == [["run_level_aux"]]
    out, asked = _refit_list([screen_a], [], [g])
    assert out == [("fam_a", "screen")] and asked == [[]]
    # nothing from the screen or the run-level analysis: the carried candidate, by its own evidence
    out, asked = _refit_list([], [], [g])
    assert out == [("gen_g", "carried")] and asked == [[], ["gen_g"]]
    # without a run-level analysis a run-level form's evidence is the screen's (run_p None), else its signal's p
    assert _refit_list([], [], [rl_aux])[0] == []                    # the screen's p 0.2 is not below 0.01
    assert _refit_list([], [], [rl_aux], run_p=lambda c: 0.004)[0] == [("run_level_aux", "carried")]
    assert _refit_list([], [], [g], allowed=lambda c: False)[0] == []


def test_a_carried_generic_term_gets_its_named_alternative():
    g = CandidateForce("gen_g", "y", "", ("a",), ("N",), None, generic=True)
    n = _cand("named_n", "y")
    scores = [Score(n, 0.15, 2e-3, 30.0, -1.0, np.zeros(1), -30.0)]
    out, _ = _refit_list([], [], [g], scores, share=lambda named, gen: 0.9)
    assert out == [("gen_g", "carried"), ("named_n", "named")]
    assert _refit_list([], [], [g], scores, share=lambda named, gen: 0.0)[0] == [("gen_g", "carried")]
