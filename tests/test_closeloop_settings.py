"""The close loop's settings as one frozen record (:mod:`l1b2.closeloop.settings`) behind ``CloseLoop(...)``, and
the run folds they define, computed once per fit."""

import dataclasses
import json

import numpy as np
import pytest
from l1b2.closeloop.loop import CloseLoop, close_loop
from l1b2.closeloop.settings import LoopSettings
from l1b2.data.measurements import Measurements
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

#: the constructor's keywords and defaults, in order, written out
DEFAULTS = {"order": 8, "k_folds": 5, "alpha": 0.01, "min_gain": 0.05, "parsimony": 0.9, "seed": 0, "n_starts": 4,
            "library": None, "progress": None, "max_rounds": 3, "shortlist": 2, "refit_folds": 4,
            "refit_repeats": 1, "tie_repeats": 3, "min_cv_gain": 0.03, "min_cv_drop": 0.005, "refit_nfev": 10,
            "final_nfev": 60,
            "screen_alpha": 0.01, "noise_fit": "alternate", "noise": "common", "client": None, "baseline": "eq29",
            "run_level": True, "session_cycle": False, "stroke_speed_gain": False, "response_columns": None,
            "clock_folds": "blocks",
            "fold_unit": "run"}

#: settings other than the defaults for every rule the report records
CHANGED = {"order": 3, "n_starts": 1, "max_rounds": 0, "min_gain": 0.07, "alpha": 0.02, "parsimony": 0.8,
           "k_folds": 3, "shortlist": 1, "refit_folds": 2, "refit_repeats": 2, "tie_repeats": 5, "min_cv_gain": 0.04,
           "min_cv_drop": 0.006, "screen_alpha": None, "noise_fit": "profile", "noise": "per_run",
           "run_level": False, "session_cycle": True, "stroke_speed_gain": True, "clock_folds": "rotation",
           "response_columns": ("aux_a", "aux_b"),
           "fold_unit": "condition"}


def small_train(seed=1):
    """Twelve noisy runs of the Eq. 29 predictor itself (order 3), as validated measurements."""
    df = simulate_dataset(example_params(3), design_grid(voltages=(220.0, 324.0), loads=(-0.05, 0.0, 0.05)), 0.1,
                          noise_std=1e-3, seed=seed)
    return Measurements(df=df, meta={"slider_mass_kg": 0.1}, path="train.csv")


def test_the_settings_are_the_constructors_keywords_in_one_frozen_record():
    est = CloseLoop()
    assert est.get_params() == DEFAULTS and list(est.get_params()) == list(DEFAULTS)
    assert est.settings == LoopSettings() and est.settings.as_dict() == DEFAULTS
    est = CloseLoop(**CHANGED)
    assert est.get_params() == {**DEFAULTS, **CHANGED}
    assert (est.k_folds, est.noise, est.clock_folds, est.refit_repeats) == (3, "per_run", "rotation", 2)
    assert est.settings == LoopSettings(**CHANGED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.settings.seed = 4
    assert est.set_params(seed=4) is est and est.settings.seed == 4 == est.seed
    with pytest.raises(TypeError, match="gamma"):
        CloseLoop(gamma=1.0)
    with pytest.raises(TypeError):
        CloseLoop(8)            # keywords only


def test_the_report_records_the_rules_as_given():
    # reference: the rules written out for settings other than the defaults; the list of response columns as a
    # list (JSON), in report.json as in the result
    rules = {"min_gain": 0.07, "alpha": 0.02, "parsimony": 0.8, "k_folds": 3, "shortlist": 1, "refit_folds": 2,
             "refit_repeats": 2, "tie_repeats": 5, "min_cv_gain": 0.04, "min_cv_drop": 0.006, "screen_alpha": None,
             "noise_fit": "profile", "noise": "per_run", "fold_unit": "condition", "max_rounds": 0, "run_level": False,
             "session_cycle": True, "stroke_speed_gain": True, "clock_folds": "rotation",
             "response_columns": ["aux_a", "aux_b"]}
    assert CloseLoop(**CHANGED).settings.rules() == rules
    res = close_loop(small_train(), **CHANGED)
    got = res.diagnosis["rules"]
    assert got == rules and list(got) == list(rules)
    assert json.loads(json.dumps(res.to_dict()))["diagnosis"]["rules"] == rules
    assert np.isfinite(res.baseline["train"]["free_run"]["nrmse"])


def test_trains_run_folds_are_computed_once_per_fit_and_shared_by_their_three_users(monkeypatch):
    # reference: stratified_folds(TRAIN, refit_folds, seed) computed independently; the baseline's choice, the
    # measurement chain's cross-validation and split 0 of the rounds' refit folds get that one list (the chain's
    # test made to accept a filter, so that the chain is cross-validated; both families, so that one is chosen)
    from l1b2.closeloop import folds as fo
    import l1b2.closeloop.loop as loop_mod
    from l1b2.closeloop.chain import OutputFilter
    real, calls, seen = fo.stratified_folds, [], {}

    def spy(df, k, seed=0):
        calls.append(seed)
        return real(df, k, seed)

    def spy_on(name, key, at):
        fn = getattr(loop_mod, name)

        def wrapped(*args, **kwargs):
            out = fn(*args, **kwargs)
            seen[key] = args[at] if at is not None else out
            return out
        monkeypatch.setattr(loop_mod, name, wrapped)

    monkeypatch.setattr(fo, "stratified_folds", spy)
    monkeypatch.setitem(fo.UNIT_FOLDS, "run", spy)      # the run folds as the refit's splits ask for them
    monkeypatch.setattr(loop_mod, "stratified_folds", spy)
    spy_on("choose_baseline", "baseline", 4)
    spy_on("chain_cv_errors", "chain", 3)
    spy_on("refit_schemes", "refit", None)
    monkeypatch.setattr(loop_mod.chain, "speed_channel", lambda df, mask, k, seed: {
        "accepted": True, "filter": OutputFilter(), "cv_gain": 0.0})
    train = small_train()
    close_loop(train, order=3, n_starts=1, max_rounds=0, run_level=False, baseline="best", refit_folds=3,
               refit_repeats=2, seed=3)
    assert calls == [3, [3, 1]]                   # split 0 once; split 1 of the repeated folds on its own stream
    monkeypatch.undo()
    want = fo.stratified_folds(train.df, 3, 3)
    assert seen["baseline"] is seen["chain"] and [f.tolist() for f in seen["baseline"]] == [f.tolist() for f in want]
    refit = seen["refit"][False]
    assert all(a is b for a, b in zip(refit[:3], seen["baseline"]))
    assert [f.tolist() for f in refit] == [f.tolist() for f in fo.repeated_folds(train.df, 3, 2, 3)]


@pytest.mark.parametrize("flags, message", [
    (["--clock-folds", "weekly"], "l1b2: error: --clock-folds must be one of blocks, rotation, got 'weekly'"),
    (["--fold-unit", "session"], "l1b2: error: --fold-unit must be one of run, condition, got 'session'"),
    (["--refit-repeats", "0"], "l1b2: error: --refit-repeats must be a whole number >= 1, got '0'"),
    (["--refit-repeats", "two"], "l1b2: error: --refit-repeats must be a whole number >= 1, got 'two'"),
    (["--refit-repeats", "1.5"], "l1b2: error: --refit-repeats must be a whole number >= 1, got '1.5'"),
    (["--tie-repeats", "0"], "l1b2: error: --tie-repeats must be a whole number >= 1, got '0'"),
])
def test_a_bad_fold_flag_is_one_line_before_any_file_is_read(tmp_path, capsys, flags, message):
    from l1b2.cli import main
    out = tmp_path / "cl"
    code = main(["close-loop", "--train", str(tmp_path / "absent.csv"), "--out", str(out), "--quiet",
                 "--no-plots", "--workers", "1"] + flags)
    err = capsys.readouterr().err
    assert code == 2 and err == message + "\n" and not out.exists()


def test_the_fold_flags_reach_the_loop_and_its_report(tmp_path):
    # reference: the values given on the command line are the report's rules; the flags' defaults are the loop's
    from l1b2 import cli
    from l1b2.closeloop.folds import CLOCK_FOLDS, UNIT_FOLDS
    assert set(cli.CLOCK_FOLDS) == set(CLOCK_FOLDS) and set(cli.FOLD_UNITS) == set(UNIT_FOLDS)
    args = cli.build_parser().parse_args(["close-loop", "--train", "x.csv", "--out", "o"])
    assert cli._fold_settings(args) == {"clock_folds": LoopSettings().clock_folds, "fold_unit": LoopSettings().fold_unit,
                                        "refit_repeats": LoopSettings().refit_repeats,
                                        "tie_repeats": LoopSettings().tie_repeats}
    for name, seed in (("train", 1), ("test", 2)):
        small_train(seed).df.to_csv(tmp_path / f"{name}.csv", index=False)
    out = tmp_path / "cl"
    assert cli.main(["close-loop", "--train", str(tmp_path / "train.csv"), "--test", str(tmp_path / "test.csv"),
                     "--slider-mass", "0.1", "--order", "3", "--max-rounds", "0", "--out", str(out), "--quiet",
                     "--no-plots", "--workers", "1", "--clock-folds", "rotation", "--refit-repeats", "3",
                     "--fold-unit", "condition", "--tie-repeats", "4"]) == 0
    rules = json.loads((out / "report.json").read_text())["diagnosis"]["rules"]
    assert (rules["clock_folds"], rules["refit_repeats"], rules["max_rounds"]) == ("rotation", 3, 0)
    assert rules["fold_unit"] == "condition" and rules["tie_repeats"] == 4
