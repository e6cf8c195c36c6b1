"""Folds of whole conditions for the candidates that do not depend on the session clock (issue 28, item 7).

The fold rule is written out here (conditions shuffled by the seed, ordered by stratum, dealt in turn) and checked
with its stated properties: every run held out once, a condition never split, the strata balanced, seeded, and
:func:`~l1b2.closeloop.folds.stratified_folds` when every condition is one run. The loop's setting
``fold_unit`` is followed to the refit's folds and to the folds the screen scores on.
"""

import types

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import acceptance as acc
from l1b2.closeloop import folds as fo
from l1b2.closeloop import residuals as res
from l1b2.closeloop.loop import CloseLoop


def _plan_frame(seed=11, voltages=(220.0, 255.0, 290.0, 324.0), loads=(-0.09, -0.07, -0.03, 0.0, 0.03, 0.07, 0.09)):
    """The rig's protocol: every (V0, load) once in a shuffled order, each run forward then backward, 3 samples a
    run. Returns the frame (rows in session order) and its conditions written out (run ids, in session order)."""
    conds = [(V, L) for V in voltages for L in loads]
    conds = [conds[i] for i in np.random.default_rng(seed).permutation(len(conds))]
    rows, units, r = [], [], 0
    for V, L in conds:
        units.append([])
        for d in (1, -1):
            rows.append(pd.DataFrame({"run": 100 + r, "time_s": 2.0 * r + np.arange(3) * 0.1, "voltage_V": V,
                                      "load_kg": L, "direction": d}))
            units[-1].append(100 + r)
            r += 1
    return pd.concat(rows, ignore_index=True), units


def _irregular_frame():
    """Conditions of one, two and three runs; (255, 0.0) measured twice apart in the session (its runs 502, 503 and
    509); two neighbouring conditions at one V0 with different loads. Rows in session order, run ids in order."""
    plan = [(324.0, 0.03, 1), (324.0, 0.03, -1), (255.0, 0.0, 1), (255.0, 0.0, -1), (220.0, -0.07, 1),
            (220.0, -0.07, -1), (220.0, -0.07, 1), (220.0, 0.09, 1), (220.0, 0.09, -1), (255.0, 0.0, 1),
            (290.0, 0.07, -1), (324.0, -0.03, 1), (324.0, -0.03, -1), (290.0, 0.0, 1), (290.0, 0.0, -1)]
    rows = [pd.DataFrame({"run": 500 + j, "time_s": 2.0 * j + np.arange(3) * 0.1, "voltage_V": V, "load_kg": L,
                          "direction": d}) for j, (V, L, d) in enumerate(plan)]
    units = [[500, 501], [502, 503, 509], [504, 505, 506], [507, 508], [510], [511, 512], [513, 514]]
    return pd.concat(rows, ignore_index=True), units


def _dealt_written_out(df, units, k, seed):
    """The rule: the conditions (in the order their first run appears) permuted by ``default_rng(seed)``, sorted
    stably by (mean direction of their runs, V0), condition j of that order to fold j mod k."""
    first = df.groupby("run")[["direction", "voltage_V"]].first()
    perm = np.random.default_rng(seed).permutation(len(units))

    def key(pos):
        u = units[perm[pos]]
        return (float(np.mean([first.loc[r, "direction"] for r in u])), float(first.loc[u[0], "voltage_V"]), pos)
    ranked = [perm[pos] for pos in sorted(range(len(units)), key=key)]
    k = min(k, len(units))
    return [[r for j, u in enumerate(ranked) if j % k == i for r in units[u]] for i in range(k)]


def test_condition_units_group_the_runs_of_one_drive_amplitude_and_load_wherever_they_lie():
    df, units = _irregular_frame()
    assert [u.tolist() for u in fo.condition_units(df)] == units
    # the rows' order decides only the units' order (first appearance), not their content
    shuffled = df.sample(frac=1.0, random_state=2)
    assert sorted(sorted(u.tolist()) for u in fo.condition_units(shuffled)) == sorted(units)
    # without the condition columns: one unit per run
    assert [u.tolist() for u in fo.condition_units(df.drop(columns=["voltage_V", "load_kg"]))] == [
        [r] for r in range(500, 515)]
    plan, plan_units = _plan_frame()
    assert [u.tolist() for u in fo.condition_units(plan)] == plan_units


@pytest.mark.parametrize("k", [2, 3, 4, 5])
@pytest.mark.parametrize("case", ["plan", "irregular"])
def test_condition_folds_deal_whole_conditions_in_turn_within_strata(k, case):
    df, units = _plan_frame() if case == "plan" else _irregular_frame()
    folds = fo.condition_folds(df, k, seed=7)
    assert [f.tolist() for f in folds] == _dealt_written_out(df, units, k, 7)            # the rule written out
    runs = [r for u in units for r in u]
    assert sorted(np.concatenate(folds).tolist()) == sorted(runs)                       # every run held out once
    fold_of = {r: i for i, f in enumerate(folds) for r in f.tolist()}
    assert all(len({fold_of[r] for r in u}) == 1 for u in units)                         # no condition split
    first = df.groupby("run")[["direction", "voltage_V"]].first()
    strata: dict = {}
    for u in units:
        strata.setdefault((first.loc[u, "direction"].mean(), first.loc[u[0], "voltage_V"]), []).append(fold_of[u[0]])
    for members in strata.values():                                                       # balanced per stratum
        counts = [members.count(i) for i in range(k)]
        assert max(counts) - min(counts) <= 1, counts
    if case == "plan":       # every condition forward and backward: both directions equally in every fold
        assert all(first.loc[f, "direction"].sum() == 0 for f in folds)
        sizes = [len(f) for f in folds]
        assert max(sizes) - min(sizes) <= 2
    # seeded: the same seed gives the same folds; another seed other folds (seven conditions in each stratum)
    assert [f.tolist() for f in fo.condition_folds(df, k, seed=7)] == [f.tolist() for f in folds]
    if case == "plan":
        assert [f.tolist() for f in fo.condition_folds(df, k, seed=8)] != [f.tolist() for f in folds]


def test_condition_folds_of_one_run_per_condition_are_the_stratified_run_folds():
    rng = np.random.default_rng(3)
    df = pd.concat([pd.DataFrame({"run": r, "time_s": r + np.arange(3) * 0.1, "direction": rng.choice([-1, 1]),
                                  "voltage_V": rng.choice([220.0, 255.0, 290.0]), "load_kg": 0.001 * r})
                    for r in rng.permutation(29)], ignore_index=True)
    for k, seed in ((2, 0), (4, 7), (5, [7, 1])):
        assert [f.tolist() for f in fo.condition_folds(df, k, seed)] == [
            f.tolist() for f in fo.stratified_folds(df, k, seed)]


def test_the_refit_and_the_screen_take_their_folds_by_the_unit():
    df, _ = _plan_frame()
    mask = np.ones(len(df), bool)
    mask[df["run"].to_numpy() == 103] = False                       # a run without a sample on the mask
    for unit in ("run", "condition"):
        s = fo.refit_schemes(df, 4, 2, seed=5, unit=unit)
        split = fo.stratified_folds if unit == "run" else fo.condition_folds
        assert [f.tolist() for f in s[False]] == [f.tolist() for seed in (5, [5, 1]) for f in split(df, 4, seed)]
        assert [f.tolist() for f in s[True]] == [f.tolist() for f in fo.session_blocks(df, 4)]
        assert [f.tolist() for f in fo.unit_folds(df, 4, 5, unit)] == [f.tolist() for f in split(df, 4, 5)]
    # the screen: the runs on the mask shuffled and dealt (as before), or whole conditions of the runs on the mask
    folds, blocks = fo.screen_folds(df, mask, 5, 3, "rotation", "run")
    assert [f.tolist() for f in folds] == [f.tolist() for f in res.run_folds(df["run"].to_numpy()[mask], 5, 3)]
    assert [f.tolist() for f in blocks] == [f.tolist() for f in fo.session_rotation(df, 5)]
    folds, _ = fo.screen_folds(df, mask, 5, 3, "blocks", "condition")
    assert [f.tolist() for f in folds] == [f.tolist() for f in fo.condition_folds(df[mask], 5, 3)]
    assert 103 not in np.concatenate(folds) and 102 in np.concatenate(folds)
    for call in (lambda: fo.unit_folds(df, 4, 0, "conditions"), lambda: fo.screen_folds(df, mask, 4, 0, "blocks",
                                                                                             "runs")):
        with pytest.raises(ValueError, match="fold_unit"):
            call()


@pytest.mark.parametrize("unit", ["run", "condition"])
def test_the_loop_folds_the_other_candidates_by_its_setting(unit, monkeypatch):
    """``_iterate`` asks the refit's folds and the screen's for its ``fold_unit`` and scores on the screen's."""
    from l1b2.closeloop import loop as loop_mod
    df, _ = _plan_frame()
    mask = np.ones(len(df), bool)
    seen, scored = [], {}

    class Stop(Exception):
        pass

    real_refit = fo.refit_schemes

    def refit_spy(d, k, repeats, seed, clock, u, first=None):
        seen.append((k, seed, u, first))
        return real_refit(d, k, repeats, seed, clock, u, first)

    def score_spy(*args, **kw):
        scored.update(kw)
        raise Stop
    monkeypatch.setattr(loop_mod, "refit_schemes", refit_spy)
    monkeypatch.setattr(loop_mod, "score_candidates", score_spy)
    monkeypatch.setattr(loop_mod, "Directions", lambda *a: None)
    monkeypatch.setattr(loop_mod, "nuisance_forces", lambda *a: None)
    monkeypatch.setattr(loop_mod.res, "drive_residual", lambda d, v: np.zeros(len(d)))
    model = types.SimpleNamespace(predict_free_run=lambda d: np.zeros(len(d)), params_=None)
    it = types.SimpleNamespace(rounds=[{}], model=model, effects=acc.EffectSet())
    assert CloseLoop().fold_unit == "run"                                   # the default: runs, as before
    est = CloseLoop(fold_unit=unit, k_folds=5, refit_folds=3, seed=4)
    assert est.get_params()["fold_unit"] == unit
    run_folds = fo.stratified_folds(df, 3, 4)        # the fit's run folds, as CloseLoop.fit hands them on
    with pytest.raises(Stop):
        est._iterate(it, [], df, mask, 0.1, None, lambda *a: None, folds=run_folds)
    # the run folds are reused as split 0 only when the unit is the run; condition folds are computed afresh
    assert seen == [(3, 4, unit, run_folds if unit == "run" else None)]
    want, blocks = fo.screen_folds(df, mask, 5, 4, "blocks", unit)
    assert [f.tolist() for f in scored["folds"]] == [f.tolist() for f in want]
    assert [f.tolist() for f in scored["time_folds"]] == [f.tolist() for f in blocks]
    if unit == "condition":
        assert [f.tolist() for f in want] == [f.tolist() for f in fo.condition_folds(df, 5, 4)]
