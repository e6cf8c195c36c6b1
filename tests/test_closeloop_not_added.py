"""Why a significant channel added nothing (``diagnosis.channels_considered[*].not_added``)."""

from types import SimpleNamespace

import numpy as np
from l1b2.closeloop.evidence import channels_considered, not_added_reason
from l1b2.closeloop.selection import Score


def _trial(effect, label, gain=0.01, improved=1, folds=4, cur=0.02, ref=0.0198):
    return {"effect": effect, "label": label, "cv_gain": gain, "folds_improved": improved, "folds": folds,
            "cv_free_run_nrmse_current": cur, "cv_free_run_nrmse_refit": ref}


def _score(name, gain, p):
    cand = SimpleNamespace(family=f"channel_{name}", label=f"channel_{name}[force, sample]",
                           spec={"kind": "channel", "form": "force"}, regressor=name)
    return Score(candidate=cand, cv_gain=gain, p_value=p, runs_improved=0.8, delta_bic=-4.0, phi=np.zeros(1),
                 delta_aic=-6.0)


CHANNELS = tuple({"name": n, "kind": "logged", "within_run": True, "sd": 1.0} for n in ("aux", "weak"))


def test_a_refit_family_is_named_with_its_last_trials_figures():
    # property: the last round that refit the family gives the reason, with its CV gain, folds and nrmse
    trials = [[_trial("a", "a"), _trial("channel_aux", "channel_aux[x]", 0.5, 1, 4, 0.03, 0.029)],
              [_trial("channel_aux", "channel_aux[x]", -0.021, 1, 4, 0.0251, 0.0256)]]
    r = not_added_reason({"channel_aux"}, trials, ["a"])
    assert r == ("refit in round 2: CV gain -2.1%, 1/4 folds improved, CV nrmse 2.51% -> 2.56%: refused by the "
                 "acceptance rules")


def test_a_family_that_passed_the_rules_names_what_its_round_added_instead():
    trials = [[_trial("a", "a[x]"), {**_trial("run_level_aux", "run_level_aux[run]", 0.4, 4, 4, 0.03, 0.01),
                                     "accepted": True}],
              [{**_trial("channel_aux", "channel_aux[x]", 0.2, 3, 4, 0.01, 0.009), "accepted": True}]]
    assert not_added_reason({"run_level_aux"}, trials, ["a[x]"]) == (
        "refit in round 1: CV gain 40.0%, 4/4 folds improved, CV nrmse 3.00% -> 1.00%: passed the acceptance "
        "rules, but round 1 added a[x] instead")
    assert not_added_reason({"channel_aux"}, trials, ["a[x]"]).endswith(
        "passed the acceptance rules, but a later check of round 2 added nothing")


def test_a_family_never_refit_names_the_first_rounds_candidates_and_the_last_round():
    trials = [[_trial("s", "smooth_v"), _trial("t", "load_slope"), _trial("s", "smooth_v")], [_trial("u", "u")]]
    r = not_added_reason({"channel_aux", "run_level_aux"}, trials)
    assert r == ("not refit: stronger candidates were refit first (round 1: smooth_v, load_slope); "
                 "the loop ended after round 2")
    assert not_added_reason({"channel_aux"}, []) == "not refit: the loop refit no candidate"


def test_only_significant_rows_that_were_not_added_carry_a_reason():
    scores = [_score("aux", 0.12, 1e-8), _score("weak", 0.01, 0.3)]
    trials = [[_trial("channel_aux", "channel_aux[force, sample]", 0.02, 2, 4)]]
    rows = {r["channel"]: r for r in channels_considered(CHANNELS, scores, 1e-3, 0.05, set(), None, trials)}
    assert rows["aux"]["significant"] and rows["aux"]["not_added"].startswith("refit in round 1: CV gain 2.0%")
    assert rows["aux"]["not_added"].endswith("refused by the acceptance rules")
    assert not rows["weak"]["significant"] and rows["weak"]["not_added"] is None
    added = {r["channel"]: r for r in channels_considered(CHANNELS, scores, 1e-3, 0.05, {"channel_aux"}, None,
                                                          trials)}
    assert added["aux"]["added"] and added["aux"]["not_added"] is None
    # the input rows (no run-level evidence here) are not significant and carry none
    assert all(r["not_added"] is None for r in added.values() if r["kind"] == "input")
