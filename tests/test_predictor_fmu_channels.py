"""Predictor.fmu of a calibrated model whose effects read logged auxiliary channels: one input per channel.

A logged column that is none of the FMU's fixed inputs (V0, s, load, direction, T) gets an input of its own, named
after the column (:func:`l1b2.cosim.composite.channel_input`); ``col:<column>`` and ``run:<column>`` are its current
value (:func:`l1b2.predictor.effects.channels.fmu_signal`), a run-level signal under the run-level contract of
:func:`l1b2.predictor.effects.channels.export_problem`. References: the families' features written out, the
identification's own free run (run means by groupby) and :meth:`l1b2.predictor.effects.ExtendedPredictor.free_run`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop.candidates import Context, candidate, channels_of
from l1b2.closeloop.runlevel import run_signals
from l1b2.cosim.composite import ExtendedPredictorBlock, PredictorBlock
from l1b2.data import measurements as dataio
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import ExtendedPredictor, IdentifiedEffect
from l1b2.predictor.effects import channels as ch

N = 60
DT = 1e-3
T0 = 3.0
G = 9.81
#: per run: direction, V0 [V], load [kg], line pressure [bar] (held per run), fixture (a setting held per run)
RUN_TABLE = [(1.0, 300.0, 0.03, 2.0, 1.0), (-1.0, 260.0, -0.02, 2.6, 2.0), (1.0, 320.0, 0.0, 2.3, 3.0)]


def _frame(pressure_noise_bar: float = 0.0) -> pd.DataFrame:
    """Three runs; ``supply_V`` varies along each run; ``line_pressure_bar`` is held per run (plus a ripple of
    ``pressure_noise_bar`` within the run when given)."""
    rows = []
    for i, (d, V0, m, p, fix) in enumerate(RUN_TABLE):
        t = T0 + i * 0.5 + np.arange(N) * DT
        k = np.arange(N)
        rows.append(pd.DataFrame({
            dataio.TIME: t, dataio.RUN: i, dataio.POSITION: -0.01 * d + d * 0.15 * (t - t[0]),
            dataio.VOLTAGE: V0, dataio.LOAD: m, dataio.DIRECTION: d, dataio.SPEED: 0.1 * d,
            "supply_V": 24.0 + 0.5 * np.sin(k / 7.0) + 0.3 * i,
            "line_pressure_bar": p + pressure_noise_bar * np.sin(k / 3.0), "fixture_id": fix}))
    return pd.concat(rows, ignore_index=True)


def _setups():
    # imported here: the isolated fmpy worker loads this file without tests/ on its path, and never calls this
    from test_extended_predictor_fmu import _setups as extended_setups
    return extended_setups(1.02)


def _ctx(base) -> Context:
    def no_baseline(_df):
        raise AssertionError("these effects do not read v_base")
    return Context(no_baseline, base.slider_mass_kg, (T0, T0 + 1.5), (-0.02, 0.02))


def _hypotheses(df) -> dict:
    """The loop's hypotheses on the frame: the run-level ones of ``line_pressure_bar``, ``supply_V`` and the session
    clock ``time_s`` (its run values' mean and sd, TRAIN's within-run spread) and the sample-level force-factor one
    of ``supply_V``."""
    sigs = [{**sg, "mean": float(np.mean(sg["values"])), "sd": float(np.std(sg["values"]))}
            for sg in run_signals(df, channels_of(df)) if sg.get("transform") in ("none", "drive")]
    hyps = fx.family("run_level").hypotheses(sigs)
    run = {h.spec["channel"]: h for h in hyps if h.spec["transform"] == "none"}
    drive = {h.spec["channel"]: h for h in hyps if h.spec["transform"] == "drive"}
    summary = fx.TrainingSummary(1.0, (T0, T0 + 1.5), (-0.02, 0.02), 300.0, {}, channels=channels_of(df))
    sample = next(h for h in fx.family("channel").grid(summary)
                  if h.spec["channel"] == "supply_V" and h.spec["level"] == "sample"
                  and h.spec["form"] == "force_factor" and h.spec.get("shape", "linear") == "linear")
    return {"pressure_run": run["line_pressure_bar"], "supply_run": run["supply_V"], "clock_run": run["time_s"],
            "supply_sample": sample, "pressure_drive": drive["line_pressure_bar"]}


def _effect(h, phi) -> IdentifiedEffect:
    return IdentifiedEffect(h.family, h.family, dict(h.spec), tuple(h.names), tuple(h.units), tuple(float(p) for p in phi),
                            (0.01,) * len(h.names), h.description, (h.regressor,), h.structural)


def _category_hypothesis():
    return fx.family("run_level_category").hypotheses([{"channel": "fixture_id", "levels": (1.0, 2.0, 3.0),
                                                        "shares": (1 / 3, 1 / 3), "run_spread": 0.0}])[0]


# ---------------------------------------------------------------------------
# the signals, units and inputs (fast: the block instantiated directly)
# ---------------------------------------------------------------------------

def test_a_logged_channel_is_its_own_inputs_signal_and_the_session_clock_has_none():
    # reference: the rule of fmu_signal written out
    assert ch.fmu_signal("run:line_pressure_bar") == ch.fmu_signal("col:line_pressure_bar") == "col:line_pressure_bar"
    assert ch.fmu_signal("run:voltage_V") == "V0" and ch.fmu_signal("col:temperature_C") == "T"
    assert ch.fmu_signal("col:time_s") is None and ch.fmu_signal("run:time_s") is None
    assert ch.fmu_signal("v_base") == "v_base" and ch.fmu_signal("nonsense") is None
    x = ch.with_input_signals({"col:p": np.array([1.0, 2.0])}, {"run:p", "col:p"})
    np.testing.assert_array_equal(x["run:p"], [1.0, 2.0])   # the run-level signal is the input's current value


def test_a_column_names_its_unit_by_its_suffix():
    # reference: the data format's table, then the name's last two parts as a product or a quotient, or its last
    # part, when it is a unit
    from l1b2.units import UNITS, column_unit
    want = {"line_pressure_bar": "bar", "supply_V": "V", "belt_speed_m_s": "m/s", "coolant_C": "degC",
            "oil_viscosity_mPa_s": "mPa.s", "glycerol_Pa_s": "Pa.s", "dwell_s": "s",
            "heater_W": "W", "coil_current_A": "A", "payload_g": "g", "temperature_C": "degC", "direction": "1",
            "fixture_id": None, "aux_relay": None, "sensor_1": None, "V": None}
    assert {n: column_unit(n) for n in want} == want
    assert UNITS["bar"].base_unit_attributes() == {"kg": "1", "m": "-1", "s": "-2", "factor": "100000.0"}
    assert UNITS["g"].base_unit_attributes() == {"kg": "1", "factor": "0.001"}
    assert UNITS["mPa.s"].base_unit_attributes() == {"kg": "1", "m": "-1", "s": "-1", "factor": "0.001"}


def test_the_block_declares_one_input_per_logged_channel_with_unit_start_and_provenance():
    # reference: the spec's TRAIN means (run values' mean for the run-level effect; the category's mean over runs,
    # 1/3 (1 + 2 + 3) = 2), the unit from the column's name, and the fixed inputs before them
    base, refit = _setups()
    hs = _hypotheses(_frame())
    cat = _category_hypothesis()
    ep = ExtendedPredictor(base, refit, (_effect(hs["pressure_run"], (0.1, 0.2, 0.3)),
                                         _effect(hs["supply_sample"], (0.05,)), _effect(cat, (0.1,) * 6)),
                           None, {"train": "train.csv"})
    assert ep.channel_inputs == pytest.approx({"fixture_id": 2.0, "line_pressure_bar": np.mean([2.0, 2.6, 2.3]),
                                               "supply_V": hs["supply_sample"].spec["mean"]}, rel=1e-12)
    block = PredictorBlock(ep)
    assert type(block) is ExtendedPredictorBlock
    ins = {v.name: v for v in PredictorBlock.variables(ep) if v.causality == "input"}
    assert list(ins) == ["V0", "s", "load", "direction", "frequency_Hz", "fixture_id", "line_pressure_bar", "supply_V"]
    assert [v.name for v in block.INPUTS] == list(ins)
    assert (ins["line_pressure_bar"].unit, ins["supply_V"].unit, ins["fixture_id"].unit) == ("bar", "V", "1")
    assert "logged channel line_pressure_bar of the calibration data (train.csv)" in ins["line_pressure_bar"].description
    assert "unit is not known from its name" in ins["fixture_id"].description
    assert "unit is not known" not in ins["supply_V"].description
    for name, v in ins.items():
        if name in ep.channel_inputs:
            assert v.start == pytest.approx(ep.channel_inputs[name], rel=1e-15) == getattr(block, name)
    # the plain model keeps the plain predictor's inputs, a class-level list (the instance adds none)
    plain = PredictorBlock(ExtendedPredictor(base, refit))
    assert [v.name for v in plain.INPUTS] == ["V0", "s", "load", "direction", "frequency_Hz"]


def test_a_channel_named_like_a_predictor_variable_is_refused_and_the_drive_frequency_is_its_input():
    # reference: the FMU's variable names are unique; the data format's frequency_Hz is the predictor's own input
    base, refit = _setups()
    for name in ("v0", "s", "F_extra"):
        h = fx.family("run_level").hypotheses([{"channel": name, "transform": "none", "mean": 1.0, "sd": 0.5,
                                                "run_spread": 0.0}])[0]
        with pytest.raises(ValueError, match=f"variable names declared twice: {name} "):
            PredictorBlock.variables(ExtendedPredictor(base, refit, (_effect(h, (0.1,) * 3),), None, {}))
    h = fx.family("run_level").hypotheses([{"channel": "frequency_Hz", "transform": "none", "mean": 48500.0,
                                            "sd": 50.0, "run_spread": 0.0}])[0]
    ep = ExtendedPredictor(base, refit, (_effect(h, (0.1, 0.2, 0.3)),), None, {})
    ins = [v for v in PredictorBlock.variables(ep) if v.causality == "input"]
    assert [v.name for v in ins] == ["V0", "s", "load", "direction", "frequency_Hz"]
    assert ins[-1].description.endswith("; also the logged channel the identified effects read")
    gain = 0.1 * 300.0 / 300.0 + 0.2   # load 0: F = z (a V0/300 + b), z = (f - 48500)/50
    assert _stepped_force(ep, frequency_Hz=48600.0) == pytest.approx(2.0 * gain, rel=1e-12)


def test_a_settings_step_is_an_input_of_its_own_that_the_host_computes_not_the_drive_amplitude():
    # reference: the run-level force written out, F = z (a V0/300 + b + c g d m), z = (step - mean)/sd, read from the
    # input named after the derived column (closeloop.lags: voltage_V_step), never from V0; in V, the voltage's unit
    from l1b2.closeloop.lags import STEP_SUFFIX
    name = "voltage_V" + STEP_SUFFIX
    assert ch.fmu_signal("run:" + name) == "col:" + name and ch.fmu_signal("run:voltage_V") == "V0"
    base, refit = _setups()
    h = fx.family("run_level").hypotheses([{"channel": name, "transform": "none", "mean": 12.0, "sd": 60.0,
                                            "run_spread": 0.0}])[0]
    a, b, c = 0.3, -0.1, 0.5
    ep = ExtendedPredictor(base, refit, (_effect(h, (a, b, c)),), None, {})
    ins = {v.name: v for v in PredictorBlock.variables(ep) if v.causality == "input"}
    assert list(ins) == ["V0", "s", "load", "direction", "frequency_Hz", name]
    assert ins[name].start == pytest.approx(12.0) and ins[name].unit == "V"
    V0, m, d = 290.0, 0.02, 1.0
    f = _stepped_force(ep, V0=V0, load=m, direction=d, **{name: 72.0})
    assert f == pytest.approx((72.0 - 12.0) / 60.0 * (a * V0 / 300.0 + b + c * G * d * m), rel=1e-12)
    assert _stepped_force(ep, V0=V0, load=m, direction=d, **{name: 12.0}) == pytest.approx(0.0, abs=1e-15)


def _stepped_force(ep, **inputs) -> float:
    """``F_extra`` of the block after one step from the inputs ``inputs`` (held), the FMU's own call sequence."""
    block = PredictorBlock(ep)
    for k, v in {"V0": 300.0, "s": 0.0, "load": 0.0, "direction": 1.0, **inputs}.items():
        block.set(k, v)
    block.set_start_time(T0)
    block.initialize()
    block.do_step(T0, DT)
    return float(block.F_extra)


def test_changing_the_channel_input_changes_the_force_by_the_identified_coefficients():
    # reference: the run-level family's force written out, F = z (a V0/V_ref + b + c g d m), z = (p - mean)/sd,
    # V_ref = 300 V: a change dp of the pressure input changes F by dp/sd (a V0/300 + b + c 9.81 d m); the category,
    # F = sum_j x_j (a_j V0/300 + b_j + c_j g d m), x_j = 1[c = v_j] - s_j: from the last level (3) to the first (1)
    # it changes by a_0 V0/300 + b_0 + c_0 g d m; a value that is no level gives x = 0, F = 0
    base, refit = _setups()
    h = _hypotheses(_frame())["pressure_run"]
    a, b, c = 0.4, -0.15, 0.7
    ep = ExtendedPredictor(base, refit, (_effect(h, (a, b, c)),), None, {})
    V0, m, d = 280.0, 0.04, -1.0
    mean, sd = h.spec["mean"], h.spec["sd"]
    f1 = _stepped_force(ep, V0=V0, load=m, direction=d, line_pressure_bar=2.1)
    f2 = _stepped_force(ep, V0=V0, load=m, direction=d, line_pressure_bar=2.5)
    gain = a * V0 / 300.0 + b + c * G * d * m
    assert f1 == pytest.approx((2.1 - mean) / sd * gain, rel=1e-12)
    assert f2 - f1 == pytest.approx(0.4 / sd * gain, rel=1e-9)
    assert abs(f2 - f1) > 0.05   # not vacuous
    cat = _category_hypothesis()
    phi = (0.3, -0.2, 0.5, 0.1, 0.25, -0.4)
    ep = ExtendedPredictor(base, refit, (_effect(cat, phi),), None, {})
    f_first, f_last, f_unseen = (_stepped_force(ep, V0=V0, load=m, direction=d, fixture_id=v) for v in (1.0, 3.0, 7.0))
    s0 = s1 = 1 / 3
    gains = [phi[0] * V0 / 300.0 + phi[1] + phi[2] * G * d * m, phi[3] * V0 / 300.0 + phi[4] + phi[5] * G * d * m]
    assert f_last == pytest.approx(-s0 * gains[0] - s1 * gains[1], rel=1e-12)
    assert f_first - f_last == pytest.approx(gains[0], rel=1e-12)
    assert f_unseen == 0.0


def test_the_free_run_needs_the_logged_channel_and_the_block_refuses_a_non_finite_one():
    base, refit = _setups()
    h = _hypotheses(_frame())["pressure_run"]
    ep = ExtendedPredictor(base, refit, (_effect(h, (0.1, 0.1, 0.1)),), None, {})
    t = T0 + np.arange(5) * DT
    with pytest.raises(fx.EffectSpecError, match="logged channel 'line_pressure_bar': pass channels="):
        ep.free_run(t, 0.0 * t, 300.0, 0.0, 1.0, 0.1)
    from l1b2.errors import SimulationError
    block = PredictorBlock(ep)
    block.set("line_pressure_bar", float("nan"))
    with pytest.raises(SimulationError, match="input line_pressure_bar \\[bar\\] = nan is not finite"):
        block.initialize()


def test_a_run_level_channel_the_runs_did_not_hold_constant_is_still_refused(tmp_path):
    # reference: the run-level contract, run_spread <= RUN_CONSTANT_TOL (0.01) sd of the run values: supply_V
    # varies along each run (0.5 V ripple against a run sd of 0.24 V); the line pressure with a 0.01 bar ripple
    # (0.01 / 0.245 = 0.04 sd) too; held exactly per run it passes
    from l1b2.fmi.export import ExportError, export_calibrated
    base, refit = _setups()
    hs = _hypotheses(_frame())
    assert ch.export_problem(hs["pressure_run"].spec) is None
    assert ch.export_problem(hs["supply_sample"].spec) is None   # a sample-level signal needs no constancy
    why = ch.export_problem(hs["supply_run"].spec)
    assert why is not None and why.startswith("not constant within runs: supply_V deviates from its run's mean")
    noisy = _hypotheses(_frame(pressure_noise_bar=0.01))["pressure_run"]
    assert noisy.spec["run_spread"] == pytest.approx(0.01 * np.max(np.abs(np.sin(np.arange(N) / 3.0)
                                                                         - np.mean(np.sin(np.arange(N) / 3.0)))),
                                                     rel=1e-6)
    assert ch.export_problem(noisy.spec).startswith("not constant within runs: line_pressure_bar")
    # the shared rule: (column, spread, sd) beyond RUN_CONSTANT_TOL sd; an unrecorded spread is inf
    assert ch.run_spread_excess(hs["pressure_run"].spec) == []
    [(col, spread, sd)] = ch.run_spread_excess(noisy.spec)
    assert (col, spread, sd) == ("line_pressure_bar", noisy.spec["run_spread"], noisy.spec["sd"])
    assert spread > ch.RUN_CONSTANT_TOL * sd
    unrecorded = {k: v for k, v in noisy.spec.items() if k != "run_spread"}
    assert ch.run_spread_excess(unrecorded) == [("line_pressure_bar", float("inf"), noisy.spec["sd"])]
    assert "(run_spread)" in ch.export_problem(unrecorded)
    with pytest.raises(ExportError, match="run_level_line_pressure_bar: not constant within runs"):
        export_calibrated(ExtendedPredictor(base, refit, (_effect(noisy, (0.1, 0.1, 0.1)),), None, {}),
                          tmp_path / "out")
    assert not (tmp_path / "out" / "fmus" / "Predictor.fmu").exists()


def test_the_native_kernels_refuse_a_logged_channel_by_name():
    # reference: the native kernels read SIGNALS only; a channel input has no slot there: a named refusal, no kernel
    from l1b2.predictor.effects import kernels as ek
    h = _hypotheses(_frame())["pressure_run"]
    with pytest.raises(fx.EffectSpecError, match="reads the logged channel 'line_pressure_bar' through an input of "
                                                 "its own, which the native kernels do not have"):
        ek.spec_scalars(h.spec)


# ---------------------------------------------------------------------------
# the real FMU through fmpy
# ---------------------------------------------------------------------------

INPUTS = ("V0", "s", "load", "direction", "line_pressure_bar", "supply_V")


def worker_fmpy(path: str, runs: list, names: list):
    """The FMU through fmpy over each run (inputs at each step's start): ``v`` and ``F_extra`` after initialisation
    and after each step."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(path)
    out = []
    for r in runs:
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="channels")
        rows = []
        try:
            fmu.instantiate()
            fmu.setupExperiment(startTime=r["t"][0])
            fmu.setReal([vr["v0"]], [r["v_start"]])
            fmu.setReal([vr[n] for n in names], [r[n][0] for n in names])
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            rows.append(fmu.getReal([vr["v"], vr["F_extra"]]))
            for k in range(len(r["t"]) - 1):
                fmu.setReal([vr[n] for n in names], [r[n][k] for n in names])
                fmu.doStep(currentCommunicationPoint=r["t"][k], communicationStepSize=r["t"][k + 1] - r["t"][k])
                rows.append(fmu.getReal([vr["v"], vr["F_extra"]]))
            fmu.terminate()
        finally:
            fmu.freeInstance()
        out.append(rows)
    return out


def test_the_exported_fmu_driven_with_the_channel_inputs_reproduces_the_identifications_free_run(tmp_path, isolated):
    # reference: the identification's own free run (l1b2.predictor.simulate.free_run of the re-identified setup with
    # the candidates' force, the run-level pressure each run's mean by groupby) and ExtendedPredictor.free_run with
    # the channels; the FMU through fmpy, each run from its first speed, within 1e-10 relative (atol 1e-14 m/s);
    # the manifest lists the channel inputs; no native FMU, and it says why
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    from l1b2.fmi.export import export_calibrated
    from l1b2.predictor.simulate import free_run
    base, refit = _setups()
    df = _frame()
    hs = _hypotheses(df)
    ctx = _ctx(base)
    parts = []
    for key, phi in (("pressure_run", (0.3, -0.2, 0.5)), ("supply_sample", (0.4,)),
                     ("pressure_drive", (-0.2, 0.3, 0.1))):
        F = np.asarray(candidate(ctx, hs[key]).features(df))
        parts.append((key, np.asarray(phi) * 0.1 / np.sqrt(np.mean(F ** 2, axis=0)), F))
    force = sum(F @ phi for _, phi, F in parts)
    run = df[dataio.RUN].to_numpy()
    v_start = [0.1 * d for d, *_ in RUN_TABLE]
    args = (df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD], df[dataio.DIRECTION], df[dataio.TIME], v_start,
            refit.slider_mass_kg, run)
    want = free_run(refit.params, *args, extra_force=force)
    assert np.max(np.abs(want - free_run(refit.params, *args))) > 1e-4   # not vacuous: the effects move the speed
    ep = ExtendedPredictor(base, refit, tuple(_effect(hs[k], phi) for k, phi, _ in parts), None,
                           {"train": "synthetic"})
    chans = {c: df[c].to_numpy() for c in ("line_pressure_bar", "supply_V")}
    np.testing.assert_allclose(ep.free_run(df[dataio.TIME], *args[:4], v_start, run, channels=chans), want,
                               rtol=1e-12, atol=1e-15)
    man = export_calibrated(ep, tmp_path / "out")
    assert man["inputs"] == ["V0", "s", "load", "direction", "line_pressure_bar", "supply_V"]
    recs = {r["name"]: r for r in man["channel_inputs"]}
    assert recs["line_pressure_bar"]["unit"] == "bar" and recs["supply_V"]["unit"] == "V"
    assert recs["line_pressure_bar"]["start"] == pytest.approx(np.mean([2.0, 2.6, 2.3]), rel=1e-12)
    assert recs["line_pressure_bar"]["effects"] == ["run_level_line_pressure_bar", "run_level_d*line_pressure_bar"]
    assert hs["pressure_drive"].spec["centre"] == pytest.approx(np.mean([2.0, 2.6, 2.3]), rel=1e-12)
    assert man["native"]["Predictor"]["included"] is False
    assert "logged channel 'line_pressure_bar' through an input of its own" in man["native"]["Predictor"]["reason"]
    path = tmp_path / "out" / "fmus" / "Predictor.fmu"
    assert validate_fmu(str(path)) == []
    assert not list((tmp_path / "out" / "fmus").glob("Predictor-native*.fmu"))
    var = {v.name: v for v in read_model_description(str(path)).modelVariables}
    assert (var["line_pressure_bar"].causality, var["line_pressure_bar"].unit) == ("input", "bar")
    runs = []
    for i, v0 in enumerate(v_start):
        sel = df[dataio.RUN] == i
        r = {"t": df.loc[sel, dataio.TIME].tolist(), "v_start": v0}
        for name, col in zip(INPUTS, (dataio.VOLTAGE, dataio.POSITION, dataio.LOAD, dataio.DIRECTION,
                                      "line_pressure_bar", "supply_V")):
            r[name] = df.loc[sel, col].tolist()
        runs.append(r)
    got = np.concatenate(isolated(__file__, "worker_fmpy", str(path), runs, list(INPUTS)).value)
    np.testing.assert_allclose(got[:, 0], want, rtol=1e-10, atol=1e-14)
    starts = np.r_[0, np.flatnonzero(np.diff(run)) + 1]
    steps = np.setdiff1d(np.arange(len(df)), starts)   # F_extra after a step: the force at the step's start
    np.testing.assert_allclose(got[steps, 1], force[steps - 1], rtol=1e-10, atol=1e-14)


def test_a_logged_setting_with_sensor_noise_is_exported_when_its_samples_barely_move_the_free_run(tmp_path):
    # reference: the export accepts a run-level effect of a logged channel beyond RUN_CONSTANT_TOL when the spec's
    # run_feed (largest change of the free run, samples fed instead of run means, over its rms) is at most
    # RUN_FEED_TOL; an input of the plan keeps the contract whatever run_feed says
    from l1b2.closeloop.calibrated import run_feed
    from l1b2.fmi.export import export_calibrated
    base, refit = _setups()
    df = _frame(pressure_noise_bar=0.01)
    noisy = _hypotheses(df)["pressure_run"]
    ep = ExtendedPredictor(base, refit, (_effect(noisy, (0.3, -0.2, 0.5)),), None, {"train": "synthetic"})
    # written out: the free run with the logged samples and with each run's mean of the pressure
    run = df[dataio.RUN].to_numpy()
    first = df.groupby(dataio.RUN, sort=False)[dataio.SPEED].first().to_numpy()
    args = (df[dataio.TIME], df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD], df[dataio.DIRECTION], first, run)
    v1 = ep.free_run(*args, channels={"line_pressure_bar": df["line_pressure_bar"].to_numpy()})
    means = df.groupby(dataio.RUN)["line_pressure_bar"].transform("mean").to_numpy()
    v2 = ep.free_run(*args, channels={"line_pressure_bar": means})
    want = np.max(np.abs(v1 - v2)) / np.sqrt(np.mean(v1 ** 2))
    assert 0 < want < ch.RUN_FEED_TOL
    assert run_feed(ep, df, "line_pressure_bar") == pytest.approx(want, rel=1e-12)
    fed = {**noisy.spec, "run_feed": want}
    assert ch.export_problem(fed) is None
    worse = ch.export_problem({**noisy.spec, "run_feed": 0.02})
    assert worse.startswith("not constant within runs: line_pressure_bar") and "by up to 2.00% of its rms" in worse
    effect = dataclasses.replace(_effect(noisy, (0.3, -0.2, 0.5)), spec=fed)
    man = export_calibrated(ExtendedPredictor(base, refit, (effect,), None, {}), tmp_path / "out")
    assert "line_pressure_bar" in man["inputs"]
    # an input of the plan (V0) is held to the run-level contract: run_feed does not excuse it
    spec_v = {"kind": "run_level", "channel": "voltage_V", "transform": "none", "mean": 300.0, "sd": 20.0,
              "run_spread": 5.0, "run_feed": 0.0}
    assert ch.export_problem(spec_v).startswith("not constant within runs: voltage_V")


def test_a_model_that_also_reads_the_session_clock_gets_no_run_feed_and_is_not_exported():
    # reference: run_feed evaluates the model's free run, which has no input for the session clock; with an effect
    # of time_s beside a noisy logged setting the model cannot be exported whatever the setting's feed, so the specs
    # come back unchanged (before: the free run raised for the missing run:time_s signal) and the export names it
    from l1b2.closeloop.calibrated import run_feed, with_run_feeds
    base, refit = _setups()
    df = _frame(pressure_noise_bar=0.01)
    hyp = _hypotheses(df)
    noisy = _effect(hyp["pressure_run"], (0.3, -0.2, 0.5))
    clock = _effect(hyp["clock_run"], (0.1, 0.0, 0.0))

    def build(recs):
        return ExtendedPredictor(base, refit, tuple(recs), None, {"train": "synthetic"})
    both = [noisy, clock]
    assert with_run_feeds(both, build, df) == both
    assert ch.export_problem(clock.spec) and ch.export_problem(noisy.spec)
    # the logged setting alone gets its feed, the value run_feed gives
    fed = with_run_feeds([noisy], build, df)
    assert fed[0].spec["run_feed"] == pytest.approx(run_feed(build([noisy]), df, "line_pressure_bar"), rel=1e-12)
    assert ch.export_problem(fed[0].spec) is None
    assert with_run_feeds([noisy], build, None) == [noisy]
