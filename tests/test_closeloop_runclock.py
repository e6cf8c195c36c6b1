"""The run's own clock as a channel: the time since each run's first sample, offered along the stroke only.

Fast tests against the definition written out (``t - t_0(run)``) and against the rule that the run clock has no
run-level form, no run-level signal and no FMU input for its run mean, while a logged channel with the very same
values keeps all of those (so each assertion could fail)."""

import numpy as np
import pandas as pd
import pytest

DT = 0.1   # the clock's sample interval [s]


def _session(starts, lengths, run0=1):
    """Runs of ``lengths[k]`` samples DT apart starting at ``starts[k]`` [s]; V0, load and direction vary by run."""
    rows = []
    for k, (t0, n) in enumerate(zip(starts, lengths)):
        for i in range(n):
            rows.append({"time_s": t0 + DT * i, "run": run0 + k, "position_m": 0.001 * i,
                         "voltage_V": 200.0 + 20.0 * k, "direction": 1 if k % 2 == 0 else -1,
                         "load_kg": 0.01 * (k % 3), "speed_m_s": 0.1})
    return pd.DataFrame(rows)


def test_the_column_is_each_samples_time_since_its_runs_first_sample():
    from l1b2.closeloop.runclock import COLUMN, with_run_clock
    train = _session([0.0, 5.0, 12.3], [4, 6, 3])
    test = _session([2.0, 20.0], [5, 2], run0=11)
    test = test.iloc[::-1].reset_index(drop=True)          # rows out of time order: the run's first sample is its
    tr, te, rec = with_run_clock(train, test)              # earliest, not its first row
    assert rec["derived"] and COLUMN == "time_in_run_s"
    # written out: sample i of a run is i DT after the run's start
    want_tr = np.concatenate([DT * np.arange(n) for n in (4, 6, 3)])
    np.testing.assert_allclose(tr[COLUMN].to_numpy(), want_tr, atol=1e-12)
    want_te = np.concatenate([DT * np.arange(n) for n in (5, 2)])[::-1]
    np.testing.assert_allclose(te[COLUMN].to_numpy(), want_te, atol=1e-12)
    assert COLUMN not in train.columns and COLUMN not in test.columns   # copies, the inputs untouched
    assert rec["duration_s"] == pytest.approx({"min": 2 * DT, "median": 3 * DT, "max": 5 * DT})


def test_runs_of_one_sample_give_no_column_and_a_present_column_is_kept():
    from l1b2.closeloop.runclock import COLUMN, with_run_clock
    train = _session([0.0, 1.0, 2.0], [1, 1, 1])
    tr, te, rec = with_run_clock(train, None)
    assert tr is train and te is None and not rec["derived"]
    two = _session([0.0, 1.0], [3, 3])
    two[COLUMN] = 7.0
    tr, _, rec = with_run_clock(two, None)
    assert tr is two and not rec["derived"] and (tr[COLUMN] == 7.0).all()


def _channels(df):
    from l1b2.closeloop.candidates import channels_of
    return {c["name"]: c for c in channels_of(df)}


def _with_clock_and_twin():
    """A TRAIN frame with the run clock and ``twin_s``, a logged channel holding the very same values."""
    from l1b2.closeloop.runclock import COLUMN, with_run_clock
    tr, _, _ = with_run_clock(_session([0.0, 5.0, 12.3, 20.0, 31.0, 40.0], [4, 6, 3, 5, 4, 6]), None)
    tr["twin_s"] = tr[COLUMN]
    return tr, COLUMN


def _summary(df):
    """A TRAIN summary with the frame's channel records (slider 0.04 kg, largest load 0.02 kg)."""
    from l1b2.predictor import effects as fx
    return fx.TrainingSummary(0.04, (0.0, 41.0), (0.0, 0.006), 250.0, {"load_abs": 0.02},
                              channels=tuple(_channels(df).values()))


def test_the_run_clock_is_offered_at_the_sample_level_only():
    from l1b2.predictor import effects as fx
    tr, col = _with_clock_and_twin()
    chans = _channels(tr)
    assert chans[col]["kind"] == "run_clock" and chans[col]["within_run"]
    # the same values logged: its run means follow the runs' lengths (candidates.run_length_share), so it is
    # offered per sample only by its values; the run clock is by its kind, whatever its record says
    assert chans["twin_s"]["kind"] == "logged" and chans["twin_s"]["run_length"]
    assert set(fx.channels.levels_of({**chans["twin_s"], "run_length": False})) == {"sample", "run"}
    assert fx.channels.levels_of({**chans[col], "run_length": False}) == ("sample",)
    hyps = fx.family("channel").grid(_summary(tr))
    mine = [h for h in hyps if h.spec["channel"] == col]
    twin = [h for h in hyps if h.spec["channel"] == "twin_s"]
    assert mine and {h.spec["level"] for h in mine} == {"sample"}
    assert {h.spec["level"] for h in twin} == {"sample"}
    # the sample-level forms are all the logged channel's: every form, shape and the load interaction; the form
    # that grows with V0 (force_factor) among them
    assert ({(h.spec["form"], h.spec.get("shape", "linear"), h.spec.get("by", "")) for h in mine}
            == {(h.spec["form"], h.spec.get("shape", "linear"), h.spec.get("by", "")) for h in twin
                if h.spec["level"] == "sample"})
    assert any(h.spec["form"] == "force_factor" for h in mine)
    assert all(h.family == f"channel_{col}" for h in mine)
    # no run-level hypothesis of the run-level family either
    runs = {h.spec["channel"] for h in fx.family("run_level").grid(_summary(tr))}
    assert "twin_s" not in runs and col not in runs and "time_s" in runs


def test_the_run_clock_has_no_run_level_signal():
    from l1b2.closeloop.runlevel import run_signals
    tr, col = _with_clock_and_twin()
    chans = tuple(_channels(tr).values())
    names = {sg["channel"] for sg in run_signals(tr, chans)}
    assert "twin_s" not in names and col not in names                    # the twin by its values (run_length)
    assert "voltage_V" in names                                          # the inputs' signals are still there
    unflagged = tuple({**ch, "run_length": False} for ch in chans)
    names = {sg["channel"] for sg in run_signals(tr, unflagged)}
    assert "twin_s" in names and col not in names                        # the run clock by its kind


def test_the_levels_rule():
    from l1b2.predictor.effects.channels import LEVELS, levels_of
    assert levels_of({"kind": "run_clock", "within_run": True}) == ("sample",)
    assert levels_of({"kind": "logged", "within_run": True}) == LEVELS
    assert levels_of({"kind": "logged", "within_run": False}) == ("run",)


def test_the_fmu_reads_the_run_clock_as_an_input_along_the_run_and_refuses_its_run_mean():
    from l1b2.closeloop.runclock import COLUMN
    from l1b2.predictor.effects.channels import channel_inputs, export_problem, fmu_signal
    assert fmu_signal("col:" + COLUMN) == "col:" + COLUMN
    assert fmu_signal("run:" + COLUMN) is None
    assert fmu_signal("run:twin_s") == "col:twin_s"                       # a logged channel's run mean has one
    spec = {"kind": "channel", "channel": COLUMN, "form": "force_factor", "level": "sample", "mean": 1.5, "sd": 0.8}
    assert export_problem(spec) is None
    assert channel_inputs([spec]) == {COLUMN: pytest.approx(1.5)}
    assert export_problem({**spec, "level": "run", "run_spread": 0.0}) == "no input: run:" + COLUMN


def test_the_fmu_block_declares_the_run_clock_as_an_input_in_seconds():
    from test_predictor_fmu_channels import _effect, _setups
    from l1b2.cosim.composite import PredictorBlock
    from l1b2.predictor.effects import ExtendedPredictor
    from l1b2.predictor import effects as fx
    tr, col = _with_clock_and_twin()
    h = next(h for h in fx.family("channel").grid(_summary(tr)) if h.spec["channel"] == col
             and h.spec["form"] == "force_factor" and h.spec.get("shape", "linear") == "linear"
             and not h.spec.get("by"))
    base, refit = _setups()
    ep = ExtendedPredictor(base, refit, (_effect(h, (0.05,)),), None, {"train": "train.csv"})
    assert ep.channel_inputs == pytest.approx({col: h.spec["mean"]})
    ins = {v.name: v for v in PredictorBlock.variables(ep) if v.causality == "input"}
    assert col in ins and ins[col].unit == "s"


def test_a_logged_column_named_like_the_run_clock_is_set_aside():
    from l1b2.closeloop.derived import is_derivable_name, set_aside_derivable_names
    from l1b2.closeloop.runclock import COLUMN, with_run_clock
    assert is_derivable_name(COLUMN, ["time_s"]) and not is_derivable_name("time_in_runs", ["time_s"])
    train = _session([0.0, 5.0], [3, 3])
    train[COLUMN] = 9.0                                                  # a logger's own column of that name
    tr, _, record = set_aside_derivable_names(train, None)
    assert COLUMN + "_logged" in tr.columns and COLUMN not in tr.columns
    assert record[0]["from"] == COLUMN
    tr, _, rec = with_run_clock(tr, None)
    assert rec["derived"] and (tr[COLUMN + "_logged"] == 9.0).all()
    np.testing.assert_allclose(tr[COLUMN].to_numpy(), np.tile(DT * np.arange(3), 2), atol=1e-12)


def test_the_reports_run_clock_record_survives_a_round_trip_and_an_older_report_loads():
    from l1b2.closeloop.report import Diagnosis
    from l1b2.closeloop.runclock import with_run_clock
    _, _, rec = with_run_clock(_session([0.0, 5.0], [3, 4]), None)
    old = {"significant": False, "traced_to": [], "effect": None, "effect_shape": None,
           "effect_description": None, "effects": [], "message": "no significant missing effect"}
    assert Diagnosis.from_dict(old).run_clock == {}
    d = Diagnosis.from_dict({**old, "run_clock": rec})
    assert d.to_dict()["run_clock"] == rec and Diagnosis.from_dict(d.to_dict()) == d


# --- the run's own travel ------------------------------------------------------------------------------------------

def _strokes(lengths, speeds, run0=1):
    """Runs of ``lengths[k]`` samples DT apart, alternately from -20 mm forward and from +20 mm backward at
    ``speeds[k]`` [m/s]."""
    rows, t0 = [], 0.0
    for k, (n, v) in enumerate(zip(lengths, speeds)):
        d = 1 if k % 2 == 0 else -1
        for i in range(n):
            rows.append({"time_s": t0 + DT * i, "run": run0 + k, "position_m": -d * 0.02 + d * v * DT * i,
                         "voltage_V": 200.0 + 20.0 * k, "direction": d, "load_kg": 0.01 * (k % 3),
                         "speed_m_s": d * v})
        t0 += DT * n + 1.0
    return pd.DataFrame(rows)


def test_the_travel_is_the_way_gone_in_the_runs_direction_since_its_first_sample():
    from l1b2.closeloop.runclock import TRAVEL_COLUMN, with_run_travel
    train = _strokes([4, 6, 3], [0.01, 0.02, 0.005])
    test = _strokes([5, 2], [0.03, 0.01], run0=11)
    test = test.iloc[::-1].reset_index(drop=True)          # rows out of time order: the run's first sample is its
    tr, te, rec = with_run_travel(train, test)             # earliest, not its first row
    assert rec["derived"] and TRAVEL_COLUMN == "travel_in_run_m"
    # written out: sample i of a run at speed v has gone v i DT in its own direction, whichever way that is
    want_tr = np.concatenate([v * DT * np.arange(n) for n, v in zip((4, 6, 3), (0.01, 0.02, 0.005))])
    np.testing.assert_allclose(tr[TRAVEL_COLUMN].to_numpy(), want_tr, atol=1e-12)
    want_te = np.concatenate([v * DT * np.arange(n) for n, v in zip((5, 2), (0.03, 0.01))])[::-1]
    np.testing.assert_allclose(te[TRAVEL_COLUMN].to_numpy(), want_te, atol=1e-12)
    assert TRAVEL_COLUMN not in train.columns and TRAVEL_COLUMN not in test.columns
    assert rec["span_m"] == pytest.approx({"min": 0.005 * 2 * DT, "median": 0.01 * 3 * DT, "max": 0.02 * 5 * DT})
    # the loop's derivations append it beside the run clock and name it derived (no logarithm, lag or run signal)
    from l1b2.closeloop.auxiliary import derived_columns
    from l1b2.closeloop.derived import with_protocol_channels
    from l1b2.closeloop.events import session
    tr2, _, recs = with_protocol_channels(train, None, (), session(train, None))
    assert recs["run_travel"]["derived"] and recs["run_clock"]["derived"]
    np.testing.assert_allclose(tr2[TRAVEL_COLUMN].to_numpy(), want_tr, atol=1e-12)
    assert {TRAVEL_COLUMN, "time_in_run_s"} <= set(derived_columns(tr2))


def test_runs_that_do_not_move_give_no_travel_and_a_present_column_is_kept():
    from l1b2.closeloop.runclock import TRAVEL_COLUMN, with_run_travel
    still = _strokes([3, 3], [0.0, 0.0])
    tr, te, rec = with_run_travel(still, None)
    assert tr is still and te is None and not rec["derived"]
    moving = _strokes([3, 3], [0.01, 0.01])
    moving[TRAVEL_COLUMN] = 7.0
    tr, _, rec = with_run_travel(moving, None)
    assert tr is moving and not rec["derived"] and (tr[TRAVEL_COLUMN] == 7.0).all()


def test_the_travel_is_offered_at_the_sample_level_only_and_has_no_run_level_signal():
    from l1b2.closeloop.runclock import TRAVEL_COLUMN, with_run_travel
    from l1b2.closeloop.runlevel import run_signals
    from l1b2.predictor import effects as fx
    tr, _, _ = with_run_travel(_strokes([4, 6, 3, 5, 4, 6], [0.01, 0.02, 0.005, 0.03, 0.015, 0.02]), None)
    tr["twin_m"] = tr[TRAVEL_COLUMN] + 0.001 * tr["run"]        # a logged channel like it, its run means apart
    chans = _channels(tr)
    assert chans[TRAVEL_COLUMN]["kind"] == "run_travel" and chans["twin_m"]["kind"] == "logged"
    assert fx.channels.levels_of({**chans[TRAVEL_COLUMN], "run_length": False}) == ("sample",)
    assert set(fx.channels.levels_of({**chans["twin_m"], "run_length": False})) == {"sample", "run"}
    mine = [h for h in fx.family("channel").grid(_summary(tr)) if h.spec["channel"] == TRAVEL_COLUMN]
    assert mine and {h.spec["level"] for h in mine} == {"sample"}
    assert {"damping", "force_factor"} <= {h.spec["form"] for h in mine}
    assert TRAVEL_COLUMN not in {h.spec["channel"] for h in fx.family("run_level").grid(_summary(tr))}
    unflagged = tuple({**ch, "run_length": False} for ch in chans.values())
    names = {sg["channel"] for sg in run_signals(tr, unflagged)}
    assert "twin_m" in names and TRAVEL_COLUMN not in names


def test_the_fmu_reads_the_travel_as_an_input_in_metres_along_the_run_and_refuses_its_run_mean():
    from test_predictor_fmu_channels import _effect, _setups
    from l1b2.closeloop.runclock import TRAVEL_COLUMN, with_run_travel
    from l1b2.cosim.composite import PredictorBlock
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import ExtendedPredictor
    from l1b2.predictor.effects.channels import export_problem, fmu_signal
    assert fmu_signal("col:" + TRAVEL_COLUMN) == "col:" + TRAVEL_COLUMN and fmu_signal("run:" + TRAVEL_COLUMN) is None
    spec = {"kind": "channel", "channel": TRAVEL_COLUMN, "form": "damping", "level": "run", "mean": 0.01,
            "sd": 0.005, "run_spread": 0.0}
    assert export_problem(spec) == "no input: run:" + TRAVEL_COLUMN
    tr, _, _ = with_run_travel(_strokes([4, 6, 3, 5, 4, 6], [0.01, 0.02, 0.005, 0.03, 0.015, 0.02]), None)
    h = next(h for h in fx.family("channel").grid(_summary(tr)) if h.spec["channel"] == TRAVEL_COLUMN
             and h.spec["form"] == "damping" and h.spec.get("shape", "linear") == "linear" and not h.spec.get("by"))
    base, refit = _setups()
    ep = ExtendedPredictor(base, refit, (_effect(h, (0.05,)),), None, {"train": "train.csv"})
    ins = {v.name: v for v in PredictorBlock.variables(ep) if v.causality == "input"}
    assert TRAVEL_COLUMN in ins and ins[TRAVEL_COLUMN].unit == "m"


def test_a_logged_column_named_like_the_travel_is_set_aside_and_the_record_round_trips():
    from l1b2.closeloop.derived import is_derivable_name, set_aside_derivable_names
    from l1b2.closeloop.report import Diagnosis
    from l1b2.closeloop.runclock import TRAVEL_COLUMN, with_run_travel
    assert is_derivable_name(TRAVEL_COLUMN, ["time_s"]) and not is_derivable_name("travel_m", ["time_s"])
    train = _strokes([3, 3], [0.01, 0.02])
    train[TRAVEL_COLUMN] = 9.0
    tr, _, record = set_aside_derivable_names(train, None)
    assert TRAVEL_COLUMN + "_logged" in tr.columns and record[0]["from"] == TRAVEL_COLUMN
    tr, _, rec = with_run_travel(tr, None)
    assert rec["derived"] and (tr[TRAVEL_COLUMN + "_logged"] == 9.0).all()
    old = {"significant": False, "traced_to": [], "effect": None, "effect_shape": None,
           "effect_description": None, "effects": [], "message": "no significant missing effect"}
    assert Diagnosis.from_dict(old).run_travel == {}
    d = Diagnosis.from_dict({**old, "run_travel": rec})
    assert d.to_dict()["run_travel"] == rec and Diagnosis.from_dict(d.to_dict()) == d
