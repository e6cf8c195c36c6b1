"""A new effect family is one file: the toy family of ``toy_effect.py``, registered at run time, goes through
the registry, the close-the-loop estimator, ``Predictor.fmu`` and the calibration of the subsystem FMUs with no
other module touched.

References: the rig's injected pulley friction (``rig_truth.json``: the calibrated ``Slider.pulley_mu``
within 10 %, as for the package's own ``load_path_friction``), and the extended model's vectorised free run
(:meth:`l1b2.predictor.effects.ExtendedPredictor.free_run`), which Predictor.fmu must reproduce through fmpy
in another process, where the toy family is known only from the file the export shipped.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from l1b2.closeloop.candidates import CandidateLibrary, default_library, named_candidates
from l1b2.closeloop.loop import close_loop
from l1b2.data.measurements import load_measurements
from l1b2.predictor import effects as fx
from l1b2.predictor.effects.homes import physical_homes
from l1b2.rig.experiment import RigPlan
from rigcache import rig_dir
from toy_effect import ToyPulley


@pytest.fixture
def toy():
    fx.register(ToyPulley)
    yield fx.family("toy_pulley")
    fx.unregister("toy_pulley")


def test_a_family_registered_at_run_time_is_in_the_registry_the_library_and_the_homes(toy):
    # reference: the toy's law, -g |m_load| per unit coefficient (g = 9.81 m/s^2, the package's G_M_S2),
    # evaluated by lookup
    assert "toy_pulley" in fx.KINDS and fx.needs({"kind": "toy_pulley"}) == {"V0", "d", "load"}
    x = {"V0": np.array([300.0, 300.0]), "d": np.array([1.0, -1.0]), "load": np.array([0.05, -0.02])}
    np.testing.assert_allclose(fx.effect_features({"kind": "toy_pulley"}, x)[:, 0], [-0.05 * 9.81, -0.02 * 9.81],
                               rtol=1e-15)
    assert physical_homes()["toy_pulley"] == "Slider.pulley_mu"
    d = rig_dir("pulley_friction_1", injections=["pulley_friction"], injection_seed=1,
                plan=RigPlan(step_s=1e-3, seed=1))
    df = load_measurements(d / "train.csv").df
    from l1b2.closeloop.loop import candidate_context
    ctx = candidate_context(lambda frame: np.zeros(len(frame)), 0.12, df, np.ones(len(df), bool), {})
    fams = [c.family for c in default_library()(ctx, df)]
    assert fams.count("toy_pulley") == 1 and fams.index("toy_pulley") < fams.index("smooth_time")


def test_toy_family_through_the_loop_the_fmu_and_the_calibration(toy, tmp_path, isolated):
    from l1b2.workflows import export_close_loop
    d = rig_dir("pulley_friction_1", injections=["pulley_friction"], injection_seed=1,
                plan=RigPlan(step_s=1e-3, seed=1))
    only_toy = CandidateLibrary(lambda ctx, df: [c for c in named_candidates(ctx, df) if c.family == "toy_pulley"])
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"), library=only_toy)
    diag = res.diagnosis
    assert diag["effect"] == "toy_pulley" and diag["traced_to"][0] == "load", diag["message"]
    assert res.after["test"]["free_run"]["nrmse"] <= 0.5 * res.before["test"]["free_run"]["nrmse"]

    man = export_close_loop(res, tmp_path / "exp")
    truth = json.loads((d / "rig_truth.json").read_text())["injections"][0]["parameters"]["Slider.pulley_mu"]
    # the toy's record (the loop may add run-level effects beside it: they are not of the library)
    (rec,) = [e for e in man["effects"] if e["family"] == "toy_pulley"]
    assert rec["subsystems"]["home"] == "Slider.pulley_mu"
    assert all(e["family"].startswith("run_level") for e in man["effects"] if e is not rec)
    assert man["calibrated_ssp"]["changed"]["Slider.pulley_mu"] == pytest.approx(truth, rel=0.1)

    dte = res.test_df
    run = dte[dte["run"] == dte["run"].iloc[0]]
    want = res.calibrated_model.free_run(run["time_s"], run["position_m"], run["voltage_V"], run["load_kg"],
                                         run["direction"], float(run["speed_m_s"].iloc[0]))
    r = {"t": run["time_s"].tolist(), "s": run["position_m"].tolist(), "V0": run["voltage_V"].tolist(),
         "load": run["load_kg"].tolist(), "d": run["direction"].tolist(), "v_start": float(run["speed_m_s"].iloc[0])}
    got = isolated(str(Path(__file__).with_name("test_extended_predictor_fmu.py")), "worker_fmpy",
                   {"fmu": str(tmp_path / "exp" / "fmus" / "Predictor.fmu")}, [r], r["t"][0]).value["fmu"][0]
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-13)
