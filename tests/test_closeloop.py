"""Close the loop on virtual-rig data with undeclared effects (issue 5).

Each effect is injected into the co-simulated motor (a declared FMU parameter
that is off in the reference), never declared to the model; its size and
parameters are drawn from the effect's range with a per-case seed. The test
set is used only for the before/after report, never for fitting or choosing.

Fast set (``make test``): four effects, one seed each, plus two controls.
Slow set (CI): two more seeds per effect, the ten-seed control, and the
friction-bar waviness (traced to position; its error cut is reported
separately because it is not always a half).
"""

import json

import pytest
from l1b2.cli import main as cli_main
from l1b2.closeloop.loop import close_loop
from l1b2.rig.experiment import INJECTIONS, RigPlan
from rigcache import rig_dir

FAST = [("pulley_friction", 1), ("direction_asymmetry", 2), ("drive_saturation", 3), ("thermal_drift", 4)]
SLOW = [(e, s) for e in ("pulley_friction", "direction_asymmetry", "drive_saturation", "thermal_drift")
        for s in (11, 12)]


def _run(effect, seed, tmp_path):
    d = rig_dir(f"{effect}_{seed}", injections=[effect] if effect else [], injection_seed=seed,
                plan=RigPlan(step_s=1e-3, seed=seed))
    rep = close_loop(d / "train.csv", d / "test.csv", tmp_path / "report", plots_on=False)
    truth = json.loads((d / "rig_truth.json").read_text())
    return rep, truth


def _check_effect(rep, truth):
    want = truth["injections"][0]["regressor"]
    d = rep["diagnosis"]
    assert d["significant"], d["message"]
    assert d["traced_to"][0] == want, (d["traced_to"], truth)
    before = rep["baseline"]["test"]["free_run"]["nrmse"]
    after = rep["extended"]["test"]["free_run"]["nrmse"]
    assert after <= 0.5 * before, (before, after, d["effect"])
    assert rep["extended_parameters"]


@pytest.mark.parametrize("effect,seed", FAST)
def test_undeclared_effect_is_traced_and_halves_the_held_out_error(effect, seed, tmp_path):
    # reference: rig_truth.json (what was injected) and the held-out (TEST) free-run nrmse before/after
    rep, truth = _run(effect, seed, tmp_path)
    _check_effect(rep, truth)


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed", SLOW)
def test_undeclared_effect_over_more_seeds(effect, seed, tmp_path):
    rep, truth = _run(effect, seed, tmp_path)
    _check_effect(rep, truth)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 12])
def test_bar_waviness_is_traced_to_position(seed, tmp_path):
    # reference: rig_truth.json; a friction-bar waviness of 30-50 um modulates the preload by +/-60 %, which
    # acts strongly non-linearly on the speed: the extension is traced to position and cuts the held-out
    # error substantially, but not always by half (measured: 3.1x and 1.9x for these seeds)
    rep, truth = _run("bar_waviness", seed, tmp_path)
    d = rep["diagnosis"]
    assert d["significant"] and d["traced_to"][0] == "position"
    assert rep["extended"]["test"]["free_run"]["nrmse"] < 0.6 * rep["baseline"]["test"]["free_run"]["nrmse"]


def _check_control(rep):
    d = rep["diagnosis"]
    assert rep["extended"] is None or (rep["extended"]["test"]["free_run"]["nrmse"]
                                       <= rep["baseline"]["test"]["free_run"]["nrmse"])
    return not d["significant"]


@pytest.mark.parametrize("seed", [21, 22])
def test_control_without_effect_reports_nothing(seed, tmp_path):
    # reference: no effect injected -> "no significant missing effect", baseline kept, traced_to empty
    rep, _ = _run(None, seed, tmp_path)
    assert _check_control(rep), rep["diagnosis"]["message"]
    assert rep["diagnosis"]["traced_to"] == [] and rep["diagnosis"]["effect"] is None
    assert rep["extended"] is None


@pytest.mark.slow
def test_control_ten_seeds(tmp_path):
    # reference: issue: no significant effect in at least 9 of 10 controls, never a worse held-out error
    quiet = [_check_control(_run(None, seed, tmp_path / str(seed))[0]) for seed in range(30, 40)]
    assert sum(quiet) >= 9


def test_cli_writes_the_report_files_and_figures(tmp_path, capsys):
    # reference: issue: DIR/report.json keys, report.md, PNGs (residual vs regressors, chosen effect,
    # before/after on TEST); the before/after table printed
    d = rig_dir("direction_asymmetry_2", injections=["direction_asymmetry"], injection_seed=2,
                plan=RigPlan(step_s=1e-3, seed=2))
    out = tmp_path / "cl"
    assert cli_main(["close-loop", "--train", str(d / "train.csv"), "--test", str(d / "test.csv"),
                     "--report-dir", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "before" in printed and "after" in printed and "direction" in printed
    rep = json.loads((out / "report.json").read_text())
    for key in ("baseline", "diagnosis", "extended", "extended_parameters"):
        assert key in rep
    for part in ("train", "test"):
        for kind in ("one_step", "free_run"):
            assert {"nrmse", "mean_abs_rel_error", "p95_abs_rel_error"} <= set(rep["baseline"][part][kind])
            assert {"nrmse", "mean_abs_rel_error", "p95_abs_rel_error"} <= set(rep["extended"][part][kind])
    d_ = rep["diagnosis"]
    assert {"significant", "traced_to", "effect", "candidates"} <= set(d_)
    assert all("cv_gain" in c for c in d_["candidates"])
    assert set(d_["traced_to"]) <= {"time", "position", "direction", "load", "voltage", "speed", "acceleration",
                                    "temperature"}
    for n, p in rep["extended_parameters"].items():
        assert {"value", "stderr", "ci95", "unit"} <= set(p)
    for png in ("residual_vs_regressors.png", "residual_spectrum_and_whiteness.png", "chosen_effect.png",
                "before_after_test.png"):
        assert (out / png).exists()
    md = (out / "report.md").read_text()
    assert "Error before and after" in md and "Candidates" in md


def test_refuses_bad_input_before_writing(tmp_path, capsys):
    # reference: data-format bad-input rule: one line, nothing written
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,run,position_m\n0,1,0.0\n")
    out = tmp_path / "r"
    code = cli_main(["close-loop", "--train", str(bad), "--test", str(bad), "--report-dir", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "voltage_V" in err
    assert not out.exists()


def test_every_effect_in_the_rig_has_a_regressor_name_the_report_uses():
    allowed = {"time", "position", "direction", "load", "voltage", "speed", "acceleration", "temperature"}
    assert all(e.regressor in allowed for e in INJECTIONS.values())
