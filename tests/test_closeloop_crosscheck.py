"""A named effect found from the Eq. 29 baseline is read as physics only when the pure-slip family confirms it
(issue 28 item 6, decision 0043): the pick rule and the check on synthetic inputs, in seconds."""

import numpy as np
import pytest
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import crosscheck as cc
from l1b2.closeloop.candidates import CandidateForce, candidate
from l1b2.errors import FitDivergedError
from l1b2.predictor import effects as fx
from test_effects_registry import TRAIN


def _fe(sse):
    return acc.FoldErrors(np.asarray(sse, float), np.full(len(sse), 100.0))


CUR = _fe([10.0, 10.0, 10.0, 10.0])     # current model: CV nrmse sqrt(40 / 400) = 0.316


def _t(family, ext, generic, cur=CUR, n=1):
    c = CandidateForce(family, "load", "", tuple(f"{family}_{i}" for i in range(n)), ("N",) * n, None,
                       generic=generic, description=f"{family} force")
    return acc.RefitCV(c, cur, _fe(ext), phi=np.zeros(n))


def _first(trials):
    """A stand-in for the loop's choice: named before generic, then the largest gain."""
    return min(trials, key=lambda t: (t.candidate.generic, -t.gain))


class _Confirm:
    """``confirm`` answering from a table, recording what it was asked."""

    def __init__(self, verdicts):
        self.verdicts, self.asked = verdicts, []

    def __call__(self, t):
        self.asked.append(t.candidate.family)
        v = self.verdicts.get(t.candidate.family)
        return None if v is None else {"label": t.candidate.label, "confirmed": v}


def test_a_generic_pick_is_not_checked():
    gen = _t("smooth_load", [5, 5, 5, 5], True)
    conf = _Confirm({})
    pick, recs = cc.confirmed_pick([gen], _first, conf)
    assert pick is gen and recs == [] and conf.asked == []


def test_a_structural_named_pick_is_not_checked():
    # a named term that relaxes Eq. 29's linearisation (load_slope_voltage) is already read as the reduced model's
    named = _t("load_slope_voltage", [4, 4, 4, 4], False)
    structural = acc.RefitCV(CandidateForce("load_slope_voltage", "load", "", ("p",), ("N",), None,
                                            structural="Eq. 29's slope"), CUR, _fe([4] * 4))
    conf = _Confirm({"load_slope_voltage": False})
    pick, recs = cc.confirmed_pick([structural], _first, conf)
    assert pick is structural and recs == [] and conf.asked == []
    pick, recs = cc.confirmed_pick([named], _first, conf)     # the same without the tag: checked
    assert pick is not named and conf.asked == ["load_slope_voltage"]


def test_a_confirmed_named_pick_is_kept_and_recorded():
    named, gen = _t("named_x", [4, 4, 4, 4], False), _t("smooth_load", [3, 3, 3, 3], True)
    conf = _Confirm({"named_x": True})
    pick, recs = cc.confirmed_pick([gen, named], _first, conf)
    assert pick is named and [r["outcome"] for r in recs] == ["kept"]
    pick, recs = cc.confirmed_pick([gen, named], _first, _Confirm({}))
    assert pick is named and recs == []                    # no check applies (e.g. a pure-slip baseline)


def test_an_unconfirmed_named_pick_is_kept_only_as_its_generic_structural_form():
    named = _t("named_x", [4, 4, 4, 4], False)
    conf = _Confirm({"named_x": False})
    pick, recs = cc.confirmed_pick([named], _first, conf)
    assert pick is not named and pick.candidate.generic and pick.candidate.structural
    assert pick.candidate.family == "named_x" + cc.FORM_SUFFIX
    assert pick.current is named.current and pick.extended is named.extended     # the same cross-validated figures
    assert [r["outcome"] for r in recs] == [f"withdrawn, kept as {pick.candidate.label}"]
    assert conf.asked == ["named_x"]                       # the form itself is generic: not checked again


def test_an_unconfirmed_named_pick_keeps_its_place_as_its_form():
    # the round's choice stands (its acceptance and the choice's rules); only the pick's reading changes, even when
    # a generic term has the larger gain or another named trial would be confirmed
    named = _t("named_x", [4, 4, 4, 4], False)
    gen = _t("smooth_load", [3, 3, 3, 3], True)
    other = _t("named_y", [5, 5, 5, 5], False)
    conf = _Confirm({"named_x": False, "named_y": True})
    pick, recs = cc.confirmed_pick([named, gen, other], _first, conf)
    assert pick.candidate == cc.as_form(named.candidate) and pick.phi is named.phi
    assert [r["outcome"] for r in recs] == [f"withdrawn, kept as {pick.candidate.label}"]
    assert conf.asked == ["named_x"]                       # only the pick is checked
    assert cc.confirmed_pick([], _first, _Confirm({})) == (None, [])


def _pulley():
    return candidate(None, fx.family("load_path_friction").grid(TRAIN)[0])


def test_the_form_has_the_same_force_and_no_physical_home():
    import pandas as pd
    from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
    from l1b2.predictor.effects.homes import map_effects
    c = _pulley()
    f = cc.as_form(c)
    assert f.generic and not c.generic and f.structural and not c.structural
    assert f.family == "load_path_friction_form" and f.names == ("load_path_friction_form_0",)
    assert f.spec == c.spec and f.bounds == c.bounds and f.n_params == c.n_params
    df = pd.DataFrame({"time_s": [0.0, 1e-3], "run": [0, 0], "position_m": [0.0, 0.0], "voltage_V": [300.0] * 2,
                       "direction": [1, 1], "load_kg": [0.05, -0.03], "speed_m_s": [0.1, 0.1]})
    np.testing.assert_array_equal(f.features(df), c.features(df))

    def effect(cand):
        return fx.IdentifiedEffect(cand.family, cand.label, dict(cand.spec), cand.names, cand.units, (0.3,),
                                   (0.01,), cand.description, cand.regressors, cand.structural)
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    model = type("M", (), {"effects": (effect(c),)})()
    out, rec = map_effects(model, mp)
    assert rec[0]["mapped"] and out.slider.pulley_mu == pytest.approx(0.3)      # the named reading: copied
    model = type("M", (), {"effects": (effect(f),)})()
    out, rec = map_effects(model, mp)
    assert not rec[0]["mapped"] and out.slider.pulley_mu == mp.slider.pulley_mu   # the form: no subsystem value


def test_score_of_finds_the_named_score_behind_a_form():
    from l1b2.closeloop.selection import Score
    c = _pulley()
    s = Score(c, 0.4, 1e-4, 0.9, -5.0, np.ones(1), -6.0)
    other = Score(CandidateForce("smooth_load", "load", "", ("p",), ("N",), None, generic=True),
                  0.3, 1e-3, 0.8, -4.0, np.ones(1), -5.0)
    t = acc.RefitCV(c, CUR, _fe([4] * 4), phi=np.ones(1))
    assert cc.score_of(t, [other, s]) is s
    form = cc.score_of(acc.RefitCV(cc.as_form(c), CUR, _fe([4] * 4)), [other, s])
    assert form.candidate == cc.as_form(c) and form.cv_gain == s.cv_gain
    with pytest.raises(ValueError):
        cc.score_of(t, [other])


# ---------------------------------------------------------------------------
# the check itself, with the identifications replaced by stand-ins (what it refits, counts and decides)
# ---------------------------------------------------------------------------

class _Model:
    def __init__(self, name):
        self.name, self.params_ = name, name
        self.convergence_ = {"nfev_total": 7}

    def predict_free_run(self, df):
        return np.zeros(len(df))


class _Clock:
    def __init__(self):
        self.stages, self.counts = [], []

    def __call__(self, msg):
        self.stages.append(msg)

    def count(self, n, nfev):
        self.counts.append((n, nfev))


@pytest.fixture
def stand_ins(monkeypatch):
    calls = {"refit": [], "cv": []}
    ext = {"sse": [4.0, 4.0, 4.0, 4.0]}

    def refit(df, mask, m_s, init, effects, settings, max_outer=2):
        calls["refit"].append((init, tuple(c.label for c in effects.candidates), settings.max_nfev))
        return _Model(f"{init}+{len(effects.candidates)}")

    def cv_errors(df, mask, m_s, folds, init, jobs, settings):
        calls["cv"].append((init, [tuple(c.label for c in e.candidates) for e, _ in jobs], len(folds)))
        out = [_fe([10.0] * len(folds)), _fe(ext["sse"][:len(folds)])]
        for e in out:
            e.nfev = 3
        return out

    monkeypatch.setattr(cc, "refit", refit)
    monkeypatch.setattr(cc, "cv_errors", cv_errors)
    monkeypatch.setattr(cc, "design", lambda c, r, df, mask, p, m_s, v_pred: (None, None, None, None))
    monkeypatch.setattr(cc, "fold_start_phi", lambda S, A, y, runs, folds: [np.zeros(1)] * len(folds))
    monkeypatch.setattr(cc.res, "drive_residual", lambda df, v: np.zeros(len(df)))
    return calls, ext


def _check(identify, clock, min_gain=0.03):
    import pandas as pd
    df = pd.DataFrame({"x": np.zeros(5)})
    return cc.PureSlipCheck(identify, df, np.ones(5, bool), 0.1, lambda c: [[0], [1], [2], [3]],
                            acc.RefitSettings(max_nfev=10), min_gain=min_gain, final_nfev=60, clock=clock)


def test_the_check_refits_from_the_pure_slip_family_and_counts_on_the_stage_clock(stand_ins):
    calls, ext = stand_ins
    n_identify = []
    clock = _Clock()
    check = _check(lambda: n_identify.append(1) or _Model("ps"), clock)
    trial = _t("named_x", [4, 4, 4, 4], False)
    rec = check(trial, acc.EffectSet(), 2)
    assert rec["checked"] and rec["confirmed"] and rec["cv_gain"] == pytest.approx(0.6)
    assert rec["folds_improved"] == 4 and rec["eq29_cv_gain"] == pytest.approx(trial.gain)
    assert calls["refit"] == [] and calls["cv"] == [("ps", [(), ("named_x",)], 4)]   # from the baseline itself
    assert clock.counts == [(8, 6)] and "pure_slip" in clock.stages[0]
    # with effects already added, the pure-slip model is re-identified with them once (the final budget)
    gen = _t("smooth_load", [5] * 4, True).candidate
    eff = acc.EffectSet().add(gen, [0.0])
    check(trial, eff, 3)
    check(trial, eff, 3)
    assert calls["refit"] == [("ps", ("smooth_load",), 60)] and len(n_identify) == 1
    assert calls["cv"][-1] == ("ps+1", [("smooth_load",), ("smooth_load", "named_x")], 4)
    assert clock.counts[1] == (1, 7)
    # the loop's acceptance rule decides: a gain below min_gain, or a fall in only half of the folds, refuses it
    ext["sse"] = [9.9, 9.9, 9.9, 9.9]
    assert not check(trial, acc.EffectSet(), 2)["confirmed"]
    ext["sse"] = [2.0, 2.0, 11.0, 11.0]
    assert not check(trial, acc.EffectSet(), 2)["confirmed"]


def test_a_pure_slip_fit_that_diverges_leaves_the_named_reading_unchecked(stand_ins):
    def fail():
        raise FitDivergedError("the pure_slip fit diverged")
    check = _check(fail, _Clock())
    rec = check(_t("named_x", [4, 4, 4, 4], False), acc.EffectSet(), 1)
    assert rec["confirmed"] and not rec["checked"] and "diverged" in rec["note"]


def test_the_report_names_the_check_its_figures_and_its_outcome():
    rec = {"round": 2, "label": "load_path_friction", "family": "pure_slip", "checked": True, "confirmed": False,
           "cv_free_run_nrmse_current": 0.021, "cv_free_run_nrmse_refit": 0.0208, "cv_gain": 0.019,
           "folds_improved": 3, "folds": 4, "eq29_cv_gain": 0.2, "min_cv_gain": 0.03,
           "outcome": "withdrawn, kept as load_path_friction_form"}
    line = cc.describe(rec)
    for part in ("load_path_friction", "pure_slip", "2.10% -> 2.08%", "1.9%", "3/4", "20.0%", "not confirmed",
                 "kept as load_path_friction_form"):
        assert part in line, (part, line)
    assert "load_path_friction" in cc.withdrawn_note([rec])
    assert cc.withdrawn_note([{**rec, "confirmed": True, "outcome": "kept"}]) == ""


# ---------------------------------------------------------------------------
# the named parameter from both families (decision 0048): recorded beside the check, not a rule
# ---------------------------------------------------------------------------

class _Fitted(_Model):
    """A stand-in joint fit whose named parameter has a value and a model-based standard error."""

    def __init__(self, name, value, se):
        super().__init__(name)
        self.extra_params_ = {"pulley_mu": value}
        self.extra_stderr_ = {"pulley_mu": se}
        self.extra_ci95_ = {"pulley_mu": (value - 2 * se, value + 2 * se)}


def test_the_named_parameter_is_estimated_in_both_families_with_its_standard_errors(stand_ins, monkeypatch):
    calls, _ = stand_ins
    fits = {"eq29": (0.061, 0.008), "ps+1": (0.045, 0.011)}
    starts = []

    def refit(df, mask, m_s, init, effects, settings, max_outer=2):
        calls["refit"].append((init, tuple(c.label for c in effects.candidates), settings.max_nfev))
        starts.append((init, effects.phi[-1].tolist()))
        return _Fitted(init, *fits[init])

    monkeypatch.setattr(cc, "refit", refit)
    y = np.array([1.0, 2.0, 3.0, 4.0])
    A, S = np.ones((4, 1)), np.array([[0.0], [1.0], [2.0], [3.0]])       # least squares: y = 1 + 1 * S
    monkeypatch.setattr(cc, "design", lambda c, r, df, mask, p, m_s, v_pred: (y, A, S, np.arange(4)))
    clock = _Clock()
    check = _check(lambda: _Model("ps+1"), clock)
    trial = acc.RefitCV(_pulley(), CUR, _fe([4] * 4), phi=np.array([0.3]))
    rec = {**check(trial, acc.EffectSet(), 2, estimate=True), "outcome": "kept"}
    assert "parameters" not in rec      # the Eq. 29 side waits for the loop's joint refit
    # the check refits only its own family, started at its own linearised fit, with the final budget
    assert starts == [("ps+1", [pytest.approx(1.0)])] and calls["refit"][-1][2] == 60
    assert clock.counts[-1] == (1, 7)
    joint = _Fitted("eq29", *fits["eq29"])          # the loop's joint re-identification with the pick
    check.record_joint_refit([rec], joint)
    p = rec["parameters"]["pulley_mu"]
    assert len(starts) == 1                          # no second Eq. 29 refit: the loop's is read
    assert p["eq29"] == check.estimates_of(joint, trial.candidate)["pulley_mu"]
    assert p["eq29"]["value"] == 0.061 and p["eq29"]["stderr"] == 0.008 and p["pure_slip"]["stderr"] == 0.011
    # the difference against the standard error of both estimates (a dropped one or the wrong sign fails)
    assert p["z_difference"] == pytest.approx((0.045 - 0.061) / np.hypot(0.008, 0.011))
    assert p["z_pure_slip"] == pytest.approx(0.045 / 0.011)
    line = cc.describe({"round": 2, "label": "load_path_friction", "family": "pure_slip", "checked": True,
                        "confirmed": True, "cv_free_run_nrmse_current": 0.02, "cv_free_run_nrmse_refit": 0.019,
                        "cv_gain": 0.05, "folds_improved": 4, "folds": 4, "eq29_cv_gain": 0.3,
                        "min_cv_gain": 0.03, "outcome": "kept", "parameters": {"pulley_mu": p}})
    assert "pulley_mu from eq29 0.061 ± 0.008, from pure_slip 0.045 ± 0.011 (difference -1.2 se)" in line, line
    again = {**rec, "parameters": None}
    check.record_joint_refit([again], joint)          # completed once: nothing is left pending
    assert again["parameters"] is None


def test_only_a_confirmed_reading_gets_both_families_parameters(stand_ins, monkeypatch):
    calls, ext = stand_ins
    monkeypatch.setattr(cc, "refit", lambda df, mask, m_s, init, effects, settings, max_outer=2: _Fitted(
        init, 0.05, 0.01))
    monkeypatch.setattr(cc, "design", lambda c, r, df, mask, p, m_s, v_pred: (
        np.ones(4), np.ones((4, 1)), np.arange(4.0)[:, None], np.arange(4)))
    check = _check(lambda: _Model("ps"), _Clock())
    trial = acc.RefitCV(_pulley(), CUR, _fe([4] * 4), phi=np.array([0.3]))
    rec = {**check(trial, acc.EffectSet(), 2, estimate=True), "outcome": "kept"}
    check.record_joint_refit([rec], _Fitted("eq29", 0.05, 0.01))
    assert rec["confirmed"] and set(rec["parameters"]["pulley_mu"]) >= {"eq29", "pure_slip", "z_difference"}
    assert "pulley_mu from eq29 0.05 ± 0.01" in cc.describe(rec)
    ext["sse"] = [9.9, 9.9, 9.9, 9.9]        # withdrawn: no parameter is reported, none is estimated
    rec = {**check(trial, acc.EffectSet(), 2, estimate=True), "outcome": "withdrawn, kept as x"}
    check.record_joint_refit([rec], _Fitted("eq29", 0.05, 0.01))
    assert "parameters" not in rec
    kept = {**rec, "outcome": "kept"}                  # nothing was left pending by the withdrawn one
    check.record_joint_refit([kept], _Fitted("eq29", 0.05, 0.01))
    assert "parameters" not in kept
    ext["sse"] = [4.0] * 4
    rec = {**check(trial, acc.EffectSet(), 2), "outcome": "kept"}     # no estimate asked: none made
    check.record_joint_refit([rec], _Fitted("eq29", 0.05, 0.01))
    assert "parameters" not in rec


def test_a_failed_estimate_of_the_named_parameters_is_recorded_not_raised(stand_ins, monkeypatch):
    def refit(*a, **k):
        raise FitDivergedError("the joint refit diverged")
    monkeypatch.setattr(cc, "refit", refit)
    monkeypatch.setattr(cc, "design", lambda c, r, df, mask, p, m_s, v_pred: (
        np.ones(4), np.ones((4, 1)), np.arange(4.0)[:, None], np.arange(4)))
    check = _check(lambda: _Model("ps"), _Clock())
    rec = check(acc.RefitCV(_pulley(), CUR, _fe([4] * 4), phi=np.array([0.3])), acc.EffectSet(), 2, estimate=True)
    rec = {**rec, "outcome": "kept"}
    check.record_joint_refit([rec], _Fitted("eq29", 0.05, 0.01))
    assert rec["confirmed"] and "parameters" not in rec and "diverged" in rec["parameters_note"]
