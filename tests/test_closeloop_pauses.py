"""The pause before each run as a channel: the logarithm of the session clock's gap before each run. Fast tests
against the definition written out."""

import math

import numpy as np
import pandas as pd
import pytest

DT = 0.1   # the clock's sample interval [s]


def _session(starts, n=4, run0=1):
    """Runs of ``n`` samples DT apart starting at ``starts`` [s]: each run lasts (n - 1) DT."""
    rows = []
    for k, t0 in enumerate(starts):
        for i in range(n):
            rows.append({"time_s": t0 + DT * i, "run": run0 + k, "position_m": 0.0, "voltage_V": 200.0,
                         "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1})
    return pd.DataFrame(rows)


def _per_run(df, column):
    return df.groupby("run", sort=False)[column].agg(["min", "max"])


def test_the_column_is_the_log_of_each_runs_pause_and_test_continues_the_session():
    from l1b2.closeloop.pauses import COLUMN, with_pause_channel
    starts = [0.0, 1.3, 6.3, 6.65, 26.65, 28.05]         # a run lasts 0.3 s: pauses 1.0, 4.7, 0.05, 19.7, 1.1
    whole = _session(starts)
    train = whole[whole["run"].isin([1, 2, 4, 6])].reset_index(drop=True)
    test = whole[whole["run"].isin([3, 5])].reset_index(drop=True)
    tr, te, rec = with_pause_channel(train, test)
    assert rec["derived"] and rec["one_session"] and rec["imputed_runs"] == 1
    assert rec["floor_s"] == pytest.approx(DT)
    # the pause floored at the sample interval, over 1 s; the session's first run: TRAIN's median of its known ones
    known_train = [math.log(1.0), math.log(DT), math.log(1.1)]          # runs 2, 4 (under one step) and 6
    want = {1: float(np.median(known_train)), 2: math.log(1.0), 3: math.log(4.7), 4: math.log(DT),
            5: math.log(19.7), 6: math.log(1.1)}
    for df in (tr, te):
        got = _per_run(df, COLUMN)
        assert (got["min"] == got["max"]).all()                       # one value per run
        for run, v in got["min"].items():
            assert v == pytest.approx(want[run], abs=1e-9)
    assert COLUMN not in train.columns and COLUMN not in test.columns   # copies, the inputs untouched
    assert rec["pauses_s"]["min"] == pytest.approx(0.05)
    assert rec["pauses_s"]["max"] == pytest.approx(1.1)                 # TRAIN's known pauses


def test_frames_of_their_own_sessions_are_ordered_each_on_its_own():
    from l1b2.closeloop.pauses import COLUMN, with_pause_channel
    train = _session([0.0, 1.3, 6.3, 9.6])                 # pauses 1.0, 4.7, 3.0
    test = _session([0.0, 2.3], run0=11)                   # overlaps TRAIN's clock: its own session, pause 2.0
    tr, te, rec = with_pause_channel(train, test)
    assert rec["derived"] and not rec["one_session"] and rec["imputed_runs"] == 2
    fill = math.log(3.0)                                   # TRAIN's median of ln(1.0), ln(4.7), ln(3.0)
    assert _per_run(tr, COLUMN)["min"].tolist() == pytest.approx([fill, 0.0, math.log(4.7), math.log(3.0)])
    assert _per_run(te, COLUMN)["min"].tolist() == pytest.approx([fill, math.log(2.0)])


def test_regular_pauses_give_no_column():
    from l1b2.closeloop.pauses import MIN_SPAN, pauses_vary, with_pause_channel
    train = _session([0.0, 1.3, 2.6, 3.9000000001, 5.2])   # every pause 1 s (a float's jitter)
    tr, te, rec = with_pause_channel(train, None)
    assert tr is train and te is None and not rec["derived"]
    assert rec["pauses_s"]["max"] == pytest.approx(1.0)
    # the span rule: the longest at least MIN_SPAN times the shortest; a zero pause and a longer one vary
    assert not pauses_vary([1.0, 1.0 * MIN_SPAN * 0.99, np.nan])
    assert pauses_vary([1.0, 1.0 * MIN_SPAN, np.nan])
    assert pauses_vary([0.0, 0.5]) and not pauses_vary([0.0, 0.0]) and not pauses_vary([3.0, np.nan])


def test_the_column_is_a_run_level_candidate_channel():
    from l1b2.closeloop.candidates import channels_of
    from l1b2.closeloop.pauses import COLUMN, with_pause_channel
    tr, _, _ = with_pause_channel(_session([0.0, 1.3, 6.3, 6.6, 26.6, 28.0]), None)
    ch = {c["name"]: c for c in channels_of(tr)}[COLUMN]
    assert ch["kind"] == "logged" and not ch["within_run"]


def test_the_log_pause_is_finite_for_a_zero_pause_and_leaves_a_missing_one_missing():
    from l1b2.closeloop.pauses import REFERENCE_S, log_pause
    got = log_pause([0.0, 2.0, np.nan, -1.0], 0.001)
    assert got[0] == pytest.approx(math.log(0.001 / REFERENCE_S)) and got[1] == pytest.approx(math.log(2.0))
    assert np.isnan(got[2]) and got[3] == pytest.approx(math.log(0.001))


def test_a_run_level_effect_of_the_column_is_exported_through_an_input_named_after_it():
    from l1b2.closeloop.pauses import COLUMN, with_pause_channel
    from l1b2.predictor.effects.channels import channel_inputs, export_problem, fmu_signal, run_spread
    tr, _, _ = with_pause_channel(_session([0.0, 1.3, 6.3, 6.65, 26.65, 28.0]), None)
    spread = run_spread(tr[COLUMN], tr["run"])
    assert spread == 0.0                                   # one value per run: the run-level contract holds exactly
    sd = float(tr[COLUMN].std())
    spec = {"kind": "channel", "channel": COLUMN, "form": "friction", "level": "run", "mean": float(tr[COLUMN].mean()),
            "sd": sd, "run_spread": spread}
    assert fmu_signal("run:" + COLUMN) == "col:" + COLUMN
    assert export_problem(spec) is None
    assert channel_inputs([spec]) == {COLUMN: pytest.approx(spec["mean"])}


def test_the_break_clock_is_the_time_since_the_latest_run_after_a_break():
    from l1b2.closeloop.pauses import BREAK_COLUMN, BREAK_COUNT_COLUMN, BREAK_FACTOR, with_break_clock
    # runs every 1.3 s (median period 1.3 s); two breaks: before run 7 (600 s) and before run 13 (100 s)
    starts = [1.3 * k for k in range(6)]
    starts += [starts[-1] + 600.0 + 1.3 * k for k in range(6)]
    starts += [starts[-1] + 100.0 + 1.3 * k for k in range(6)]
    assert 100.0 >= BREAK_FACTOR * 1.3
    whole = _session(starts)
    train = whole[whole["run"] % 4 != 0].reset_index(drop=True)
    test = whole[whole["run"] % 4 == 0].reset_index(drop=True)
    tr, te, rec = with_break_clock(train, test)
    assert rec["derived"] and rec["one_session"] and rec["breaks_s"] == pytest.approx([starts[6], starts[12]])
    assert rec["count_column"] == BREAK_COUNT_COLUMN
    for df in (tr, te):
        t = df["time_s"].to_numpy()
        origin = np.where(t >= starts[12], starts[12], np.where(t >= starts[6], starts[6], starts[0]))
        assert df[BREAK_COLUMN].to_numpy() == pytest.approx(t - origin)
        # the count: 0 for the first six runs, 1 for the next six (after the first break), 2 for the last six
        assert np.array_equal(df[BREAK_COUNT_COLUMN].to_numpy(), ((df["run"].to_numpy() - 1) // 6).astype(float))
    assert BREAK_COLUMN not in train.columns and BREAK_COUNT_COLUMN not in train.columns
    # TEST holds the first run after each break: its count is the merged session's (TRAIN alone would place the
    # breaks one run late)
    held = whole["run"].isin([7, 13, 16])
    tr, te, rec = with_break_clock(whole[~held].reset_index(drop=True), whole[held].reset_index(drop=True))
    for df in (tr, te):
        assert np.array_equal(df[BREAK_COUNT_COLUMN].to_numpy(), ((df["run"].to_numpy() - 1) // 6).astype(float))


def test_no_break_clock_without_breaks_or_with_too_many():
    from l1b2.closeloop.events import MIN_BLOCK_RUNS
    from l1b2.closeloop.pauses import BREAK_FACTOR, break_starts, with_break_clock
    from l1b2.closeloop.events import run_table
    regular = _session([1.3 * k for k in range(12)])
    tr, _, rec = with_break_clock(regular, None)
    assert tr is regular and not rec["derived"] and rec["breaks_s"] == []
    # a pause just under / at the factor times the median period
    under = _session([0.0, 1.3, 2.6, 2.6 + 1.3 * BREAK_FACTOR * 0.99 + 0.3, 2.6 + 1.3 * BREAK_FACTOR * 0.99 + 1.6])
    at = _session([0.0, 1.3, 2.6, 2.6 + 1.3 * BREAK_FACTOR + 0.3, 2.6 + 1.3 * BREAK_FACTOR + 1.6])
    assert len(break_starts(run_table([under], "time_s"))) == 0
    assert len(break_starts(run_table([at], "time_s"))) == 1
    # breaks more often than once per MIN_BLOCK_RUNS runs: a rig that pauses irregularly, not a session of segments
    starts, t = [], 0.0
    for k in range(12):
        starts.append(t)
        t += 1.3 if k % 2 == 0 else 1.3 + 30.0
    busy = _session(starts)
    assert len(break_starts(run_table([busy], "time_s"))) > 12 / MIN_BLOCK_RUNS
    assert not with_break_clock(busy, None)[2]["derived"]
