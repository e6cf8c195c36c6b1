"""Design studies (`l1b2 sweep`, issue 13): spec checks, sampling, estimators, the Dask engine.

Short traverses (a 4 mm stroke at a 1 ms step, ~0.1 s each) and few samples
keep this fast; the Dask tests start two local clusters of two processes.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from l1b2.errors import L1B2Error, SimulationError, SpecError
from l1b2.sweep.analysis import sobol_indices, src_ranking
from l1b2.sweep.sampling import draw_samples
from l1b2.sweep.spec import parse_spec
from l1b2.sweep.tasks import simulate_sample
from l1b2.workflows import run_sweep

TINY = """
[study]
name = "tiny"
seed = 7
engine = "inprocess"
draws = 5
chunk_size = 3

[simulation]
step_s = { value = 1e-3, unit = "s" }
max_time_s = { value = 0.5, unit = "s" }

[operating_points]
V0 = { values = [324.0], unit = "V" }
load = { values = [0.05], unit = "kg" }
direction = { values = [1, -1], unit = "1" }

[parameters]
"Stator.P0_N" = { distribution = "normal", sd = 0.3, bounds = [5.5, 7.2], unit = "N" }
"Interface.mu_p" = { distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }

[fixed]
"Slider.s_min_m" = { value = -0.002, unit = "m" }
"Slider.s_max_m" = { value = 0.002, unit = "m" }

[outputs]
mean_speed = { middle = 0.5 }
speed_at = { positions = [0.0], unit = "m" }
traverse_time = true
stall = true
"""
N_SAMPLES = 10  # 2 operating points x 5 draws, in 4 chunks of 3


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("spec") / "tiny.toml"
    p.write_text(TINY)
    return p


@pytest.fixture(scope="module")
def serial(spec_file, tmp_path_factory):
    """The reference: the tiny study run serially in this process."""
    out = tmp_path_factory.mktemp("serial")
    res = run_sweep(spec_file, out, workers=0, progress=False, plots_on=False)
    return res, pd.read_parquet(out / "samples.parquet")


@pytest.fixture(scope="module")
def scheduler():
    """A 2-worker LocalCluster (processes, one thread each) shared by the tests that go through --scheduler."""
    import logging

    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster:
        yield cluster.scheduler_address


# ---------------------------------------------------------------------------
# hooks run on the workers (importable from this module)
# ---------------------------------------------------------------------------

def faulty_traverse(sample, motor, ctx, *, marker_dir, kill_id=None, fail_id=None):
    """The real traverse, except: sample ``fail_id`` raises; sample ``kill_id`` kills its worker process the
    first time it runs (a marker file remembers), then succeeds on the retry."""
    sid = int(sample["sample_id"])
    if sid == fail_id:
        raise SimulationError(f"injected failure of sample {sid}")
    if sid == kill_id:
        marker = Path(marker_dir) / f"killed-{sid}"
        if not marker.exists():
            marker.write_text(str(os.getpid()))
            os._exit(1)
    return simulate_sample(sample, motor, ctx)


CALLS: list[int] = []


def counting_traverse(sample, motor, ctx, *, stop_at=None):
    """Counts executions (serial runs only); ``stop_at``: an interrupt (Ctrl-C) on that sample."""
    if sample["sample_id"] == stop_at:
        raise KeyboardInterrupt
    CALLS.append(int(sample["sample_id"]))
    return simulate_sample(sample, motor, ctx)


# ---------------------------------------------------------------------------
# spec
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("old, new, key", [
    ('"Interface.mu_p"', '"Interface.mu_q"', "parameters.Interface.mu_q"),
    ('bounds = [5.5, 7.2]', 'bounds = [-1.0, 7.2]', "parameters.Stator.P0_N.bounds"),
    ('sd = 0.3, bounds = [5.5, 7.2], unit = "N"', 'sd = 0.3, unit = "kN"', "parameters.Stator.P0_N"),
    ('low = 0.13, high = 0.17, unit = "1"', 'low = 0.13, high = 0.17', "parameters.Interface.mu_p"),
    ('"normal"', '"gamma"', "parameters.Stator.P0_N.distribution"),
    ('V0 = { values = [324.0], unit = "V" }', 'V0 = { values = [324.0], unit = "kV" }', "operating_points.V0"),
    ('V0 =', 'V1 =', "operating_points.V1"),
    ('engine = "inprocess"', 'engine = "spice"', "study.engine"),
    ('chunk_size = 3', 'chunk_size = 3\nworkers = 2', "study.workers"),
    ('"Slider.s_min_m" = { value = -0.002, unit = "m" }', '"Slider.mass_kg" = { value = -1.0, unit = "kg" }',
     "fixed.Slider.mass_kg"),
    ('positions = [0.0], unit = "m"', 'positions = [0.0], unit = "mm"', "outputs.speed_at"),
])
def test_bad_specs_are_refused_with_one_line_naming_the_key(old, new, key):
    # reference: issue 13: unknown parameter name, bound outside the declared range, unit mismatch -> SpecError
    assert old in TINY
    with pytest.raises(SpecError) as exc:
        parse_spec(TINY.replace(old, new), "tiny.toml")
    msg = str(exc.value)
    assert msg.startswith(f"tiny.toml: {key}:"), msg
    assert "\n" not in msg


def test_parameters_by_ssv_or_toml_name_and_nested_tables():
    # reference: the SSV name (Interface.mu_p) and the TOML section.field (interface.mu_p) name one parameter
    a = parse_spec(TINY, "a.toml")
    b = parse_spec(TINY.replace('"Interface.mu_p"', "interface.mu_p"), "b.toml")
    assert [p.name for p in a.parameters] == [p.name for p in b.parameters] == ["Stator.P0_N", "Interface.mu_p"]
    nested = TINY.replace('"Interface.mu_p" = { distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }\n',
                          "") + '\n[parameters.Interface.mu_p]\ndistribution = "uniform"\nlow = 0.13\nhigh = 0.17\nunit = "1"\n'
    assert parse_spec(nested).parameters == a.parameters
    with pytest.raises(SpecError, match="given twice"):
        parse_spec(TINY.replace('"Interface.mu_p" = { distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }',
                                'stator.P0_N = { distribution = "normal", sd = 0.1, unit = "N" }'))


def test_the_shipped_study_parses_and_a_spec_may_name_its_motor(tmp_path):
    from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
    from l1b2.sweep.spec import motor_reference
    shipped = SYSTEM_MODELS_DIR / "studies" / "tolerances_220V.toml"
    spec = parse_spec(shipped.read_text(), str(shipped))
    assert spec.draws == 50 and len(draw_samples(spec)) == 50 and len(spec.parameters) == 5
    # a motor file beside the spec: its values are the defaults and ranges the spec is checked against
    (tmp_path / "m.toml").write_text((SYSTEM_MODELS_DIR / "reference_motor.toml").read_text().replace(
        "P0_N = { value = 6.35,", "P0_N = { value = 5.0,"))
    (tmp_path / "s.toml").write_text(TINY.replace("[study]", '[study]\nmotor = "m.toml"').replace(
        "bounds = [5.5, 7.2]", "bounds = [4.0, 6.0]"))
    text = (tmp_path / "s.toml").read_text()
    assert motor_reference(text) == "m.toml"
    spec = parse_spec(text, "s.toml", load_motor(tmp_path / "m.toml"))
    assert spec.parameters[0].a == 5.0  # the normal's mean defaults to this motor's preload
    (tmp_path / "bad.toml").write_text(TINY.replace("[study]", '[study]\nmotor = "nope.toml"'))
    with pytest.raises(L1B2Error, match="nope.toml"):
        run_sweep(tmp_path / "bad.toml", tmp_path / "o", workers=0, progress=False, plots_on=False)
    assert not (tmp_path / "o").exists()


def test_samples_are_drawn_up_front_from_the_seed_within_bounds():
    spec = parse_spec(TINY)
    s1, s2 = draw_samples(spec), draw_samples(spec)
    pd.testing.assert_frame_equal(s1, s2)
    assert len(s1) == N_SAMPLES and list(s1.sample_id) == list(range(N_SAMPLES))
    assert s1["Stator.P0_N"].between(5.5, 7.2).all() and s1["Interface.mu_p"].between(0.13, 0.17).all()
    # common random numbers: the same draws at both operating points
    np.testing.assert_array_equal(s1.loc[s1.op_id == 0, "Stator.P0_N"], s1.loc[s1.op_id == 1, "Stator.P0_N"])
    other = draw_samples(parse_spec(TINY.replace("seed = 7", "seed = 8")))
    assert not np.allclose(other["Stator.P0_N"], s1["Stator.P0_N"])


def test_saltelli_estimator_recovers_analytic_sobol_indices():
    # reference: y = 4 u1 + 2 u2 + 0 u3 with independent uniforms: S1 = ST = (0.8, 0.2, 0)
    text = TINY.replace('draws = 5', 'draws = 512\ndesign = "saltelli"').replace(
        '"Stator.P0_N" = { distribution = "normal", sd = 0.3, bounds = [5.5, 7.2], unit = "N" }',
        '"Stator.P0_N" = { distribution = "uniform", low = 6.0, high = 7.0, unit = "N" }\n'
        '"Slider.mass_kg" = { distribution = "uniform", low = 0.1, high = 0.2, unit = "kg" }')
    spec = parse_spec(text)
    df = draw_samples(spec)
    assert len(df) == 2 * 512 * (3 + 2)
    u1 = df["Stator.P0_N"] - 6.0
    u2 = (df["Interface.mu_p"] - 0.13) / 0.04
    df["y"] = 4 * u1 + 2 * u2
    df["status"] = "ok"
    sob = sobol_indices(df, ["y"]).query("op_id == 0").set_index("parameter")
    expect = {"Stator.P0_N": 0.8, "Interface.mu_p": 0.2, "Slider.mass_kg": 0.0}
    for p, v in expect.items():
        assert sob.loc[p, "S1"] == pytest.approx(v, abs=0.06)
        assert sob.loc[p, "ST"] == pytest.approx(v, abs=0.06)
    assert sob.loc["Stator.P0_N", "rank"] == 1
    src = src_ranking(df, ["y"]).query("op_id == 0").set_index("parameter")
    assert src.loc["Stator.P0_N", "src"] == pytest.approx(np.sqrt(0.8), abs=0.03)
    assert src.loc["Stator.P0_N", "r2"] == pytest.approx(1.0)


# ---------------------------------------------------------------------------
# running
# ---------------------------------------------------------------------------

def test_serial_study_gives_outputs_summary_and_ranking(serial, spec_file):
    res, table = serial
    assert list(table.sample_id) == list(range(N_SAMPLES)) and (table.status == "ok").all()
    assert (table.mean_speed_m_s > 0.1).all() and (~table.stalled).all()
    assert table["traverse_time_s"].between(0.01, 0.5).all()
    s = res.summary.query("output == 'mean_speed_m_s'")
    assert len(s) == 2 and (s.p5 <= s.p50).all() and (s.p50 <= s.p95).all()
    r = res.sensitivity.query("op_id == 0 and output == 'mean_speed_m_s'")
    assert set(r.parameter) == {"Stator.P0_N", "Interface.mu_p"} and (r.r2 > 0.9).all()
    assert res.info["executed_samples"] == N_SAMPLES


def test_cli_two_workers_identical_to_serial(serial, spec_file, scheduler, tmp_path, capsys):
    # reference: issue 13: the same seed gives the same Parquet content whatever the number of workers
    out = tmp_path / "study"
    code = cli_main(["sweep", "--spec", str(spec_file), "--out", str(out), "--scheduler", scheduler, "--quiet"])
    text = capsys.readouterr().out
    assert code == 0
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), serial[1])
    for f in ("summary.csv", "sensitivity.csv", "study.json", "sweep_outputs.png", "sweep_sensitivity.png",
              "sweep_operating_map.png"):
        assert (out / f).is_file(), f
    assert "on 2 worker(s)" in text and f"plot: {out / 'sweep_outputs.png'}" in text
    import pyarrow.parquet as pq
    assert pq.read_schema(out / "samples.parquet").field("mean_speed_m_s").metadata[b"unit"] == b"m/s"


def test_killed_worker_and_failing_sample_lose_and_duplicate_nothing(serial, spec_file, scheduler, tmp_path):
    # reference: issue 13: a worker killed mid-sweep is retried by Dask; a raising simulation is recorded
    hook = functools.partial(faulty_traverse, marker_dir=str(tmp_path), kill_id=4, fail_id=7)
    res = run_sweep(spec_file, tmp_path / "out", scheduler=scheduler, progress=False, plots_on=False, traverse=hook)
    assert res.info["engine_workers"] == 2
    assert (tmp_path / "killed-4").is_file()  # the worker really died once
    table = pd.read_parquet(tmp_path / "out" / "samples.parquet")
    assert list(table.sample_id) == list(range(N_SAMPLES))
    failed = table[table.status == "failed"]
    assert list(failed.sample_id) == [7]
    assert failed.error.iloc[0] == "SimulationError: injected failure of sample 7"
    assert failed[["mean_speed_m_s", "traverse_time_s"]].isna().all().all() and failed.stalled.isna().all()
    ref = serial[1]
    ok = table.status == "ok"
    pd.testing.assert_frame_equal(table[ok].reset_index(drop=True), ref[ok].reset_index(drop=True))
    assert "1 sample(s) failed" in "\n".join(res.report_lines())


def test_rerun_after_an_interrupt_skips_finished_chunks(serial, spec_file, tmp_path):
    # reference: issue 13: resumable; finished chunks (3 samples each) are stored and not run again
    out = tmp_path / "out"
    CALLS.clear()
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec_file, out, workers=0, progress=False, plots_on=False,
                  traverse=functools.partial(counting_traverse, stop_at=7))
    assert sorted(p.name for p in (out / "chunks").glob("chunk-*.parquet")) == ["chunk-00000.parquet",
                                                                                "chunk-00001.parquet"]
    assert CALLS == list(range(7))
    CALLS.clear()
    res = run_sweep(spec_file, out, workers=0, progress=False, plots_on=False, traverse=counting_traverse)
    assert CALLS == list(range(6, N_SAMPLES))  # chunks 2 (samples 6-8) and 3 (sample 9)
    assert res.info["skipped_samples"] == 6 and res.info["executed_samples"] == 4
    pd.testing.assert_frame_equal(pd.read_parquet(out / "samples.parquet"), serial[1])
    CALLS.clear()
    run_sweep(spec_file, out, workers=0, progress=False, plots_on=False, traverse=counting_traverse)
    assert CALLS == []
    # the folder belongs to this study: another seed is refused, nothing is mixed
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace("seed = 7", "seed = 8"))
    with pytest.raises(SpecError, match="another study"):
        run_sweep(other, out, workers=0, progress=False, plots_on=False)


def test_cli_refuses_a_bad_spec_with_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.replace('"Interface.mu_p"', '"Interface.mu_q"'))
    code = cli_main(["sweep", "--spec", str(bad), "--out", str(tmp_path / "o"), "--workers", "0"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and err.startswith("l1b2: error:")
    assert "parameters.Interface.mu_q" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.fmu
def test_fmu_engine_gives_the_in_process_results(serial, spec_file, tmp_path):
    # reference: README: the FMU master and the in-process engine agree to machine precision
    spec = tmp_path / "fmu.toml"
    spec.write_text(spec_file.read_text().replace('engine = "inprocess"', 'engine = "fmu"'))
    run_sweep(spec, tmp_path / "out", workers=0, progress=False, plots_on=False)
    table = pd.read_parquet(tmp_path / "out" / "samples.parquet")
    cols = ["mean_speed_m_s", "speed_at_+0mm_m_s", "traverse_time_s"]
    np.testing.assert_allclose(table[cols], serial[1][cols], rtol=1e-9)


# ---------------------------------------------------------------------------
# the rig on the same engine
# ---------------------------------------------------------------------------

def test_rig_on_dask_is_identical_to_serial_and_stateful_runs_stay_serial(monkeypatch):
    # reference: issue 13: the rig's parallel runs on the same engine (its own 2-worker LocalCluster here)
    from l1b2 import cluster
    from l1b2.rig.experiment import RigPlan, run_experiment
    plan = RigPlan(voltages_V=(324.0,), loads_kg=(0.0, 0.05), step_s=1e-3)
    a, _ = run_experiment(plan, workers=1)
    b, _ = run_experiment(plan, workers=2)
    pd.testing.assert_frame_equal(a, b)
    c, _ = run_experiment(plan, jobs=1)  # deprecated alias
    pd.testing.assert_frame_equal(a, c)

    def no_cluster(*args, **kw):
        raise AssertionError("a stateful injection must not go to the cluster")
    monkeypatch.setattr(cluster, "dask_client", no_cluster)
    d, _ = run_experiment(plan, injections=["thermal_drift"], workers=2, injection_seed=1)
    assert d["time_s"].is_monotonic_increasing
