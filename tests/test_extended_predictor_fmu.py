"""Predictor.fmu carrying a calibrated extended model (issue 15): every candidate kind, through fmpy and a C host.

Reference: :meth:`l1b2.predictor.effects.ExtendedPredictor.free_run`, the
vectorised free run of the extended model (the baseline's free run gives
``v_base``; its time derivative ``a_base``; the effects' forces are added to the
re-identified model's drive force; the output filter last). The effects come
from the close-the-loop library itself (:func:`l1b2.closeloop.candidates.full_library`
on a small data set), one FMU per kind, with random parameters large enough to
move the speed. That the same reference equals the close-the-loop estimator's
own prediction is checked on a real close-the-loop result in
``test_closeloop.py`` (``test_export_of_the_calibrated_model``).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
import subprocess

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop.candidates import Context, full_library
from l1b2.data import measurements as dataio
from l1b2.fmi.build import build_fmu
from l1b2.physics.params import load_motor
from l1b2.predictor import effects as fx
from l1b2.predictor.derive import derive_predictor
from l1b2.predictor.effects import ExtendedPredictor, IdentifiedEffect
from l1b2.predictor.setup import PredictorSetup

pytestmark = pytest.mark.fmu

N = 90
DT = 1e-3
T0 = 5.0                      # session time of the runs' start [s]
#: the kinds Predictor.fmu carries with its fixed inputs (``channel`` of the logged stator temperature,
#: ``run_level`` of the inputs held constant per run; the session clock as a channel and a run mean of an input the
#: runs did not hold constant are refused, tested below); not the categorical run-level family, whose every
#: hypothesis reads a logged channel through an input of its own (tests/test_predictor_fmu_channels.py)
CARRIED = tuple(k for k in fx.KINDS if fx.family(k).exportable and k != "run_level_category")
#: the output stages: the filter, and the filter with the speed channel's range (rails that cut both runs' speeds)
STAGES = ("output_filter", "output_clip")
KINDS = CARRIED + STAGES
FILTER = {"a": 0.3, "b0": 0.5, "b1": 0.2}
CLIP = {**FILTER, "lo_m_s": -0.18, "hi_m_s": 0.22}


def _run_inputs(d, V0, load):
    t = T0 + np.arange(N) * DT
    return {"t": t, "s": -0.01 * d + d * 0.2 * (t - T0), "V0": np.full(N, V0), "load": np.full(N, load),
            "d": np.full(N, d), "T": 30.0 + 5.0 * (t - T0), "v_start": 0.12 * d}


RUNS = [_run_inputs(1.0, 324.0, 0.03), _run_inputs(-1.0, 250.0, -0.02)]


def _setups(scale: float = 1.03):
    """``(base, refit)``: the reference motor's derived predictor and the same with every parameter times ``scale``
    (a stand-in for the joint re-identification), both at the sample interval ``DT``."""
    mp = load_motor()
    pp = derive_predictor(mp, n_grid=9)
    base = PredictorSetup(pp, mp.slider.mass_kg, DT)
    refit = type(pp).from_vector(pp.to_vector() * scale, s_center=pp.s_center, s_half=pp.s_half, kappa=pp.kappa,
                                 include_load_inertia=pp.include_load_inertia)
    return base, PredictorSetup(refit, mp.slider.mass_kg, DT)


def _frame() -> pd.DataFrame:
    return pd.concat([pd.DataFrame({dataio.TIME: r["t"], dataio.RUN: i, dataio.POSITION: r["s"],
                                    dataio.VOLTAGE: r["V0"], dataio.LOAD: r["load"], dataio.DIRECTION: r["d"],
                                    dataio.TEMPERATURE: r["T"], dataio.SPEED: r["v_start"]})
                      for i, r in enumerate(RUNS)], ignore_index=True)


def _free_run(ep: ExtendedPredictor, r, t=None) -> np.ndarray:
    return ep.free_run(r["t"] if t is None else t, r["s"], r["V0"], r["load"], r["d"], r["v_start"], temperature=r["T"])


def _phi(rng, F: np.ndarray) -> np.ndarray:
    """Random parameters giving each feature column a force of about 0.1 N rms (columns that vanish: 0)."""
    rms = np.sqrt(np.mean(np.asarray(F, float) ** 2, axis=0))
    return np.where(rms > 1e-12, rng.normal(0.0, 1.0, len(rms)) * 0.1 / np.maximum(rms, 1e-12), 0.0) / np.sqrt(len(rms))


@pytest.fixture(scope="module")
def pool():
    """The close-the-loop library's candidates on the test frame (baseline: the derived predictor)."""
    base, _ = _setups()
    plain = ExtendedPredictor(base, base)

    def baseline_free_run(frame):
        firsts = frame.groupby(dataio.RUN, sort=False)[dataio.SPEED].first().to_numpy()
        return plain.free_run(frame[dataio.TIME], frame[dataio.POSITION], frame[dataio.VOLTAGE], frame[dataio.LOAD],
                              frame[dataio.DIRECTION], firsts, frame[dataio.RUN].to_numpy())
    ctx = Context(baseline_free_run, base.slider_mass_kg, (T0, T0 + 1.0), (-0.02, 0.02), temperature_ref=31.0)
    return full_library()(ctx, _frame()) + _run_level_candidates(ctx, _frame())


def _run_level_candidates(ctx, df) -> list:
    """The run-level candidates of every input signal, as the loop's run-level analysis offers them (run values'
    mean and sd, TRAIN's within-run spread)."""
    from l1b2.closeloop.candidates import candidate, channels_of
    from l1b2.closeloop.runlevel import run_signals
    sigs = [{**sg, "mean": float(np.mean(sg["values"])), "sd": float(np.std(sg["values"]))}
            for sg in run_signals(df, channels_of(df))]
    return [candidate(ctx, h) for h in fx.family("run_level").hypotheses(sigs)]


def _exportable(c) -> bool:
    from l1b2.predictor.effects.channels import export_problem
    return export_problem(c.spec) is None


def test_every_candidate_has_one_parameter_per_feature_column_and_a_spec(pool):
    # reference: the candidate's own feature matrix (a mismatch made generic time/speed/temperature terms unfittable)
    df = _frame()
    for c in pool:
        assert c.spec and c.spec["kind"] in fx.KINDS, c.label
        assert np.asarray(c.features(df)).shape == (len(df), c.n_params) == (len(df), len(c.units)), c.label


@pytest.fixture(scope="module")
def models(pool) -> dict[str, ExtendedPredictor]:
    """One extended model per kind: the library's candidates of that kind (all regressors for the generic kinds)."""
    base, refit = _setups()
    df = _frame()
    rng = np.random.default_rng(7)
    out = {}
    for kind in CARRIED:
        cands = [c for c in pool if c.spec["kind"] == kind and _exportable(c)]
        assert cands, f"the library has no candidate of kind {kind}"
        if kind == "run_level":   # two of the four input signals (with two runs their z are all +-1: collinear)
            cands = [c for c in cands if (c.spec["channel"], c.spec["transform"]) in (("voltage_V", "none"),
                                                                                       ("load_kg", "drive"))]
        elif kind not in ("smooth", "smooth_pair", "channel"):   # a defect on the runs' path (centre near 0 mm)
            cands = [min(cands, key=lambda c: abs(c.spec.get("center_m", 0.0)))]
        effects = tuple(IdentifiedEffect(c.family, c.label, c.spec, c.names, c.units,
                                         tuple(_phi(rng, c.features(df))), (0.01,) * c.n_params, c.description,
                                         c.regressors, c.structural) for c in cands)
        out[kind] = ExtendedPredictor(base, refit, effects, None, {"train": "synthetic test frame"})
    out["output_filter"] = ExtendedPredictor(base, refit, out["load_path_friction"].effects, FILTER,
                                             {"train": "synthetic test frame"})
    out["output_clip"] = replace(out["output_filter"], output_filter=CLIP)
    return out


@pytest.fixture(scope="module")
def built(models, tmp_path_factory) -> dict[str, str]:
    root = tmp_path_factory.mktemp("extended")
    return {k: str(build_fmu("Predictor", root / k, extra_defaults={"predictor": m.model.to_dict(),
                                                                    "extended_predictor": m.to_dict()}))
            for k, m in models.items()}


def worker_fmpy(paths: dict, runs: list, t0: float):
    """Each FMU through fmpy over each run: v after initialisation, then after each step (inputs at the step's start)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    out = {}
    for kind, path in paths.items():
        md = read_model_description(path)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        names = ["V0", "s", "load", "direction"] + (["T"] if "T" in vr else [])
        unzipped = extract(path)
        out[kind] = []
        for r in runs:
            cols = [r["V0"], r["s"], r["load"], r["d"]] + ([r["T"]] if "T" in vr else [])
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                            instanceName=kind)
            v = []
            try:
                fmu.instantiate()
                fmu.setupExperiment(startTime=t0)
                fmu.setReal([vr["v0"]], [r["v_start"]])
                fmu.setReal([vr[n] for n in names], [c[0] for c in cols])
                fmu.enterInitializationMode()
                fmu.exitInitializationMode()
                v.append(fmu.getReal([vr["v"]])[0])
                for k in range(len(r["t"]) - 1):
                    fmu.setReal([vr[n] for n in names], [c[k] for c in cols])
                    fmu.doStep(currentCommunicationPoint=r["t"][k], communicationStepSize=r["t"][k + 1] - r["t"][k])
                    v.append(fmu.getReal([vr["v"]])[0])
                fmu.terminate()
            finally:
                fmu.freeInstance()
            out[kind].append(v)
    return out


@pytest.fixture(scope="module")
def through_fmpy(built, isolated):
    runs = [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in RUNS]
    return isolated(__file__, "worker_fmpy", built, runs, T0).value


@pytest.mark.parametrize("kind", KINDS)
def test_extended_predictor_fmu_equals_the_extended_model_through_fmpy(kind, models, through_fmpy):
    # reference: ExtendedPredictor.free_run (vectorised), 1e-10 relative; the effect must move the speed
    ep = models[kind]
    plain = ExtendedPredictor(ep.baseline, ep.model)
    for r, got in zip(RUNS, through_fmpy[kind]):
        want = _free_run(ep, r)
        np.testing.assert_allclose(np.array(got), want, rtol=1e-10, atol=1e-14)
        assert np.max(np.abs(want - _free_run(plain, r))) > 1e-4   # not vacuous: the effect changes the speed
    if kind == "output_clip":   # each run meets a rail, and the filtered speed beyond it is held there
        free = [_free_run(replace(ep, output_filter=FILTER), r) for r in RUNS]
        assert np.max(free[0]) > CLIP["hi_m_s"] and np.min(free[1]) < CLIP["lo_m_s"]
        for f, got in zip(free, through_fmpy[kind]):
            np.testing.assert_allclose(got, np.clip(f, CLIP["lo_m_s"], CLIP["hi_m_s"]), rtol=1e-10, atol=1e-14)


def test_extended_predictor_fmu_declares_every_parameter_with_unit_and_provenance(models, built):
    # reference: fmpy validation, and the model's own effects (names, units, values, stderr in the description)
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    for kind, path in built.items():
        assert validate_fmu(path) == [], kind
        md = read_model_description(path)
        var = {v.name: v for v in md.modelVariables}
        assert all(v.unit for v in md.modelVariables if v.type == "Real"), kind
        for e in models[kind].effects:
            for n, u, p in zip(e.names, e.units, e.phi):
                assert var[n].causality == "parameter" and var[n].unit == u
                assert float(var[n].start) == pytest.approx(p, rel=1e-15)
                assert "standard error 0.01" in var[n].description and "synthetic test frame" in var[n].description
        assert ("T" in var) == models[kind].needs_temperature, kind
        rails = {k: v for k, v in (models[kind].output_filter or {}).items() if k.endswith("_m_s")}
        assert {n for n in var if n.startswith("speed_rail_")} == {f"speed_rail_{k[:2]}" for k in rails}, kind
        for k, value in rails.items():
            rail = var[f"speed_rail_{k[:2]}"]
            assert rail.causality == "parameter" and rail.unit == "m/s" and float(rail.start) == value
        assert {"baseline_c_r", "c_r", "v_baseline", "F_extra"} <= set(var), kind


def test_a_parameter_without_a_finite_standard_error_is_declared_not_identifiable_on_its_own(models):
    # reference: the declared descriptions; a finite standard error is stated, an infinite or missing one is not
    # (the value is one point of a combination the data determine, not an identified value)
    from l1b2.cosim.composite import ExtendedPredictorBlock
    model = models["output_filter"]
    e = model.effects[0]
    assert len(e.names) >= 1
    for se in (float("inf"), float("nan"), None):
        odd = replace(model, effects=(replace(e, stderr=(se,) + tuple(e.stderr[1:])),) + model.effects[1:])
        var = {v.name: v for v in ExtendedPredictorBlock.variables(odd)}
        told = var[e.names[0]].description
        assert "not identifiable on its own" in told and "standard error" not in told.replace("finite standard", "")
        assert var[e.names[0]].start == e.phi[0]
    var = {v.name: v for v in ExtendedPredictorBlock.variables(model)}
    assert "identified" in var[e.names[0]].description and "standard error 0.01" in var[e.names[0]].description


def _run_level_effect(channel: str, **spec) -> IdentifiedEffect:
    h = fx.family("run_level").hypotheses([{"channel": channel, "transform": "none", **spec}])[0]
    return IdentifiedEffect(h.family, h.family, h.spec, h.names, h.units, (0.1,) * len(h.names),
                            (0.01,) * len(h.names), h.description, (h.regressor,), h.structural)


@pytest.mark.parametrize("kind", ["channel", "session_clock"])
def test_a_model_reading_the_session_clock_as_a_channel_is_refused_by_the_export(pool, tmp_path, kind):
    # reference: the inputs of Predictor.fmu: the session clock time_s is no input at either level (the FMU's own
    # time is the clock; its run mean changes within a run); a logged channel has an input (test file
    # tests/test_predictor_fmu_channels.py)
    from l1b2.fmi.export import ExportError, export_calibrated
    base, refit = _setups()
    if kind == "channel":
        c = next(c for c in pool if c.spec["kind"] == "channel" and c.spec["channel"] == dataio.TIME)
        eff = IdentifiedEffect(c.family, c.label, c.spec, c.names, c.units, (0.1,) * c.n_params,
                               (0.01,) * c.n_params, c.description, c.regressors, c.structural)
    else:
        eff = _run_level_effect(dataio.TIME, mean=T0 + 0.5, sd=0.3, run_spread=0.0)
    assert not fx.needs(eff.spec) <= set(fx.SIGNALS)
    with pytest.raises(ExportError, match="^Predictor.fmu has no input for the signals these effects read: "
                                          + eff.label.replace("[", r"\[").replace("]", r"\]") + "$"):
        export_calibrated(ExtendedPredictor(base, refit, (eff,), None, {}), tmp_path / "out")
    assert not (tmp_path / "out" / "fmus" / "Predictor.fmu").exists()


@pytest.mark.parametrize("spread,refused", [(None, True), (0.0, False), (0.01 * 7.0, False), (0.0101 * 7.0, True)])
def test_a_run_level_input_the_runs_did_not_hold_constant_is_refused(spread, refused, tmp_path):
    # reference: the run-level contract of Predictor.fmu (l1b2.predictor.effects.channels.export_problem): the FMU
    # reads the run's voltage as the input's current value, so the export needs TRAIN's largest within-run deviation
    # (run_spread) at most RUN_CONSTANT_TOL = 0.01 standard deviations of the run-level signal (sd 7 V here)
    from l1b2.fmi.export import ExportError, export_calibrated
    from l1b2.predictor.effects.channels import RUN_CONSTANT_TOL, export_problem
    assert RUN_CONSTANT_TOL == 0.01
    eff = _run_level_effect(dataio.VOLTAGE, mean=290.0, sd=7.0, **({} if spread is None else {"run_spread": spread}))
    assert (export_problem(eff.spec) is not None) == refused
    if not refused:
        return   # the export of such a model is tested through fmpy below
    base, refit = _setups()
    with pytest.raises(ExportError, match="TRAIN's runs held that input constant: run_level_voltage_V: not constant"):
        export_calibrated(ExtendedPredictor(base, refit, (eff,), None, {}), tmp_path / "out")
    assert not (tmp_path / "out" / "fmus").exists() or not any((tmp_path / "out" / "fmus").iterdir())


def test_run_spread_is_the_largest_deviation_from_the_runs_mean():
    # reference: written out per run: run 7 holds 3.0 (spread 0); run 2 has mean 2.0 and deviations -1, +1, 0;
    # run 5 has mean 10.5 and deviations -0.5, +0.5: the largest |deviation| is 1.0, whatever the run order
    from l1b2.predictor.effects.channels import run_spread
    values = np.array([3.0, 3.0, 1.0, 3.0, 2.0, 10.0, 11.0])
    run = np.array([7, 7, 2, 2, 2, 5, 5])
    assert run_spread(values, run) == pytest.approx(1.0, abs=1e-15)
    assert run_spread(values[:2], run[:2]) == 0.0
    assert run_spread(values[5:], run[5:]) == pytest.approx(0.5, abs=1e-15)
    assert run_spread(np.array([]), np.array([])) == 0.0


@pytest.mark.parametrize("drop", [None, "gain"])
def test_exported_run_level_voltage_model_reproduces_the_identifications_prediction(pool, tmp_path, isolated,
                                                                                    drop):
    # reference: the identification's own free run of a model with a run-level voltage effect (the re-identified
    # setup's l1b2.predictor.simulate.free_run with the candidate's force, whose run-level voltage is each run's
    # mean by groupby), against export_calibrated's Predictor.fmu and its native FMU through fmpy, 1e-10 relative;
    # the reduced form without the gain: the full form's offset and load columns
    from l1b2.fmi.export import export_calibrated
    from l1b2.predictor.simulate import free_run
    base, refit = _setups()
    df = _frame()
    c = next(c for c in pool if c.spec["kind"] == "run_level" and c.spec["channel"] == dataio.VOLTAGE)
    keep = [0, 1, 2] if drop is None else [1, 2]
    cols = np.asarray(c.features(df))[:, keep]
    phi = np.array([0.3, -0.2, 0.5])[keep] * 0.1 / np.sqrt(np.mean(cols ** 2, axis=0))
    force = cols @ phi
    if drop is not None:
        [h] = fx.family("run_level").hypotheses([{**c.spec, "drop": drop}])
        c = replace(c, shape=h.shape, names=h.names, units=h.units, spec=h.spec)
    want = free_run(refit.params, df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD], df[dataio.DIRECTION],
                    df[dataio.TIME], [r["v_start"] for r in RUNS], refit.slider_mass_kg, df[dataio.RUN].to_numpy(),
                    extra_force=force)
    plain = free_run(refit.params, df[dataio.POSITION], df[dataio.VOLTAGE], df[dataio.LOAD], df[dataio.DIRECTION],
                     df[dataio.TIME], [r["v_start"] for r in RUNS], refit.slider_mass_kg, df[dataio.RUN].to_numpy())
    assert np.max(np.abs(want - plain)) > 1e-4   # not vacuous: the run-level voltage effect moves the speed
    eff = IdentifiedEffect(c.family, c.label, c.spec, c.names, c.units, tuple(phi), (0.01,) * len(phi), c.description,
                           c.regressors, c.structural)
    man = export_calibrated(ExtendedPredictor(base, refit, (eff,), None, {"train": "synthetic"}), tmp_path / "out")
    assert man["native"]["Predictor"]["included"], man["native"]
    assert man["inputs"] == ["V0", "s", "load", "direction"]
    fmus = tmp_path / "out" / "fmus"
    runs = [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in RUNS]
    got = isolated(__file__, "worker_fmpy", {"py": str(fmus / "Predictor.fmu"),
                                             "native": str(fmus / "Predictor-native.fmu")}, runs, T0).value
    for key in ("py", "native"):
        np.testing.assert_allclose(np.concatenate(got[key]), want, rtol=1e-10, atol=1e-14, err_msg=key)


def test_extended_model_spec_roundtrips_through_json(models):
    # reference: the model itself (to_dict -> JSON -> from_dict gives the same predictions)
    for ep in models.values():
        again = ExtendedPredictor.from_dict(json.loads(json.dumps(ep.to_dict())))
        for r in RUNS:
            np.testing.assert_array_equal(_free_run(again, r), _free_run(ep, r))


def test_time_derivative_is_numpys_gradient_and_exact_on_quadratics():
    # reference: numpy.gradient (non-uniform spacing) and the exact derivative of a quadratic
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 50))
    v = 3.0 * t ** 2 - t + 0.2
    got = fx.time_derivative(v, t)
    np.testing.assert_allclose(got, np.gradient(v, t), rtol=1e-12)
    np.testing.assert_allclose(got[1:-1], 6.0 * t[1:-1] - 1.0, rtol=1e-9)
    two = fx.time_derivative(np.r_[v, v], np.r_[t, t], [0, 50])   # run by run
    np.testing.assert_allclose(two, np.r_[got, got], rtol=0, atol=0)


def test_unknown_effect_kinds_and_missing_signals_are_named():
    with pytest.raises(fx.EffectSpecError, match="unknown effect kind 'nope'"):
        fx.effect_features({"kind": "nope"}, {})
    with pytest.raises(fx.EffectSpecError, match="lacks the scalar 'period_m'"):
        fx.effect_features({"kind": "bar_waviness"}, {"V0": [300.0], "d": [1.0], "s": [0.0], "v_base": [0.1]})
    with pytest.raises(fx.EffectSpecError, match="signal 'T'"):
        fx.effect_features({"kind": "thermal_drift_T", "T_ref": 25.0}, {"V0": [300.0], "d": [1.0]})
    assert fx.needs({"kind": "smooth_pair", "a": "load", "b": "speed"}) == {"V0", "d", "load", "v_base"}


# ---------------------------------------------------------------------------
# the C host (l1b2/fmi/chost/fmu_host.c): constant inputs, FMU time from 0
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    import shutil

    from l1b2.fmi.runtime import compile_c_host
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        pytest.skip("no C compiler")
    return compile_c_host(tmp_path_factory.mktemp("chost") / "fmu_host")


@pytest.mark.parametrize("kind", KINDS)
def test_extended_predictor_fmu_equals_the_extended_model_through_the_c_host(kind, models, built, c_host,
                                                                              tmp_path):
    # reference: ExtendedPredictor.free_run with the C host's inputs (held constant) and time (0, h, 2h, ...)
    import zipfile

    from fmpy import read_model_description
    from l1b2.fmi.runtime import host_environment
    d = tmp_path / "fmu"
    with zipfile.ZipFile(built[kind]) as z:
        z.extractall(d)
    md = read_model_description(str(d / "modelDescription.xml"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    r = {k: (np.full(N, v[0]) if isinstance(v, np.ndarray) and k not in ("t",) else v) for k, v in RUNS[0].items()}
    args = [str(c_host), "-h", repr(DT), "-n", str(N - 1), "-p", f"{vr['v0']}={r['v_start']!r}"]
    for name, key in (("V0", "V0"), ("s", "s"), ("load", "load"), ("direction", "d"), ("T", "T")):
        if name in vr:
            args += ["-i", f"{vr[name]}={float(r[key][0])!r}"]
    args += ["-o", str(vr["v"]), str(d), md.coSimulation.modelIdentifier, md.guid]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=120, env=host_environment())
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines() if line.strip()])
    t = np.arange(N) * DT
    np.testing.assert_allclose(rows[:, 0], t, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rows[:, 1], _free_run(models[kind], r, t=t), rtol=1e-10, atol=1e-14)


# ---------------------------------------------------------------------------
# the native Predictor FMU of an extended model (C generated from l1b2.predictor.effects.kernels)
# ---------------------------------------------------------------------------

def test_effect_kernels_equal_the_families_features(pool):
    # reference: each family's vectorised features @ phi (l1b2.predictor.effects), sample by sample, for every
    # candidate the library proposes on the test frame (random phi), 1e-12 relative to the force's scale
    from l1b2.predictor.effects import kernels as ek
    df = _frame()
    rng = np.random.default_rng(11)
    x = {"t": df[dataio.TIME].to_numpy(copy=True), "s": df[dataio.POSITION].to_numpy(copy=True),
         "V0": df[dataio.VOLTAGE].to_numpy(), "load": df[dataio.LOAD].to_numpy(), "d": df[dataio.DIRECTION].to_numpy(),
         "T": df[dataio.TEMPERATURE].to_numpy(), "v_base": rng.normal(0.0, 0.1, len(df)),
         "a_base": rng.normal(0.0, 2.0, len(df))}
    # the samples at the ranges' ends and beyond (clipping), and at the B-spline knots
    x["t"][:6] = [T0 - 1.0, T0, T0 + 0.5, T0 + 1.0, T0 + 2.0, T0 + 1.0 / 3.0]
    x["s"][:6] = [-0.05, -0.02, 0.0, 0.02, 0.05, 0.01]
    x.update({k: v for k, v in _identification_signals(df).items() if k not in x})   # channels, run means
    seen, forms = set(), set()
    for c in pool:
        if c.spec["kind"] not in ek.KERNEL_KINDS:
            continue
        if not _exportable(c):   # a channel that is no input, or a run mean the runs did not hold constant
            with pytest.raises(fx.EffectSpecError, match="no input|not constant within runs"):
                ek.spec_scalars(c.spec)
            continue
        seen.add(c.spec["kind"])
        forms.add(c.spec.get("form"))
        phi = rng.normal(0.0, 1.0, c.n_params)
        want = fx.effect_features(c.spec, x) @ phi
        kind, q = ek.spec_scalars(c.spec)
        rows = np.column_stack([x[s] for s in fx.SIGNALS])
        got = np.array([ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want))), err_msg=c.label)
    assert seen == set(ek.KERNEL_KINDS)
    # every channel form (the temperature's)
    assert {"friction", "force_factor", "force", "inertia", "damping"} <= forms


def _identification_signals(df) -> dict:
    """Every ``col:``/``run:`` signal of the frame's columns as the identification computes it (run means by
    groupby), not as the FMU reads it."""
    from l1b2.closeloop.candidates import signals
    cols = [dataio.VOLTAGE, dataio.LOAD, dataio.DIRECTION, dataio.TEMPERATURE, dataio.TIME]
    return signals(df, None, [f"{p}{c}" for c in cols for p in ("col:", "run:")])


def test_run_level_kernels_equal_the_features_on_runs_that_hold_their_inputs(pool):
    # reference: RunLevel.features and Channel.features @ phi over the identification's signals (each run's mean by
    # groupby), on runs that hold V0, load, direction and temperature constant: the kernel, reading the inputs'
    # current values, gives the same force (1e-12 relative); a spec recording within-run variation is refused
    from l1b2.predictor.effects import kernels as ek
    df = _frame()
    df[dataio.TEMPERATURE] = np.where(df[dataio.RUN] == 0, 31.5, 27.25)
    rng = np.random.default_rng(5)
    x = {"t": df[dataio.TIME].to_numpy(), "s": df[dataio.POSITION].to_numpy(), "V0": df[dataio.VOLTAGE].to_numpy(),
         "load": df[dataio.LOAD].to_numpy(), "d": df[dataio.DIRECTION].to_numpy(),
         "T": df[dataio.TEMPERATURE].to_numpy(), "v_base": rng.normal(0.0, 0.1, len(df)),
         "a_base": rng.normal(0.0, 2.0, len(df)), **_identification_signals(df)}
    from l1b2.closeloop.candidates import channels_of
    from l1b2.closeloop.runlevel import run_signals
    sigs = [{**sg, "mean": float(np.mean(sg["values"])) + 0.1, "sd": float(np.std(sg["values"]))}
            for sg in run_signals(df, channels_of(df))]
    hyps = [h for h in fx.family("run_level").hypotheses(sigs) if ek.fmu_signal("run:" + h.spec["channel"])]
    assert {h.spec["channel"] for h in hyps} == {dataio.VOLTAGE, dataio.LOAD, dataio.DIRECTION, dataio.TEMPERATURE}
    import re   # the parameters are FMU variables: legal structured FMI names (fmpy refused "|load_kg|_run_gain")
    assert all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", n) for h in hyps for n in h.names), [h.names for h in hyps]
    load_abs = float(np.max(np.abs(df[dataio.LOAD])))
    assert load_abs > 0
    chans = fx.family("channel").grid(fx.TrainingSummary(1.0, (T0, T0 + 1), (-0.02, 0.02), 300.0,
                                                         {"load_abs": load_abs}, channels=channels_of(df)))
    rows = np.column_stack([x[sg] for sg in fx.SIGNALS])
    n_checked = 0
    for h in hyps + [h for h in chans if h.spec["channel"] == dataio.TEMPERATURE]:
        assert h.spec.get("level") == "sample" or h.spec["run_spread"] == pytest.approx(0.0, abs=1e-12), h.family
        phi = rng.normal(0.0, 1.0, len(h.names))
        want = fx.effect_features(h.spec, x) @ phi
        kind, q = ek.spec_scalars(h.spec)
        got = np.array([ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want))), err_msg=h.family)
        assert np.max(np.abs(want)) > 1e-3, h.family
        n_checked += 1
    # V0, d*load, |load|, direction, temperature; its channel's 3 forms x (3 shapes + 2 shapes x load) and the
    # inertia form in the 3 shapes and the damping form in the linear and quadratic shapes (run)
    assert n_checked == 4 + 1 + 3 * (3 + 2) + 3 + 2
    # a reduced form (without one column) is the full form with that column's parameter 0: features and kernel
    for h in hyps:
        for j, drop in enumerate(("gain", "offset", "load")):
            [r] = fx.family("run_level").hypotheses([{**h.spec, "drop": drop}])
            phi = rng.normal(0.0, 1.0, 2)
            full_phi = np.insert(phi, j, 0.0)
            want = fx.effect_features(h.spec, x) @ full_phi
            np.testing.assert_allclose(fx.effect_features(r.spec, x) @ phi, want, rtol=1e-13, atol=1e-13)
            kind, q = ek.spec_scalars(r.spec)
            got = np.array([ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows])
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want))))
            assert r.family == h.family and len(r.names) == 2 and r.names == tuple(
                n for k, n in enumerate(h.names) if k != j)
    # a logged temperature's run mean centred on 29 degC times the direction (the loop's d*<column> signal)
    [h] = fx.family("run_level").hypotheses([{"channel": dataio.TEMPERATURE, "transform": "drive", "centre": 29.0,
                                              "mean": 0.1, "sd": 2.0, "run_spread": 0.0}])
    phi = rng.normal(0.0, 1.0, 3)
    z = (x["d"] * (x["T"] - 29.0) - 0.1) / 2.0
    want = np.column_stack([x["V0"] / 300.0 * z, z, 9.81 * x["d"] * x["load"] * z]) @ phi
    np.testing.assert_allclose(fx.effect_features(h.spec, x) @ phi, want, rtol=1e-13, atol=1e-13)
    kind, q = ek.spec_scalars(h.spec)
    got = np.array([ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want))))
    # the same run mean centred on 29 degC, squared, less 0.7 times itself (the loop's <column>^2 signal)
    [h] = fx.family("run_level").hypotheses([{"channel": dataio.TEMPERATURE, "transform": "square", "centre": 29.0,
                                              "slope": 0.7, "mean": 4.0, "sd": 1.5, "run_spread": 0.0}])
    assert h.family == "run_level_temperature_C^2" and h.names[0] == "sq_temperature_C_run_gain"
    z = ((x["T"] - 29.0) ** 2 - 0.7 * (x["T"] - 29.0) - 4.0) / 1.5
    want = np.column_stack([x["V0"] / 300.0 * z, z, 9.81 * x["d"] * x["load"] * z]) @ phi
    np.testing.assert_allclose(fx.effect_features(h.spec, x) @ phi, want, rtol=1e-13, atol=1e-13)
    kind, q = ek.spec_scalars(h.spec)
    got = np.array([ek.effect_force(kind, row.tolist(), q, phi.tolist()) for row in rows])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want))))
    varied = dict(hyps[0].spec, run_spread=0.02 * hyps[0].spec["sd"])
    with pytest.raises(fx.EffectSpecError, match="not constant within runs"):
        ek.spec_scalars(varied)


def test_every_family_of_the_package_has_a_kernel():
    # reference: the registry's kinds that Predictor.fmu carries; a family without a per-sample kernel would keep
    # its calibrated models Python FMUs (the export says so)
    from l1b2.predictor.effects import kernels as ek
    assert set(CARRIED) - set(ek.KERNEL_KINDS) == set(), "families without a kernel in l1b2.predictor.effects.kernels"
    # no kernel: a logged channel's categories, the session clock's blocks and cycle
    assert set(fx.KINDS) - set(ek.KERNEL_KINDS) == {"run_level_category", "session_blocks", "session_cycle"}


OUTPUTS = ("v", "v_steady", "v_baseline", "F_extra")


def _native_kinds() -> tuple:
    """The kinds of :data:`KINDS` whose model has a native FMU (a per-sample kernel), and the output stages."""
    from l1b2.predictor.effects.kernels import KERNEL_KINDS
    return tuple(k for k in KINDS if k in KERNEL_KINDS or k in STAGES)


def worker_outputs(paths: dict, runs: list, t0: float):
    """Each FMU (FMI 2.0 or 3.0) through fmpy over each run: ``OUTPUTS`` after initialisation and after each step."""
    from fmpy import extract, read_model_description
    from l1b2.fmi.fmpy_slave import open_slave
    out = {}
    for key, path in paths.items():
        md = read_model_description(path)
        has_t = any(v.name == "T" for v in md.modelVariables)
        names = ["V0", "s", "load", "direction"] + (["T"] if has_t else [])
        unzipped = extract(path)
        out[key] = []
        for r in runs:
            cols = [r["V0"], r["s"], r["load"], r["d"]] + ([r["T"]] if has_t else [])
            with open_slave(path, unzipdir=unzipped, instance_name=key, start_time_s=t0,
                            params={"v0": r["v_start"]}, inputs={n: c[0] for n, c in zip(names, cols)}) as sl:
                rows = [sl.get(OUTPUTS)]
                for k in range(len(r["t"]) - 1):
                    sl.set({n: c[k] for n, c in zip(names, cols)})
                    sl.step(r["t"][k], r["t"][k + 1] - r["t"][k])
                    rows.append(sl.get(OUTPUTS))
            out[key].append(rows)
    return out


@pytest.fixture(scope="module")
def native_built(built, tmp_path_factory):
    """``{(kind, 2 or 3): path}`` of the native Predictor FMUs of the extended models."""
    from l1b2.fmi.native.build import build_native_fmu, find_cc
    try:
        find_cc()
    except Exception as exc:  # noqa: BLE001
        pytest.skip(str(exc))
    root = tmp_path_factory.mktemp("extended_native")
    return {f"{k}/{v}": str(build_native_fmu("Predictor", p, root / f"{k}-{v}", v)) for k, p in built.items()
            if k in _native_kinds() for v in (2, 3)}


@pytest.fixture(scope="module")
def native_outputs(built, native_built, isolated):
    runs = [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in RUNS]
    return isolated(__file__, "worker_outputs", {**{f"{k}/py": p for k, p in built.items() if k in _native_kinds()},
                                                 **native_built}, runs, T0).value


@pytest.mark.parametrize("kind", _native_kinds())
def test_native_extended_predictor_fmu_equals_the_python_fmu(kind, native_outputs):
    # reference: the Python Predictor.fmu of the same extended model in fmpy, same call sequence: every output
    # (v, v_steady, v_baseline, F_extra) after initialisation and after every step within 1e-9 relative, FMI 2.0
    # and 3.0; the effect's force is not zero (the comparison is not vacuous)
    for ver in (2, 3):
        for want, got in zip(native_outputs[f"{kind}/py"], native_outputs[f"{kind}/{ver}"]):
            want, got = np.array(want), np.array(got)
            assert want.shape == got.shape == (N, len(OUTPUTS))
            scale = np.max(np.abs(want), axis=0)
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * float(np.max(scale)), err_msg=f"FMI {ver}")
            assert scale[OUTPUTS.index("F_extra")] > 1e-3 or kind in STAGES


def test_native_extended_predictor_fmus_validate(native_built):
    # reference: fmpy validation (FMI 2.0 and 3.0), and the generated effect kernels among the sources
    import zipfile

    from fmpy.validation import validate_fmu
    for key, path in native_built.items():
        assert validate_fmu(path) == [], key
        with zipfile.ZipFile(path) as z:
            assert "sources/effect_kernels.h" in z.namelist()


def test_export_of_a_calibrated_model_writes_the_native_fmus(models, tmp_path):
    # reference: the manifest's file records and the native FMUs beside Predictor.fmu (FMI 2.0 and 3.0), which
    # carry the model's effect parameters with their identified values
    from fmpy import read_model_description
    from l1b2.fmi.export import export_calibrated
    ep = models["bar_waviness"]
    man = export_calibrated(ep, tmp_path / "out")
    names = {Path(f["path"]).name for f in man["files"]}
    assert {"Predictor.fmu", "Predictor-native.fmu", "Predictor-native-fmi3.fmu"} <= names
    assert man["native"]["Predictor"]["included"] is True
    for stem in ("Predictor-native", "Predictor-native-fmi3"):
        md = read_model_description(str(tmp_path / "out" / "fmus" / f"{stem}.fmu"))
        var = {v.name: v for v in md.modelVariables}
        for n, p in zip(ep.effects[0].names, ep.effects[0].phi):
            assert float(var[n].start) == pytest.approx(p, rel=1e-15)


def test_voltage_interactions_are_their_written_out_forms():
    # reference: the two structural interactions written out, -(d m g) dv and -(d v)/v_ref dv with
    # dv = (V0 - V_ref)/V_ref: bit-identical (one helper computes both)
    from l1b2.units import G_M_S2
    rng = np.random.default_rng(5)
    n = 200
    x = {"V0": rng.uniform(0, 500, n), "d": rng.choice([-1.0, 1.0], n), "load": rng.normal(0, 0.2, n),
         "v_base": rng.normal(0, 0.1, n)}
    spec = {"V_ref": 287.5}
    dv = (x["V0"] - spec["V_ref"]) / fx.V_REF
    np.testing.assert_array_equal(fx.effect_features({"kind": "load_slope_voltage", **spec}, x)[:, 0],
                                  -(x["d"] * x["load"] * G_M_S2) * dv)
    np.testing.assert_array_equal(fx.effect_features({"kind": "damping_voltage", **spec}, x)[:, 0],
                                  -(x["d"] * x["v_base"]) / fx.SPEED_REF * dv)
