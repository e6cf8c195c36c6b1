"""Close the loop on virtual-rig data with undeclared effects (issue 5).

Each effect is injected into the co-simulated motor (a declared FMU parameter
that is off in the reference), never declared to the model; its size and
parameters are drawn from the effect's range with a per-case seed. The test
set is used only for the before/after report, never for fitting or choosing.

Fast set (``make test``): four effects, one seed each, plus two controls, and thermal drift with the
stator temperature logged (traced to the temperature).
Slow set (``make test-slow``, not in CI: it does not fit CI's time): two more
seeds per effect, the ten-seed control, and the friction-bar waviness (traced to position; its error cut is reported
separately because it is not always a half).
"""

import functools
import json

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from l1b2.closeloop.calibrated import frame_free_run
from l1b2.closeloop.candidates import (CandidateLibrary, Context, combine, default_library, full_library,
                                       generic_candidates, generic_library, named_candidates, named_library)
from l1b2.closeloop.loop import CloseLoop, close_loop, order_traced
from l1b2.closeloop.result import CloseLoopResult
from l1b2.data.measurements import load_measurements
from l1b2.rig.experiment import INJECTIONS, RigPlan
from rigcache import assert_round_trips, case_row, rig_dir

FAST = [("pulley_friction", 1), ("direction_asymmetry", 2), ("drive_saturation", 3), ("thermal_drift", 4)]
SLOW = [(e, s) for e in ("pulley_friction", "direction_asymmetry", "drive_saturation", "thermal_drift")
        for s in (11, 12)]


@functools.cache
def _run(effect, seed, record_temperature=False):
    d = rig_dir(f"{effect}_{seed}{'_T' if record_temperature else ''}", injections=[effect] if effect else [],
                injection_seed=seed, plan=RigPlan(step_s=1e-3, seed=seed, record_temperature=record_temperature))
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    assert_round_trips(res)
    truth = json.loads((d / "rig_truth.json").read_text())
    return res, truth


def _check_effect(res, truth, case, record, want=None):
    record("case", case_row("reference", case, res))
    want = want or truth["injections"][0]["regressor"]
    d = res.diagnosis
    assert d["significant"], d["message"]
    assert d["traced_to"][0] == want, (d["traced_to"], truth)
    before = res.before["test"]["free_run"]["nrmse"]
    after = res.after["test"]["free_run"]["nrmse"]
    assert after <= 0.5 * before, (before, after, d["effect"])
    assert res.extended_parameters


@pytest.mark.parametrize("effect,seed", FAST)
def test_undeclared_effect_is_traced_and_halves_the_held_out_error(effect, seed, record_property):
    # reference: rig_truth.json (what was injected) and the held-out (TEST) free-run nrmse before/after
    res, truth = _run(effect, seed)
    _check_effect(res, truth, f"{effect} {seed}", record_property)


def test_logged_stator_temperature_is_traced_and_used(record_property):
    # reference: data-format's optional temperature_C column (the stator temperature, when the rig measures it):
    # the self-heating drift of thermal_drift 4 is then traced to the temperature, not to the clock, and modelled
    # by it (thermal_drift_T); the cut as for the other effects
    res, truth = _run("thermal_drift", 4, record_temperature=True)
    _check_effect(res, truth, "thermal_drift 4, temperature logged", record_property, want="temperature")
    assert res.diagnosis["effects"][0]["effect"] == "thermal_drift_T"


@pytest.fixture(scope="module")
def pulley_export(tmp_path_factory):
    """``(folder, manifest)``: ``export_close_loop`` of pulley_friction 1's result with its TEST runs (Predictor.fmu,
    the native FMUs, the calibrated SSP and its held-out check), written once for the two tests that read it."""
    from l1b2.workflows import export_close_loop
    res, _ = _run("pulley_friction", 1)
    d = rig_dir("pulley_friction_1", injections=["pulley_friction"], injection_seed=1,
                plan=RigPlan(step_s=1e-3, seed=1))
    out = tmp_path_factory.mktemp("pulley_friction_1") / "exp"
    return out, export_close_loop(res, out, test=load_measurements(d / "test.csv"))


def test_export_of_the_calibrated_model(pulley_export, isolated):
    # reference: the close-the-loop estimator's own free-run prediction of TEST (1e-10 relative), for the
    # serialisable model and for Predictor.fmu through fmpy (one TEST run); the manifest names each effect's home
    from pathlib import Path
    res, _ = _run("pulley_friction", 1)
    ep = res.calibrated_model
    assert [e.label for e in ep.effects] == [e["label"] for e in res.diagnosis["effects"]
                                             if e["effect"] != "speed_channel_filter"]
    assert ep.effects, res.diagnosis["message"]
    dte = res.test_df
    want = res.extended_model.predict_free_run(dte)
    np.testing.assert_allclose(frame_free_run(ep, dte), want, rtol=1e-10, atol=1e-13)
    exp, manifest = pulley_export
    fam = {e["family"]: e for e in manifest["effects"]}
    assert fam["load_path_friction"]["subsystems"]["home"] == "Slider.pulley_mu"
    assert all(e["predictor_fmu"] == "fmus/Predictor.fmu" for e in manifest["effects"])
    run = dte[dte["run"] == dte["run"].iloc[0]]
    r = {"t": run["time_s"].tolist(), "s": run["position_m"].tolist(), "V0": run["voltage_V"].tolist(),
         "load": run["load_kg"].tolist(), "d": run["direction"].tolist(), "T": run["time_s"].tolist(),
         "v_start": float(run["speed_m_s"].iloc[0])}
    got = isolated(str(Path(__file__).with_name("test_extended_predictor_fmu.py")), "worker_fmpy",
                   {"fmu": str(exp / "fmus" / "Predictor.fmu")}, [r], r["t"][0]).value["fmu"][0]
    np.testing.assert_allclose(got, want[: len(run)], rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("effect,seed,home", [("pulley_friction", 1, "Slider.pulley_mu"),
                                              ("direction_asymmetry", 2, "Stator.asym_b")])
def test_calibrated_ssp_carries_the_identified_effect(effect, seed, home, isolated, request):
    # reference: rig_truth.json (the injected parameter, within 10 %) and the held-out runs: the calibrated SSP's
    # free-run nrmse is at most 1 pp above the extended predictor's and below half the uncalibrated SSP's;
    # libcosim loads the calibrated SSP with the calibrated parameter. The exports with the TEST runs made once
    # for the module: pulley_friction 1 by export_close_loop (pulley_export), direction_asymmetry 2 by
    # `l1b2 close-loop --export` (cli_run: the same loop on the same runs, its result checked equal to _run's
    # in test_close_loop_without_a_test_file_holds_out_the_papers_runs)
    from pathlib import Path
    res, truth = _run(effect, seed)
    if effect == "direction_asymmetry":
        cli = request.getfixturevalue("cli_run")
        out, res = cli["export"], cli["result"]
        man = json.loads((out / "calibrated_manifest.json").read_text())
    else:
        out, man = request.getfixturevalue("pulley_export")
    got = man["calibrated_ssp"]["changed"][home]
    assert got == pytest.approx(truth["injections"][0]["parameters"][home], rel=0.1)
    if effect == "direction_asymmetry":   # the calibrated value's delta-method standard error (decision 0063)
        se = next(e for e in man["effects"] if e["family"] == effect)["subsystems"]["stderr"][home]
        assert 0 < se < 0.1 * abs(got), se
    chk = man["held_out_check"]
    assert chk["extended_predictor_nrmse"] == pytest.approx(res.after["test"]["free_run"]["nrmse"], rel=1e-9)
    assert chk["calibrated_ssp_nrmse"] <= chk["extended_predictor_nrmse"] + 0.01, chk
    assert chk["calibrated_ssp_nrmse"] < 0.5 * chk["uncalibrated_ssp_nrmse"], chk
    assert (out / "held_out_ssp.png").is_file() and (out / "calibrated_ssv" / "Slider.ssv").is_file()
    pytest.importorskip("libcosimpy")
    inputs = {"V_s": 67.1, "duty": 1.0, "f_s": 48500.0, "T": 25.0, "direction": 1.0, "m_load": 0.0}
    lc = isolated(str(Path(__file__).with_name("test_libcosim.py")), "worker_libcosim",
                  str(out / "L1B2Motor_calibrated_libcosim.ssp"), 0.002, inputs, {"Slider.s0": 0.0, "Stator.s": 0.0},
                  [home], 2e-4).value
    np.testing.assert_allclose(lc[home], got, rtol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed", SLOW)
def test_undeclared_effect_over_more_seeds(effect, seed, record_property):
    res, truth = _run(effect, seed)
    _check_effect(res, truth, f"{effect} {seed}", record_property)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 12])
def test_bar_waviness_is_traced_to_position(seed, record_property):
    # reference: rig_truth.json; a friction-bar waviness of 30-50 um modulates the preload by +/-60 %, which
    # acts strongly non-linearly on the speed: the extension is traced to position and cuts the held-out
    # error substantially, but not always by half (measured: 3.1x and 1.9x for these seeds)
    res, truth = _run("bar_waviness", seed)
    record_property("case", case_row("reference", f"bar_waviness {seed}", res))
    d = res.diagnosis
    assert d["significant"] and d["traced_to"][0] == "position"
    assert res.after["test"]["free_run"]["nrmse"] < 0.6 * res.before["test"]["free_run"]["nrmse"]


def _check_control(res):
    d = res.diagnosis
    assert res.extended is None or (res.extended["test"]["free_run"]["nrmse"]
                                    <= res.baseline["test"]["free_run"]["nrmse"])
    return not d["significant"]


@pytest.mark.parametrize("seed", [21, 22])
def test_control_without_effect_reports_nothing(seed, record_property):
    # reference: no effect injected -> "no significant missing effect", baseline kept, traced_to empty
    res, _ = _run(None, seed)
    record_property("case", case_row("reference", f"clean {seed}", res))
    assert _check_control(res), res.diagnosis["message"]
    assert res.diagnosis["traced_to"] == [] and res.diagnosis["effect"] is None
    assert res.extended is None
    _check_reasons(res)


def _check_reasons(res):
    """Every significant row of channels_considered that added nothing says why, in line with the refit trials,
    and the report's table shows it."""
    d = res.diagnosis
    refit = {(r, t["effect"]) for r, rnd in enumerate(d["refit_trials"], 1) for t in rnd}
    md = res.markdown()
    for row in d["channels_considered"]:
        why = row["not_added"]
        assert (why is not None) == (row["significant"] and not row["added"]), row
        assert why is None or f"no: {why}" in md, why
        if why and why.startswith("refit in round "):
            assert (int(why.split()[3].rstrip(":")), f"channel_{row['channel']}") in refit or any(
                (int(why.split()[3].rstrip(":")), f"run_level_{e['signal']}") in refit for e in row["run_level"])
        elif why:
            assert f"channel_{row['channel']}" not in {f for _, f in refit}, (why, refit)


@pytest.mark.slow
def test_control_ten_seeds(record_property):
    # reference: issue: no significant effect in at least 9 of 10 controls, never a worse held-out error
    runs = [_run(None, seed)[0] for seed in range(30, 40)]
    for seed, res in zip(range(30, 40), runs):
        record_property("case", case_row("reference", f"clean {seed}", res))
    quiet = [_check_control(res) for res in runs]
    assert sum(quiet) >= 9
    for res in runs:
        _check_reasons(res)


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    """``l1b2 close-loop --train all.csv --report-dir DIR --export DIR2`` on direction_asymmetry 2, run once for the
    module: no ``--test`` (TEST: the paper's held-out runs of the same file) and the default settings, i.e. the loop
    of ``_run("direction_asymmetry", 2)`` on the same runs (compared in
    test_close_loop_without_a_test_file_holds_out_the_papers_runs). ``--workers 1``: the refits in this process,
    as ``_run``'s (the CLI's default local cluster runs the tutorial's close loop, test_tutorial.py; that a cluster
    gives the serial refits is test_closeloop_parallel.py's check). ``{"code", "printed", "report", "export",
    "result"}``; the result is read back from report.json."""
    import contextlib
    import io
    d = rig_dir("direction_asymmetry_2", injections=["direction_asymmetry"], injection_seed=2,
                plan=RigPlan(step_s=1e-3, seed=2))
    root = tmp_path_factory.mktemp("cli_close_loop")
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli_main(["close-loop", "--train", str(d / "all.csv"), "--report-dir", str(root / "cl"), "--quiet",
                         "--export", str(root / "fmu"), "--workers", "1"])
    rep = json.loads((root / "cl" / "report.json").read_text()) if code == 0 else None
    return {"code": code, "printed": buf.getvalue(), "report": root / "cl", "export": root / "fmu",
            "result": CloseLoopResult.from_dict(rep) if rep is not None else None}


def test_cli_writes_the_report_files_and_figures(cli_run, tmp_path, capsys):
    # reference: issue: DIR/report.json keys, report.md, PNGs (residual vs regressors, chosen effect,
    # before/after on TEST); the before/after table printed
    out = cli_run["report"]
    assert cli_run["code"] == 0
    printed = cli_run["printed"]
    # the calibrated model went into Predictor.fmu, and again from the report alone
    assert (cli_run["export"] / "fmus" / "Predictor.fmu").is_file()
    assert cli_main(["export", "--from-report", str(out), "--out", str(tmp_path / "again")]) == 0
    first = json.loads((cli_run["export"] / "calibrated_manifest.json").read_text())
    again = json.loads((tmp_path / "again" / "calibrated_manifest.json").read_text())
    assert first["effects"] == again["effects"] and first["effects"]
    assert cli_main(["export", "--from-report", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "no close-loop report here" in capsys.readouterr().err
    assert "before" in printed and "after" in printed and "direction" in printed
    # time and evaluations per stage printed: one line per stage of report.json, in order, then their total
    stages = json.loads((out / "report.json").read_text())["stages"]
    lines = printed.splitlines()
    at = lines.index("time and evaluations per stage (fits: identifications, fold refits included):")
    rows = [ln.split() for ln in lines[at + 2:at + 3 + len(stages)]]
    assert [r[-2:] for r in rows[:-1]] == [[str(s["identifications"]), str(s["nfev"])] for s in stages]
    assert rows[-1][0] == "total" and rows[-1][-1] == str(sum(s["nfev"] for s in stages)) != "0"
    text = (out / "report.json").read_text()
    rep = json.loads(text, parse_constant=lambda c: pytest.fail(f"report.json is not strict JSON: {c}"))
    for key in ("baseline", "diagnosis", "extended", "extended_parameters"):
        assert key in rep
    for part in ("train", "test"):
        for kind in ("one_step", "free_run"):
            assert {"nrmse", "mean_abs_rel_error", "p95_abs_rel_error"} <= set(rep["baseline"][part][kind])
            assert {"nrmse", "mean_abs_rel_error", "p95_abs_rel_error"} <= set(rep["extended"][part][kind])
    d_ = rep["diagnosis"]
    assert {"significant", "traced_to", "effect", "candidates"} <= set(d_)
    assert d_["rules"]["noise"] == "common"  # the fits' noise model is recorded
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


def test_cli_settings_reach_the_loop(tmp_path):
    # reference: the command line's values are the loop's recorded rules: the materiality threshold, the
    # uncorrected screen's level (below Bonferroni's: no cost) and the number of rounds (none here: the rules are
    # recorded whatever the loop finds, so the baseline alone is identified)
    d = rig_dir("direction_asymmetry_2", injections=["direction_asymmetry"], injection_seed=2,
                plan=RigPlan(step_s=1e-3, seed=2))
    out = tmp_path / "cl"
    assert cli_main(["close-loop", "--train", str(d / "train.csv"), "--test", str(d / "test.csv"),
                     "--report-dir", str(out), "--quiet", "--no-plots", "--max-rounds", "0", "--workers", "1",
                     "--min-cv-drop", "0.006", "--screen-alpha", "1e-6"]) == 0
    rules = json.loads((out / "report.json").read_text())["diagnosis"]["rules"]
    assert (rules["min_cv_drop"], rules["screen_alpha"], rules["max_rounds"]) == (0.006, 1e-6, 0)


def test_close_loop_without_a_test_file_holds_out_the_papers_runs(cli_run, tmp_path, capsys):
    # reference: `l1b2 identify`'s rule (data format: one file may hold every run): without --test, TEST is the
    # runs with |load| 0.05 kg; the result equals the loop on the rig's own train.csv/test.csv (1e-9 relative)
    d = rig_dir("direction_asymmetry_2", injections=["direction_asymmetry"], injection_seed=2,
                plan=RigPlan(step_s=1e-3, seed=2))
    res_files, _ = _run("direction_asymmetry", 2)
    res = cli_run["result"]
    assert res.checks["split"] == "paper's split: test = runs with |load| in [0.05] kg"
    assert f"data: {res.checks['split']}" in cli_run["printed"]
    for part in ("before", "after"):
        for kind in ("one_step", "free_run"):
            assert getattr(res, part)["test"][kind]["nrmse"] == pytest.approx(
                getattr(res_files, part)["test"][kind]["nrmse"], rel=1e-9)
    # every run held out: nothing to train on, one line naming the file, nothing written
    df = pd.read_csv(d / "all.csv")
    only = tmp_path / "only_005.csv"
    df[np.isclose(df["load_kg"].abs(), 0.05)].to_csv(only, index=False)
    out = tmp_path / "x"
    assert cli_main(["close-loop", "--train", str(only), "--report-dir", str(out), "--quiet"]) != 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(only) in err and "nothing left to train on" in err
    assert not out.exists()


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


def _toy_context_and_frame():
    n = 40
    df = pd.DataFrame({"time_s": np.linspace(0, 3.9, n), "run": np.repeat([1, 2], n // 2),
                       "position_m": np.tile(np.linspace(-0.02, 0.02, n // 2), 2),
                       "speed_m_s": np.tile([0.1, -0.1], n // 2), "voltage_V": np.repeat([250.0, 300.0], n // 2),
                       "load_kg": np.repeat([0.0, 0.05], n // 2), "direction": np.repeat([1, -1], n // 2)})
    ctx = Context(baseline_free_run=lambda d: d["speed_m_s"].to_numpy(float), m_s=0.1, time_range=(0.0, 3.9),
                  position_range=(-0.02, 0.02))
    return ctx, df


def test_candidate_library_is_an_argument_that_combines():
    # reference: the default library is named + generic, in that order; + and combine() concatenate
    ctx, df = _toy_context_and_frame()
    labels = [c.label for c in named_candidates(ctx, df) + generic_candidates(ctx, df)]
    assert [c.label for c in default_library()(ctx, df)] == labels
    assert [c.label for c in (named_library() + generic_library())(ctx, df)] == labels
    assert [c.label for c in combine(named_library(), generic_candidates)(ctx, df)] == labels
    assert all(c.generic for c in generic_library()(ctx, df))
    assert not any(c.generic for c in named_library()(ctx, df))
    only = CandidateLibrary(lambda ctx, df: [c for c in named_candidates(ctx, df) if c.family == "drive_saturation"])
    assert [c.family for c in only(ctx, df)] == ["drive_saturation"]
    with pytest.raises(TypeError):
        CandidateLibrary("not callable")


def test_structural_terms_are_the_voltage_dependence_of_eq29s_slopes_and_trace_after_missing_effects():
    # reference: Eq. 25's closed form: the drive force's slope over speed changes with omega U_w (with V0),
    # which Eq. 29 holds constant; exactly the load x voltage and voltage x speed candidates relax it
    ctx, df = _toy_context_and_frame()
    lib = full_library()(ctx, df)
    structural = {c.family for c in lib if c.structural}
    assert structural == {"load_slope_voltage", "damping_voltage", "smooth_load_x_voltage", "smooth_voltage_x_speed"}
    by = {c.family: c for c in lib}
    assert set(by["smooth_voltage_x_speed"].regressors) == {"voltage", "speed"}
    assert not by["smooth_time_x_voltage"].structural and not by["smooth_position_x_load"].structural
    # order: the speed filter, the missing effects in the order they were added, then the structural terms,
    # then the residual trace; nothing when nothing was added
    s, pos = by["smooth_load_x_voltage"], by["smooth_position"]
    assert order_traced([s, pos], False, ["voltage", "time"]) == ["position", "load", "voltage", "time"]
    assert order_traced([pos, s], True, []) == ["speed", "position", "load", "voltage"]
    assert order_traced([s], False, ["time"]) == ["load", "voltage", "time"]
    assert order_traced([], False, ["time"]) == []
    assert order_traced([], True, ["time"]) == ["speed", "time"]
    # evidence below the materiality threshold: after the missing effects, before the structural terms
    t, d = by["smooth_time"], by["smooth_direction_x_voltage"]
    assert order_traced([s], False, ["position"], evidence=[t]) == ["time", "load", "voltage", "position"]
    assert order_traced([pos, s], False, [], evidence=[by["smooth_voltage_x_speed"], d]) == [
        "position", "direction", "voltage", "load", "speed"]
    assert order_traced([], False, ["time"], evidence=[t]) == []
    # a speed-channel filter found by the channel's own test but not applied is evidence, not an effect: after
    # the added physical effects, before the immaterial candidates and the structural terms
    assert order_traced([s], False, ["time"], evidence=[t], speed_evidence=True) == [
        "speed", "time", "load", "voltage"]
    assert order_traced([pos, s], False, [], speed_evidence=True) == ["position", "speed", "load", "voltage"]
    assert order_traced([], False, ["time"], speed_evidence=True) == []  # nothing added: nothing traced
    assert order_traced([pos], True, [], speed_evidence=True) == ["speed", "position"]


def test_materiality_threshold_binds_structural_terms_only():
    # reference: measured on the reference motor: the thermal drift of seed 11 halved a small held-out error
    # (CV nrmse 0.73 -> 0.41 %, 4 of 4 folds) and must be added; a structural term with the same figures (on
    # clean data a voltage x speed term halves a 0.4 % error) must not be: it is Eq. 29's own error
    from l1b2.closeloop.acceptance import DEFAULT_MIN_CV_DROP, FoldErrors, RefitCV, accepts, materiality
    ctx, df = _toy_context_and_frame()
    by = {c.family: c for c in full_library()(ctx, df)}
    ss = np.full(4, 1.0)
    cur = FoldErrors(sse=ss * 0.0073 ** 2, ss_meas=ss)
    ext = FoldErrors(sse=ss * 0.0041 ** 2, ss_meas=ss)
    for family, added in (("thermal_drift", True), ("smooth_voltage_x_speed", False)):
        t = RefitCV(by[family], cur, ext)
        assert t.current.nrmse == pytest.approx(0.0073) and t.gain > 0.6 and t.folds_improved == 4
        assert accepts(t, min_drop=materiality(t.candidate, DEFAULT_MIN_CV_DROP)) is added, family
    # a material fall adds a structural term too; a non-structural one still needs the relative gain
    big = RefitCV(by["smooth_voltage_x_speed"], FoldErrors(ss * 0.02 ** 2, ss), FoldErrors(ss * 0.01 ** 2, ss))
    assert accepts(big, min_drop=materiality(big.candidate, DEFAULT_MIN_CV_DROP))
    small = RefitCV(by["thermal_drift"], cur, FoldErrors(ss * 0.99 * 0.0073 ** 2, ss))
    assert not accepts(small, min_drop=materiality(small.candidate, DEFAULT_MIN_CV_DROP))


def test_estimator_takes_measurements_and_stores_settings():
    # reference: scikit-learn convention: __init__ stores the settings unchanged; fit refuses file paths
    lib = named_library()
    est = CloseLoop(order=6, k_folds=4, library=lib)
    assert est.get_params()["order"] == 6 and est.get_params()["library"] is lib and est.k_folds == 4
    with pytest.raises(TypeError, match="Measurements"):
        est.fit("train.csv")
    assert not hasattr(est, "result_")
    # the baseline's search setting reaches the identification (an unknown one is refused there, by name)
    assert CloseLoop(noise_fit="profile").get_params()["noise_fit"] == "profile"
    assert CloseLoop().noise == "common" and CloseLoop(noise="per_run").get_params()["noise"] == "per_run"
    d = rig_dir("direction_asymmetry_2", injections=["direction_asymmetry"], injection_seed=2,
                plan=RigPlan(step_s=1e-3, seed=2))
    from l1b2.errors import IdentificationError
    with pytest.raises(IdentificationError,
                       match=r"noise_fit must be one of \('auto', 'alternate', 'profile'\), got 'nope'"):
        CloseLoop(noise_fit="nope").fit(load_measurements(d / "train.csv"))
    with pytest.raises(IdentificationError, match="noise must be 'per_run' or 'common', got 'white'"):
        CloseLoop(noise="white").fit(load_measurements(d / "train.csv"))


def test_result_api_matches_the_saved_report(tmp_path):
    # reference: the result's dict is report.json; its markdown is report.md without figures; scores as a table;
    # plot() writes nothing
    res, _ = _run("direction_asymmetry", 2)   # the same data as the fast test's (cached)
    assert isinstance(res, CloseLoopResult)
    rep = res.to_dict()
    json.dumps(rep, allow_nan=False)
    assert rep["diagnosis"]["message"] == res.diagnosis["message"] and rep["diagnosis"]["significant"]
    assert res.before_after_table().splitlines()[2].startswith("test    free_run")
    table = res.scores_to_pandas()
    assert len(table) == rep["diagnosis"]["n_candidates_scored"] and table["chosen"].sum() == 1
    assert table.loc[table["chosen"], "family"].item() == rep["diagnosis"]["effect"]
    figs = res.plot()
    assert set(figs) == {"residual_vs_regressors", "residual_spectrum_and_whiteness", "chosen_effect",
                         "before_after_test"}
    assert not any(tmp_path.iterdir())
    written = res.save(tmp_path / "r")
    assert {p.name for p in written} == {"report.json", "report.md"} | {f"{n}.png" for n in figs}
    saved = json.loads((tmp_path / "r" / "report.json").read_text())
    assert saved.pop("figures") == [str(tmp_path / "r" / f"{n}.png") for n in figs]
    assert saved == rep
    assert CloseLoopResult.from_dict(saved) == res   # figures are not part of the result
    assert (tmp_path / "r" / "report.md").read_text().startswith(res.markdown().rstrip())
    # time and evaluations per stage: the loop's stages in order, the baseline's evaluations and the refits counted
    stages = rep["stages"]
    assert stages[0]["stage"].startswith("baseline") and stages[0]["identifications"] == 1
    assert stages[0]["nfev"] == res.baseline_model.convergence_["nfev_total"] > 0
    cv = [s for s in stages if "cross-validating" in s["stage"]]
    assert cv and all(s["identifications"] >= 4 for s in cv)   # every fold of every trial is one refit
    assert all(s["nfev"] >= s["identifications"] for s in cv)  # ... and returns its evaluations (at least one each)
    assert all(s["wall_s"] >= 0 and s["cpu_s"] >= 0 for s in stages)
    # each round's collinearity screen is its own stage, just before that round's scoring (not billed to the
    # stage before it: the baseline's residual analysis or the previous round's joint re-identification)
    names = [s["stage"] for s in stages]
    scoring = [k for k, n in enumerate(names) if "candidate effects (linearised)" in n]
    assert scoring and all("screening the candidates" in names[k - 1] for k in scoring)
    assert "## Time per stage" in res.markdown() and CloseLoopResult.from_dict(saved).stages == stages


def test_stage_clock_times_each_announced_stage():
    # reference: a stage runs from its message to the next one; counts go to the stage open when they are added
    import time
    from l1b2.closeloop.stages import StageClock
    said = []
    clock = StageClock(said.append)
    clock("a")
    clock.count(2, 30)
    t0 = time.process_time()
    while time.process_time() - t0 < 0.05:
        pass
    clock("b")
    clock.count(1)
    recs = clock.close()
    assert said == ["a", "b"] and [r["stage"] for r in recs] == ["a", "b"]
    assert (recs[0]["identifications"], recs[0]["nfev"], recs[1]["identifications"], recs[1]["nfev"]) == (2, 30, 1, 0)
    assert recs[0]["cpu_s"] >= 0.045 and recs[0]["wall_s"] >= recs[0]["cpu_s"] - 0.01 and recs[1]["cpu_s"] < 0.045
    assert clock.close() == recs   # closing again adds nothing


def test_the_final_models_run_level_evidence_is_recorded_when_the_last_round_added_an_effect():
    # reference: one round that adds the pulley's friction, then the run-level analysis against the final model
    d = rig_dir("pulley_friction_1", injections=["pulley_friction"], injection_seed=1,
                plan=RigPlan(step_s=1e-3, seed=1))
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"), max_rounds=1)
    diag = res.diagnosis
    assert diag["traced_to"] and res.extended is not None
    rounds = diag["run_level_rounds"]
    assert [r["round"] for r in rounds] == [1, None]
    assert rounds[0]["significant_signals"] == diag["run_level"]["significant_signals"]
    assert "Run-level evidence left against the final model (the runs' deviations from it, after the last round)" \
        in res.markdown()
