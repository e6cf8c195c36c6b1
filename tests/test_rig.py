"""Virtual rig: the paper's experiment (Sect. 5.1, Fig. 9) on the co-simulated motor."""

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from l1b2.data import measurements as dataio
from l1b2.data import plots
from l1b2.data.metrics import evaluation_mask
from l1b2.physics.params import load_motor
from l1b2.rig.experiment import (
    INJECTIONS,
    RigPlan,
    RunSpec,
    apply_overrides,
    run_experiment,
    run_contact_factors,
    simulate_run,
    write_experiment,
)
from l1b2.errors import SimulationError

PLAN = RigPlan(voltages_V=(220.0, 272.0, 324.0), loads_kg=(-0.05, 0.0, 0.05), step_s=1e-3)


@pytest.fixture(scope="module")
def rig_data():
    df, truth = run_experiment(PLAN, engine="inprocess", jobs=1)
    return df, truth


def _mid_speed(df, V, load, direction):
    g = df[np.isclose(df.voltage_V, V) & np.isclose(df.load_kg, load) & (df.direction == direction)]
    mid = g[np.abs(g.position_m) < 0.005]
    return float(np.mean(np.abs(mid.speed_m_s)))


def test_every_run_traverses_the_stroke(rig_data):
    # reference: each run starts at rest at one end stop and ends at the other (paper Sect. 5.1)
    df, _ = rig_data
    mp = load_motor()
    assert df.run.nunique() == len(PLAN.voltages_V) * len(PLAN.loads_kg) * 2
    for _, g in df.groupby("run"):
        d = g.direction.iloc[0]
        start, end = (mp.slider.s_min_m, mp.slider.s_max_m) if d > 0 else (mp.slider.s_max_m, mp.slider.s_min_m)
        assert g.position_m.iloc[0] == pytest.approx(start, abs=1e-7)
        assert g.position_m.iloc[-1] == pytest.approx(end, abs=1e-7)


def test_speed_rises_with_voltage_and_falls_with_opposing_load(rig_data):
    # reference: paper Fig. 9(a) and 9(b)
    df, _ = rig_data
    for d in (1, -1):
        v = [_mid_speed(df, V, 0.0, d) for V in PLAN.voltages_V]
        assert np.all(np.diff(v) > 0.01), v
        # a positive load opposes +1 runs and assists -1 runs (data format)
        opp, free, assist = (_mid_speed(df, 324.0, d * L, d) for L in (0.05, 0.0, -0.05))
        assert opp < free - 0.02 < assist - 0.04


def test_speed_varies_with_position(rig_data):
    # reference: paper Fig. 9(a), docs/explanation/physics.md: 5-20 % over the stroke at constant input
    df, _ = rig_data
    g = df[(df.voltage_V == 324.0) & (df.load_kg == 0.0) & (df.direction == 1)].reset_index(drop=True)
    m = evaluation_mask(g) & (g.position_m.to_numpy() > -0.01)  # after the acceleration
    v = np.abs(g.speed_m_s.to_numpy()[m])
    assert 0.03 < (v.max() - v.min()) / v.mean() < 0.25


def test_speed_is_close_to_proportional_to_tip_velocity(rig_data):
    # reference: paper Fig. 9(c): v_s linear in omega*U_w with R^2 >= 0.95
    df, _ = rig_data
    fit = plots.fig9c_fit(df)
    assert fit["r2"] >= 0.95
    assert 0.2 < fit["k0"] < 1.5


def test_mirrored_runs_give_mirrored_speeds(rig_data):
    # reference: the reference motor is symmetric: (+1, load L) mirrors (-1, load -L); the runs come from
    # opposite ends over an asymmetric preload profile, so the slider's lag (tens of ms) differs slightly
    df, _ = rig_data
    for L in (0.0, 0.05):
        assert _mid_speed(df, 272.0, L, 1) == pytest.approx(_mid_speed(df, 272.0, -L, -1), rel=0.02)


def test_encoder_resolution_and_sampling(rig_data):
    # reference: 50 nm encoder sampled at 1 kHz (paper Sect. 5.1)
    df, _ = rig_data
    counts = df.position_m.to_numpy() / PLAN.encoder_resolution_m
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    for _, g in df.groupby("run"):
        assert np.allclose(np.diff(g.time_s), 1e-3, atol=1e-9)


def test_experiment_clock_is_continuous_with_pauses(rig_data):
    # reference: data format: time strictly increasing over the file, never reset between runs
    df, _ = rig_data
    t = df.time_s.to_numpy()
    assert np.all(np.diff(t) > 0)
    gaps = np.diff(t)[np.diff(df.run.to_numpy()) != 0]
    assert np.all(gaps >= PLAN.pause_s - 1e-9)


def test_written_files_follow_the_data_format(rig_data, tmp_path):
    # reference: the rig data format (docs/reference/data-format.md); the paper's split: test = runs with |load| = 0.05 kg
    df, truth = rig_data
    mp = load_motor()
    paths = write_experiment(df, tmp_path, mp, PLAN, truth)
    all_ = dataio.load_measurements(paths["all"])
    train = dataio.load_measurements(paths["train"])
    test = dataio.load_measurements(paths["test"])
    assert all_.n_samples == len(df)
    assert set(np.abs(test.df.load_kg)) == {0.05}
    assert 0.05 not in set(np.abs(train.df.load_kg))
    assert train.n_samples + test.n_samples == len(df)
    assert all_.meta["slider_mass_kg"] == mp.slider.mass_kg
    assert "tip_velocity_amp_m_s" in all_.df.columns  # extra column passed through
    assert json.loads((tmp_path / "rig_truth.json").read_text())["injections"] == []


def test_injected_effect_changes_the_data_but_is_not_declared(tmp_path):
    # reference: a direction asymmetry makes CH1 faster than CH2; neither CSV nor sidecar names it
    plan = RigPlan(voltages_V=(324.0,), loads_kg=(0.0,), step_s=1e-3)
    df, truth = run_experiment(plan, engine="inprocess", injections=["direction_asymmetry"])
    fwd, bwd = _mid_speed(df, 324.0, 0.0, 1), _mid_speed(df, 324.0, 0.0, -1)
    assert fwd > bwd * 1.03
    paths = write_experiment(df, tmp_path, load_motor(), plan, truth)
    text = paths["all"].read_text() + (tmp_path / "all.json").read_text()
    assert "asym" not in text and "direction_asymmetry" not in text
    assert json.loads((tmp_path / "rig_truth.json").read_text())["injections"][0]["name"] == "direction_asymmetry"


@pytest.mark.parametrize("name", sorted(INJECTIONS))
def test_every_effect_maps_to_declared_fmu_parameters(name):
    # reference: each effect only switches on parameters the FMU system declares (off in the reference)
    mp = load_motor()
    eff = INJECTIONS[name]
    changed = apply_overrides(mp, eff.draw(np.random.default_rng(0)))
    assert changed != mp
    for key in eff.params:
        comp, _, par = key.partition(".")
        assert hasattr(getattr(mp, comp.lower()), par)


def test_rig_cli_writes_data_plots_and_summary(tmp_path):
    # reference: issue text: DIR/all.csv, train.csv, test.csv with sidecars; Fig. 9 PNGs
    out = tmp_path / "rig"
    code = cli_main(["rig", "--out", str(out), "--engine", "inprocess", "--voltages", "220,324", "--loads", "0,0.05",
                     "--step", "0.001", "--quiet", "--jobs", "1"])
    assert code == 0
    for f in ("all.csv", "all.json", "train.csv", "train.json", "test.csv", "test.json", "rig_truth.json",
              "fig9a_speed_vs_position_by_voltage.png", "fig9b_speed_vs_position_by_load.png",
              "fig9c_speed_vs_tip_velocity.png", "rig_summary.json"):
        assert (out / f).exists(), f
    summary = json.loads((out / "rig_summary.json").read_text())
    assert summary["runs"] == 8
    assert pd.read_csv(out / "all.csv").shape[0] == summary["samples"]


def test_cli_refuses_bad_input_with_one_line(capsys, tmp_path):
    # reference: brief: one clear line, non-zero exit, no traceback
    code = cli_main(["simulate", "--out", str(tmp_path / "x.csv"), "--engine", "inprocess", "--direction", "2"])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("l1b2: error:") and "Traceback" not in err
    code = cli_main(["rig", "--out", str(tmp_path / "r"), "--inject", "no_such_effect", "--quiet"])
    err = capsys.readouterr().err
    assert code != 0 and "no_such_effect" in err and err.count("\n") == 1
    assert not (tmp_path / "r").exists()


NOISY = RigPlan(voltages_V=(324.0,), loads_kg=(0.0, 0.05), step_s=1e-3, seed=5)


@pytest.fixture(scope="module")
def noise_pair():
    """The same small plan without and with speed noise and run scatter (same seed, same run order)."""
    clean, _ = run_experiment(NOISY, engine="inprocess")
    noisy, truth = run_experiment(replace(NOISY, **{"speed_noise_m_s": 2e-3, "run_scatter": 0.05}),
                                  engine="inprocess")
    return clean, noisy, truth


def test_speed_noise_is_white_with_the_declared_std(noise_pair):
    # reference: closed form: speed = derivative of the encoder position + N(0, sigma^2) per sample
    clean, _, _ = noise_pair
    plan = replace(NOISY, **{"speed_noise_m_s": 2e-3})
    noisy, _ = run_experiment(plan, engine="inprocess")
    np.testing.assert_array_equal(noisy.position_m.to_numpy(), clean.position_m.to_numpy())
    e = noisy.speed_m_s.to_numpy() - clean.speed_m_s.to_numpy()
    n = len(e)
    assert abs(np.std(e) / 2e-3 - 1) < 4 / np.sqrt(2 * n)  # std of a sample std: sigma / sqrt(2n)
    assert abs(np.mean(e)) < 4 * 2e-3 / np.sqrt(n)
    assert abs(np.corrcoef(e[1:], e[:-1])[0, 1]) < 4 / np.sqrt(n)  # white: no lag-1 correlation
    again, _ = run_experiment(plan, engine="inprocess")
    np.testing.assert_array_equal(again.speed_m_s.to_numpy(), noisy.speed_m_s.to_numpy())  # seeded
    other, _ = run_experiment(replace(plan, **{"seed": 6}), engine="inprocess")
    assert not np.allclose(np.sort(other.speed_m_s.to_numpy()), np.sort(noisy.speed_m_s.to_numpy()))


def test_run_scatter_runs_each_traverse_with_its_own_contact(noise_pair):
    # reference: independent solution: each run equals a single traverse of the motor with P0 and mu_p
    # scaled by the run's recorded factors (and the noise-free runs differ from it by the scatter's effect)
    clean, noisy, truth = noise_pair
    factors = np.column_stack([truth["run_contact_factors"]["P0"], truth["run_contact_factors"]["mu_p"]])
    assert len(factors) == noisy.run.nunique()
    np.testing.assert_array_equal(factors, run_contact_factors(replace(NOISY, run_scatter=0.05), len(factors)))
    mp = load_motor()
    k = int(np.argmax(np.abs(factors - 1).max(axis=1)))  # the run with the largest contact change
    row = noisy[noisy.run == k + 1].iloc[0]
    spec = RunSpec(k + 1, float(row.voltage_V), float(row.load_kg), int(row.direction), float(row.time_s))
    scaled = mp.replace(stator__P0_N=mp.stator.P0_N * factors[k, 0], interface__mu_p=mp.interface.mu_p * factors[k, 1])
    one = simulate_run(scaled, spec, NOISY, nominal=mp)
    np.testing.assert_array_equal(one.position_m.to_numpy(), noisy[noisy.run == k + 1].position_m.to_numpy())
    assert not np.array_equal(one.position_m.to_numpy(), clean[clean.run == k + 1].position_m.to_numpy())


def test_run_contact_factors_have_the_declared_scatter():
    # reference: closed form: 1 + s z, z standard normal (mean 1, std s), the same draws for any s,
    # preload and friction drawn independently
    f = run_contact_factors(RigPlan(run_scatter=0.02, seed=9), 20000)
    assert f.shape == (20000, 2) and abs(np.corrcoef(f.T)[0, 1]) < 4 / np.sqrt(20000)
    assert abs(f.mean() - 1) < 4 * 0.02 / np.sqrt(20000) and abs(f.std() / 0.02 - 1) < 4 / np.sqrt(40000)
    g = run_contact_factors(RigPlan(run_scatter=0.04, seed=9), 20000)
    np.testing.assert_allclose(g - 1, 2 * (f - 1), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(run_contact_factors(RigPlan(seed=9), 5), np.ones((5, 2)))


@pytest.mark.parametrize("field,value", [("speed_noise_m_s", -1e-3), ("run_scatter", float("nan")),
                                         ("run_scatter", 0.3)])
def test_rig_plan_refuses_bad_noise_settings(field, value):
    with pytest.raises(SimulationError, match=f"RigPlan.{field}"):
        RigPlan(**{field: value})


def test_rig_cli_refuses_a_negative_speed_noise_with_one_line(capsys, tmp_path):
    code = cli_main(["rig", "--out", str(tmp_path / "r"), "--speed-noise", "-0.001", "--quiet"])
    err = capsys.readouterr().err
    assert code != 0 and "speed_noise_m_s" in err and err.count("\n") == 1
    assert not (tmp_path / "r").exists()


def test_rig_cli_sample_rate_records_every_step_of_the_same_traverse(tmp_path, capsys):
    # reference: stated behaviour: at a step h, the DAQ samples every 1/(rate h)-th step of the same simulation, so the
    # 1 kHz file is every 2nd row of the 2 kHz one (time, position); a step that does not divide the period is refused
    def rig(rate, step, name):
        return cli_main(["rig", "--out", str(tmp_path / name), "--engine", "inprocess", "--voltages", "324",
                         "--loads", "0", "--step", str(step), "--sample-rate", str(rate), "--quiet", "--workers", "1",
                         "--no-plots"])
    assert rig(1000, 5e-4, "r1") == 0 and rig(2000, 5e-4, "r2") == 0
    slow, fast = (pd.read_csv(tmp_path / n / "all.csv") for n in ("r1", "r2"))
    for run, g in slow.groupby("run"):
        f = fast[fast.run == run]
        assert abs(np.median(np.diff(f.time_s)) - 5e-4) < 1e-9 and abs(np.median(np.diff(g.time_s)) - 1e-3) < 1e-9
        n = len(g)
        np.testing.assert_array_equal(f.time_s.to_numpy()[::2][:n], g.time_s.to_numpy())
        np.testing.assert_array_equal(f.position_m.to_numpy()[::2][:n], g.position_m.to_numpy())
        assert len(f) in (2 * n - 1, 2 * n)
    capsys.readouterr()
    assert rig(3000, 1e-3, "r3") != 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sampling period" in err and not (tmp_path / "r3").exists()


@pytest.mark.parametrize("n,limit", [(0, 5), (7, 20), (20, 20), (21, 20), (100_000, 20_000), (124_999, 20_000)])
def test_display_rows_are_evenly_spaced_and_bounded(n, limit):
    # reference: stated behaviour: at most `limit` rows, the first one, one stride ceil(n / limit), reaching the last
    rows = plots.display_rows(n, limit)
    assert len(rows) <= limit and len(rows) == min(n, len(rows))
    if n:
        step = -(-n // limit)
        assert rows[0] == 0 and np.all(np.diff(rows) == step) and rows[-1] >= n - step
        assert len(rows) == n if n <= limit else len(rows) > limit // 2


@pytest.mark.parametrize("rate", [0.0, -1000.0, float("nan"), float("inf")])
def test_a_sampling_rate_that_is_not_a_positive_number_is_refused(rate):
    # reference: stated behaviour: RigPlan refuses it when built, naming the field
    with pytest.raises(SimulationError, match="sample_rate_Hz"):
        RigPlan(sample_rate_Hz=rate)


def test_rig_cli_runs_the_traverses_on_two_local_workers_by_default(tmp_path, monkeypatch):
    # reference: the virtual-rig how-to's words: `--workers N` local single-thread processes, default 2 (the pages'
    # quick commands pass --workers 1, so this is the default's check); --workers 1 reaches the rig as 1
    import l1b2.rig.experiment as rig_experiment

    class Stop(Exception):
        pass
    seen = []

    def fake_run_experiment(plan, mp=None, **kw):
        seen.append(kw)
        raise Stop

    monkeypatch.setattr(rig_experiment, "run_experiment", fake_run_experiment)
    for extra in ([], ["--workers", "1"]):   # the command stops at the rig (an internal error, exit code 1)
        assert cli_main(["rig", "--out", str(tmp_path / f"r{len(seen)}"), "--engine", "inprocess", "--quiet",
                         *extra]) != 0
    assert [(kw["workers"], kw["scheduler"]) for kw in seen] == [(2, None), (1, None)]
