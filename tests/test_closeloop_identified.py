"""A named effect is named only when identified (issue 28 item 6): the joint Wald test of its parameters against
zero under the reported covariance, and the pick that falls back to the round's next trial when it fails."""

import numpy as np
import pytest
from scipy import stats

from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import crosscheck as cc
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.intervals import identification, wald_test
from test_direction_calibration_se import _Fit

PHI = np.array([1.0, 2.0])
COV = np.array([[1.0, 0.5], [0.5, 2.0]])
# phi' C^-1 phi by hand: C^-1 = [[2, -0.5], [-0.5, 1]] / (1 * 2 - 0.5^2), so W = (2 - 2 + 4) / 1.75
W_UNIT = 4.0 / 1.75


def _f2_sf(f, n):
    """Survival function of F(2, n), written out: (1 + 2 f / n)^(-n / 2)."""
    return (1.0 + 2.0 * f / n) ** (-n / 2.0)


def test_the_wald_statistic_and_its_f_p_value_against_the_hand_computation():
    t = wald_test(PHI, COV, clusters=8, alpha=0.01)
    assert t["wald"] == pytest.approx(W_UNIT, rel=1e-12)
    assert (t["k"], t["df_denominator"]) == (2, 7)
    assert t["p"] == pytest.approx(_f2_sf(W_UNIT / 2, 7), rel=1e-9)
    # without clusters: chi-square with 2 df, whose survival function is exp(-W / 2)
    t = wald_test(PHI, COV, clusters=None, alpha=0.01)
    assert t["p"] == pytest.approx(np.exp(-W_UNIT / 2), rel=1e-9) and t["df_denominator"] is None


@pytest.mark.parametrize("scale, identified", [(2.7, False), (3.1, True)])
def test_either_side_of_the_threshold(scale, identified):
    # F(2, 7) at alpha 0.01: (1 + 2 F / 7)^(-3.5) = 0.01 at F = 9.55, W = 19.1, i.e. phi scaled by 2.89
    t = wald_test(scale * PHI, COV, clusters=8, alpha=0.01)
    w = scale ** 2 * W_UNIT
    assert t["wald"] == pytest.approx(w, rel=1e-12)
    assert t["p"] == pytest.approx(_f2_sf(w / 2, 7), rel=1e-9)
    assert (t["p"] < 0.01) is identified and t["identified"] is identified


def test_one_parameter_is_the_reported_t_with_clusters_minus_one():
    # k = 1: F(1, H - 1) of z^2 is the two-sided t test with H - 1 df that the reported interval uses
    t = wald_test([0.05], [[0.02 ** 2]], clusters=10, alpha=0.05)
    assert t["wald"] == pytest.approx(2.5 ** 2)
    assert t["p"] == pytest.approx(2 * stats.t.sf(2.5, 9), rel=1e-9)


def test_two_marginally_insignificant_but_jointly_significant_parameters_are_identified():
    # each |z| < 1.96, correlation -0.994: jointly W = (z1^2 + z2^2 - 2 rho z1 z2) / (1 - rho^2)
    se, rho, phi = np.array([0.040, 0.032]), -0.994, np.array([-0.048, -0.053])
    cov = np.array([[se[0] ** 2, rho * se[0] * se[1]], [rho * se[0] * se[1], se[1] ** 2]])
    z = phi / se
    t = wald_test(phi, cov, clusters=8, alpha=0.01)
    assert t["wald"] == pytest.approx((z[0] ** 2 + z[1] ** 2 - 2 * rho * z[0] * z[1]) / (1 - rho ** 2), rel=1e-9)
    assert t["identified"]
    # with the same standard errors and no correlation the pair is not
    assert not wald_test(phi, np.diag(se ** 2), clusters=8, alpha=0.01)["identified"]


def test_a_singular_or_non_finite_covariance_or_one_cluster_identifies_nothing():
    for cov, h in (([[1.0, 1.0], [1.0, 1.0]], 8), ([[np.nan, 0.0], [0.0, 1.0]], 8), (COV, 1)):
        t = wald_test(10 * PHI, cov, clusters=h, alpha=0.01)
        assert t["identified"] is False and t["wald"] is None and t["p"] is None


def test_identification_uses_the_reported_covariance_and_its_clusters():
    names = ("asym_gain", "asym_offset_N")
    # no levels: the run-robust block [[9e-4, -2e-4], [-2e-4, 4e-4]] with the fit's 4 runs, F on (2, 3)
    t = identification(_Fit(), names, None, alpha=0.01)
    det = 9e-4 * 4e-4 - 2e-4 ** 2
    w = (0.2 ** 2 * 4e-4 + 2 * 0.2 * 0.05 * 2e-4 + 0.05 ** 2 * 9e-4) / det
    assert t["interval"] == "run" and t["df_denominator"] == 3
    assert t["wald"] == pytest.approx(w, rel=1e-9)
    assert t["p"] == pytest.approx(_f2_sf(w / 2, 3), rel=1e-9)
    assert t["values"] == {"asym_gain": 0.2, "asym_offset_N": 0.05}
    # two levels: the level block, F on (2, 1)
    t = identification(_Fit(), names, ["a", "a", "b", "b"], alpha=0.01)
    v = np.array([[3.0, -1.0], [-0.5, 1.5]])
    c = 2.0 * v.T @ v
    phi = np.array([0.2, 0.05])
    assert t["interval"] == "level" and t["df_denominator"] == 1
    assert t["wald"] == pytest.approx(phi @ np.linalg.inv(c) @ phi, rel=1e-9)


def _fe(sse):
    return acc.FoldErrors(np.asarray(sse, float), np.full(len(sse), 100.0))


def _t(family, ext, generic):
    c = CandidateForce(family, "load", "", (f"{family}_0",), ("N",), None, generic=generic,
                       description=f"{family} force")
    return acc.RefitCV(c, _fe([10.0] * 4), _fe(ext), phi=np.zeros(1))


def _first(trials):
    """A stand-in for the loop's choice: named before generic."""
    return min(trials, key=lambda t: t.candidate.generic)


class _Fitter:
    def __init__(self):
        self.fitted = []

    def __call__(self, pick):
        self.fitted.append(pick.candidate.family)
        return pick.candidate.family        # the "model" is the family's name


def _ident(verdicts):
    def identify(model, c):
        return {"wald": 1.0, "k": 1, "df_denominator": 7, "p": 0.5, "alpha": 0.01, "identified": verdicts[model],
                "interval": "level", "values": {}}
    return identify


def test_a_named_pick_that_is_not_identified_falls_back_to_the_rounds_next_trial():
    named, gen = _t("direction_asymmetry", [4] * 4, False), _t("smooth_direction_x_load", [5] * 4, True)
    fit = _Fitter()
    pick, model, checks, records = cc.identified_pick(
        [named, gen], _first, lambda t: None, fit, _ident({"direction_asymmetry": False}), 3)
    assert pick is gen and model == "smooth_direction_x_load" and checks == []
    assert fit.fitted == ["direction_asymmetry", "smooth_direction_x_load"]
    (rec,) = records
    assert rec["label"] == "direction_asymmetry" and rec["round"] == 3
    assert rec["outcome"].startswith("not identified") and rec["identification"]["identified"] is False
    assert "not identified" in cc.withdrawn_note(records) and "direction_asymmetry" in cc.withdrawn_note(records)
    assert "not identified" in cc.describe(rec)
    # a label not identified in two rounds is named once
    assert cc.withdrawn_note([rec, {**rec, "round": 4}]).count("direction_asymmetry") == 1


def test_an_identified_named_pick_is_kept_with_its_test_in_its_check():
    named, gen = _t("direction_asymmetry", [4] * 4, False), _t("smooth_direction_x_load", [5] * 4, True)
    fit = _Fitter()
    confirm = (lambda t: {"round": 1, "label": t.candidate.label, "confirmed": True, "family": "pure_slip",
                          "checked": False, "note": "n"})
    pick, model, checks, records = cc.identified_pick(
        [named, gen], _first, confirm, fit, _ident({"direction_asymmetry": True}), 1)
    assert pick is named and fit.fitted == ["direction_asymmetry"]
    (rec,) = checks
    assert records == checks and rec["outcome"] == "kept" and rec["identification"]["identified"] is True
    assert "identified" in cc.describe(rec) and cc.withdrawn_note(records) == ""


def test_a_generic_pick_is_not_tested_and_nothing_left_adds_nothing():
    gen = _t("smooth_load", [5] * 4, True)
    called = []
    pick, _, checks, records = cc.identified_pick(
        [gen], _first, lambda t: None, _Fitter(), lambda m, c: called.append(c) or {}, 1)
    assert pick is gen and called == [] and records == []
    named = _t("load_path_friction", [4] * 4, False)
    pick, model, checks, records = cc.identified_pick(
        [named], _first, lambda t: None, _Fitter(), _ident({"load_path_friction": False}), 2)
    assert pick is None and model is None and checks == [] and len(records) == 1


def test_the_report_line_gives_the_tests_figures():
    t = {"wald": 21.97, "k": 2, "df_denominator": 7, "p": 0.0069, "alpha": 0.01, "identified": True,
         "interval": "level"}
    assert cc.identified_text(t) == ("; joint Wald 22 (k 2, F on 2 and 7 df, level covariance, p 0.0069 < 0.01): "
                                     "identified")
    assert cc.identified_text({**t, "wald": None}) == ("; joint Wald test not computable (level covariance): "
                                                        "not identified")
