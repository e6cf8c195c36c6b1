"""Named effects keep physical values (issue 28, item 6): ranges carried into the identification, no named effect
together with a generic term that can reproduce it, and no value reported without a standard error."""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop.acceptance import EffectSet, collinear
from l1b2.closeloop.candidates import candidate
from l1b2.closeloop.intervals import added_parameters
from l1b2.predictor import effects as fx
from test_effects_registry import TRAIN


def _df(n=400, seed=0):
    rng = np.random.default_rng(seed)
    run = np.repeat(np.arange(8), n // 8)
    d = np.where(run % 2 == 0, 1, -1)
    load = np.repeat(rng.choice([-0.09, -0.05, 0.0, 0.03, 0.07], 8), n // 8)
    return pd.DataFrame({"time_s": np.arange(n) * 1e-3, "run": run, "position_m": rng.uniform(-0.01, 0.01, n),
                         "voltage_V": np.repeat(rng.choice([220.0, 290.0], 8), n // 8), "direction": d,
                         "load_kg": load, "speed_m_s": 0.1 * d})


def _cand(kind, family=None):
    hs = [h for h in fx.family(kind).grid(TRAIN) if family is None or h.family == family]
    return candidate(None, hs[0])


def test_pulley_coefficient_is_identified_inside_its_physical_range():
    pulley, asym = _cand("load_path_friction"), _cand("direction_asymmetry")
    assert pulley.bounds == ((0.0, 1.0),) and asym.bounds == ()
    eff = EffectSet().add(asym, [0.5, -0.2]).add(pulley, [-22.9])
    extra = eff.extra()
    assert extra.lower == (-np.inf, -np.inf, 0.0) and extra.upper == (np.inf, np.inf, 1.0)
    np.testing.assert_array_equal(eff.start(), [0.5, -0.2, 0.0])     # a start outside the range is moved in
    assert EffectSet().add(asym, [0.1, 0.2]).extra().lower is None


def test_a_generic_term_that_can_reproduce_an_added_effect_is_not_offered():
    df = _df()
    mask = np.ones(len(df), bool)
    eff = EffectSet().add(_cand("load_path_friction"), [0.1])
    smooth_load = _cand("smooth", "smooth_load")          # its |m| column is the pulley's -g|m| up to a factor
    assert collinear(smooth_load, eff, df, mask)
    assert not collinear(_cand("direction_asymmetry"), eff, df, mask)
    assert not collinear(_cand("smooth", "smooth_voltage"), eff, df, mask)
    assert not collinear(smooth_load, EffectSet(), df, mask)


class _Fitted:
    extra_params_ = {"a": 0.2, "b": -22.9}
    extra_stderr_ = {"a": 0.01, "b": float("inf")}
    extra_ci95_ = {"a": (0.18, 0.22), "b": (-np.inf, np.inf)}


def test_a_parameter_without_standard_error_is_named_unidentifiable_not_reported_as_a_value():
    c = candidate(None, fx.Hypothesis("x", "load", "", ("a", "b"), ("1", "N"), {"kind": "drive_saturation"}))
    p = added_parameters(_Fitted(), EffectSet().add(c, [0.2, -22.9]))
    assert p["a"] == {"value": 0.2, "stderr": 0.01, "ci95": [0.18, 0.22], "unit": "1", "unidentifiable": False,
                      "interval": "model"}
    assert p["b"] == {"value": None, "stderr": None, "ci95": None, "unit": "N", "unidentifiable": True}
    with pytest.raises(KeyError):
        added_parameters(type("M", (), {"extra_params_": {}, "extra_stderr_": {}, "extra_ci95_": {}})(),
                    EffectSet().add(c, [0.0, 0.0]))


# ---------------------------------------------------------------------------
# a named effect is never in one model with a generic term it is collinear with; the named form is preferred
# when the evidence does not clearly favour the generic one (plain functions on synthetic matrices)
# ---------------------------------------------------------------------------

from l1b2.closeloop import acceptance as acc   # noqa: E402
from l1b2.closeloop.candidates import CandidateForce   # noqa: E402
from l1b2.closeloop.selection import Score, named_alternatives   # noqa: E402


def _partial_r2(x, y, n):
    """Squared partial correlation of x and y given n (with an intercept), the textbook formula."""
    r = np.corrcoef(np.column_stack([x, y, n]).T)
    rxy, rxn, ryn = r[0, 1], r[0, 2], r[1, 2]
    return (rxy - rxn * ryn) ** 2 / ((1 - rxn ** 2) * (1 - ryn ** 2))


def test_canonical_r2_of_single_columns_is_the_squared_partial_correlation():
    rng = np.random.default_rng(1)
    n = rng.normal(size=300)
    x = 3.0 + 0.8 * n + rng.normal(size=300)
    y = -1.0 + 0.5 * x - 0.9 * n + rng.normal(size=300)
    assert acc.max_canonical_r2(x, y) == pytest.approx(np.corrcoef(x, y)[0, 1] ** 2, rel=1e-10)
    assert acc.max_canonical_r2(x, y, n[:, None]) == pytest.approx(_partial_r2(x, y, n), rel=1e-10)
    assert acc.max_canonical_r2(x, y, n[:, None]) != pytest.approx(np.corrcoef(x, y)[0, 1] ** 2, rel=1e-3)


def test_canonical_r2_is_one_for_a_shared_direction_and_zero_for_orthogonal_spans():
    rng = np.random.default_rng(2)
    a, b, c, N = rng.normal(size=(4, 200))
    X = np.column_stack([a, b])
    # Y holds a combination of X's columns plus nuisance and an offset: the spans share a direction
    Y = np.column_stack([2 * a - b + 5 * N + 7.0, c])
    assert acc.max_canonical_r2(X, Y, N[:, None]) == pytest.approx(1.0, abs=1e-10)
    assert acc.max_canonical_r2(X, Y) < 0.99                      # without the nuisance they do not
    # orthogonal after the intercept: two centred, orthogonal columns
    u = np.tile([1.0, -1.0, 1.0, -1.0], 50)
    w = np.tile([1.0, 1.0, -1.0, -1.0], 50)
    assert acc.max_canonical_r2(u, w + 3.0) == pytest.approx(0.0, abs=1e-12)
    assert acc.max_canonical_r2(np.ones(200), u) == 0.0           # nothing left after the intercept


def test_explained_share_is_the_squared_projection_over_the_squared_norm():
    u = np.tile([1.0, -1.0, 1.0, -1.0], 50)                          # centred and orthogonal to w
    w = np.tile([1.0, 1.0, -1.0, -1.0], 50)
    x = 2.0 * u + 1.0 * w + 4.0
    # |2u|^2 / (|2u|^2 + |w|^2) = 4 / 5 (the offset is the intercept's)
    assert acc.explained_share(x, u) == pytest.approx(0.8, rel=1e-12)
    assert acc.explained_share(x, w) == pytest.approx(0.2, rel=1e-12)
    assert acc.explained_share(x, np.column_stack([u, w])) == pytest.approx(1.0, rel=1e-12)
    # a nuisance that absorbs w: what is left of x is all u's
    assert acc.explained_share(x, u, w[:, None]) == pytest.approx(1.0, rel=1e-12)


def _fe(sse):
    return acc.FoldErrors(np.asarray(sse, float), np.full(len(sse), 100.0))


def _t(family, ext, generic, cur, n=1, phi=None):
    c = CandidateForce(family, "load", "", tuple(f"{family}_{i}" for i in range(n)), ("N",) * n, None,
                       generic=generic)
    return acc.RefitCV(c, cur, _fe(ext), phi=phi)


def test_one_se_gap_is_the_gain_difference_and_the_standard_error_of_the_fold_differences():
    cur = _fe([10.0, 10.0, 10.0, 10.0])
    gen = _t("run_level_x", [2.0, 8.0, 3.0, 7.0], True, cur)        # gain 0.5
    nam = _t("named_x", [5.0, 5.0, 6.0, 8.0], False, cur)           # gain 0.4
    gap, se = acc.one_se_gap(nam, gen)
    # fold differences (5-2, 5-8, 6-3, 8-7) / 10 = (.3, -.3, .3, .1): mean .1, sd (ddof 1) sqrt(.08), se sd / 2
    assert gap == pytest.approx(gen.gain - nam.gain, rel=1e-12) and gap == pytest.approx(0.1, rel=1e-12)
    assert se == pytest.approx(np.sqrt(0.08) / 2.0, rel=1e-12)
    other = _t("named_x", [5.0, 5.0, 6.0, 8.0], False, _fe([10.0, 10.0, 10.0, 11.0]))
    assert acc.one_se_gap(other, gen) is None                       # not the same folds: no paired comparison


def test_the_named_form_replaces_a_collinear_generic_pick_within_one_standard_error():
    cur = _fe([10.0, 10.0, 10.0, 10.0])
    gen = _t("run_level_x", [2.0, 8.0, 3.0, 7.0], True, cur, n=3)  # gain 0.5
    noisy = _t("named_x", [5.0, 5.0, 6.0, 8.0], False, cur)        # gain 0.4: gap 0.1 < se 0.141
    clear = _t("named_x", [3.0, 9.0, 4.0, 8.0], False, cur)        # gain 0.4: gap 0.1 in every fold, se 0
    explains = {"named_x": 0.9}
    share = lambda n, g: explains[n.candidate.family]   # noqa: E731
    assert noisy.gain < 0.9 * gen.gain                                # outside the parsimony band of `prefer`
    assert acc.named_reading(gen, [gen, noisy], share) is noisy
    assert acc.named_reading(gen, [gen, clear], share) is gen        # the generic term is clearly better
    assert acc.named_reading(gen, [gen, noisy], lambda n, g: 0.3) is gen     # it explains too little of it
    assert acc.named_reading(noisy, [gen, noisy], share) is noisy    # a named pick stays
    better = _t("named_y", [2.0, 8.0, 2.5, 7.0], False, cur)        # gain 0.5125: above the generic's
    assert acc.named_reading(gen, [gen, noisy, better], lambda n, g: 0.6) is better
    other_folds = _t("named_x", [5.0, 5.0, 6.0, 8.0], False, _fe([10.0, 10.0, 10.0, 11.0]))
    assert acc.named_reading(gen, [gen, other_folds], share) is gen


def test_named_alternatives_adds_the_best_named_family_that_explains_a_shortlisted_generic_term():
    def score(family, gain, generic):
        c = CandidateForce(family, "load", "", ("p",), ("N",), None, generic=generic)
        return Score(c, gain, 1e-6, 1.0, -10.0, np.ones(1), -10.0)
    gen = score("run_level_x", 0.6, True)
    other_gen = score("smooth_v", 0.3, True)
    strong, weak, tiny = score("named_a", 0.4, False), score("named_b", 0.5, False), score("named_c", 0.01, False)
    shares = {("named_a", "run_level_x"): 0.8, ("named_b", "run_level_x"): 0.2, ("named_c", "run_level_x"): 0.9,
              ("named_a", "smooth_v"): 0.9, ("named_b", "smooth_v"): 0.1, ("named_c", "smooth_v"): 0.9}
    share = lambda n, g: shares[(n.family, g.candidate.family)]   # noqa: E731
    scores = [gen, other_gen, strong, weak, tiny]
    got = named_alternatives([gen, other_gen], scores, share, min_gain=0.05)
    # named_b explains too little, named_c gains too little, each once; offered as a named reading
    assert [s.candidate for s in got] == [strong.candidate] and [s.origin for s in got] == ["named"]
    assert got[0].cv_gain == strong.cv_gain and got[0].phi is strong.phi and strong.origin == "screen"
    assert named_alternatives([gen, strong], scores, share, min_gain=0.05) == []     # already shortlisted
    assert named_alternatives([weak], scores, share, min_gain=0.05) == []             # only for generic terms


def _run_level(df, transform="abs"):
    v = fx.channels.transformed(df.groupby("run", sort=False)["load_kg"].mean().to_numpy(float),
                                df.groupby("run", sort=False)["direction"].first().to_numpy(float), transform)
    h = fx.family("run_level").hypotheses([{"channel": "load_kg", "transform": transform, "mean": float(v.mean()),
                                            "sd": float(v.std())}])[0]
    return candidate(None, h)


def test_a_generic_run_level_load_term_and_the_pulley_friction_are_never_in_one_model():
    # the run-level |load| term's offset column (|m| - mean) / sd is the pulley's -g|m| up to a factor and the
    # intercept: exactly collinear after the nuisance, although neither lies in the other's raw span
    df = _df()
    mask = np.ones(len(df), bool)
    pulley, rl = _cand("load_path_friction"), _run_level(df)
    N = np.column_stack([df["position_m"], df["voltage_V"] / 300.0])
    geo = acc.Directions(df, mask, N)
    assert geo.shared_r2(pulley, rl) == pytest.approx(1.0, abs=1e-9)
    assert not collinear(rl, EffectSet().add(pulley, [0.1]), df, mask)          # the exact test misses it
    assert geo.conflicts(rl, EffectSet().add(pulley, [0.1]))                     # generic after the named one
    assert geo.conflicts(pulley, EffectSet().add(rl, np.zeros(3)))               # and the reverse
    asym = _cand("direction_asymmetry")
    assert not geo.conflicts(asym, EffectSet().add(pulley, [0.1]))               # two named effects: not this rule
    assert not geo.conflicts(_cand("smooth", "smooth_voltage"), EffectSet().add(pulley, [0.1]))
    # the generic term's offset alone is all pulley; its voltage-scaled column much less so
    assert geo.share(pulley, rl, [0.0, 1.0, 0.0]) == pytest.approx(1.0, abs=1e-9)
    assert geo.share(pulley, rl, [1.0, 0.0, 0.0]) < geo.share(pulley, rl, [0.0, 1.0, 0.0])
