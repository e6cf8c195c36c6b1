"""Auxiliary columns that are not numeric and finite as logged (issue 28, item 2: every column is a candidate or
listed with its reason): flags read as 0/1, text labels coded, gaps interpolated within their run, the rest listed.

Fast unit tests against values written out here.
"""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import auxiliary as aux
from l1b2.closeloop import runlevel as rl
from l1b2.closeloop.candidates import channels_of
from l1b2.closeloop.evidence import with_auxiliary
from l1b2.data.gaps import fill_gaps
from l1b2.predictor import effects as fx


def frame(n_runs=6, n=5, **extra):
    """``n_runs`` runs of ``n`` samples on one clock (1 ms step, 1 s apart), with the extra columns given as
    functions of ``(run, k)`` (k the sample in the run)."""
    rows = []
    for r in range(n_runs):
        for k in range(n):
            row = {"time_s": r + 0.001 * k, "run": r + 1, "position_m": -0.02 + 0.001 * k, "voltage_V": 300.0,
                   "direction": 1, "load_kg": 0.0, "speed_m_s": 0.1}
            row.update({c: f(r, k) for c, f in extra.items()})
            rows.append(row)
    return pd.DataFrame(rows)


def test_gaps_are_interpolated_in_time_within_their_run_and_held_at_its_ends():
    t = np.array([0.0, 1.0, 2.0, 4.0, 10.0, 11.0, 12.0, 20.0, 21.0])
    run = np.array([1, 1, 1, 1, 2, 2, 2, 3, 3])
    v = np.array([np.nan, 2.0, np.nan, 8.0, 5.0, np.inf, 7.0, np.nan, np.nan])
    out, empty = fill_gaps(v, t, run)
    # run 1: held at 2 before its first reading; at t=2, 2 + (8 - 2) (2 - 1)/(4 - 1) = 4
    # run 2: inf is a gap: 5 + (7 - 5) (11 - 10)/(12 - 10) = 6; run 3 has no reading: left non-finite
    np.testing.assert_allclose(out[:7], [2.0, 2.0, 4.0, 8.0, 5.0, 6.0, 7.0])
    assert np.all(np.isnan(out[7:])) and empty == [3]
    assert np.isinf(v[5])   # the input is not changed


def test_labels_are_coded_in_sorted_order_and_an_unseen_label_reads_as_no_level():
    codes, unseen = aux.label_codes(pd.Series(["b", "a", "a", "b", "b"]))
    assert codes == {"a": 0.0, "b": 1.0} and unseen == pytest.approx(3 / 5)   # two: the runs' average code
    codes, unseen = aux.label_codes(pd.Series(["jig-C", "jig-A", "jig-B", "jig-A"]))
    assert codes == {"jig-A": 0.0, "jig-B": 1.0, "jig-C": 2.0} and unseen == -1.0


def test_flags_labels_and_gaps_become_numeric_channels_and_the_rest_is_listed():
    tr = frame(flag=lambda r, k: r % 2 == 0, operator=lambda r, k: "anna" if r < 3 else "ben",
               fixture=lambda r, k: "ABC"[r % 3], note=lambda r, k: f"sample {k}",
               humidity=lambda r, k: np.nan if k % 2 else 40.0 + r, empty=lambda r, k: np.nan,
               ok=lambda r, k: 1.0 + r)
    te = frame(n_runs=2, flag=lambda r, k: True, operator=lambda r, k: "carl", fixture=lambda r, k: "ABCD"[r + 2],
               note=lambda r, k: "x", humidity=lambda r, k: np.nan, empty=lambda r, k: 1.0, ok=lambda r, k: 2.0)
    tr2, te2, rec = aux.with_usable_channels(tr, te)
    by = {r["channel"]: r for r in rec}
    assert set(by) == {"flag", "operator", "fixture", "note", "humidity", "empty"}     # "ok" needs nothing
    assert by["flag"]["action"] == "flag"
    np.testing.assert_array_equal(tr2["flag"], np.repeat([1.0, 0.0] * 3, 5))
    assert by["operator"]["kind"] == "logged" and by["operator"]["codes"] == {"anna": 0.0, "ben": 1.0}
    np.testing.assert_array_equal(te2["operator"], np.full(10, 0.5))   # unseen in TRAIN: the runs' average
    assert by["fixture"]["kind"] == "label"
    np.testing.assert_array_equal(tr2["fixture"], np.repeat([0.0, 1.0, 2.0] * 2, 5))
    np.testing.assert_array_equal(te2["fixture"], np.repeat([2.0, -1.0], 5))   # C, then D unseen
    assert by["note"]["action"] == "unusable" and "note" not in tr2.columns and "note" not in te2.columns
    assert by["empty"]["action"] == "unusable" and "empty" not in tr2.columns
    # even samples read 40 + r; odd ones between two readings 2 ms apart: their mean; the last held
    np.testing.assert_allclose(tr2["humidity"], np.repeat(40.0 + np.arange(6), 5))
    assert by["humidity"]["filled_samples"] == 12 and by["humidity"]["first_row"] == 2   # 1-based data row
    np.testing.assert_allclose(te2["humidity"], np.mean(40.0 + np.arange(6)))   # no TEST reading: TRAIN's mean
    assert aux.label_columns(tr2) == ("fixture",) and aux.label_columns(te2) == ("fixture",)
    assert tr["humidity"].isna().sum() == 12 and tr["flag"].dtype == bool   # the caller's frames are not changed


def test_frames_that_need_nothing_are_returned_as_they_are():
    tr, te = frame(ok=lambda r, k: 1.0 + r), frame(ok=lambda r, k: 2.0)
    out = aux.with_usable_channels(tr, te)
    assert out[0] is tr and out[1] is te and out[2] == []


def test_a_finite_train_column_with_gaps_in_test_is_filled_in_test():
    tr = frame(ok=lambda r, k: 1.0 + r + k)
    te = frame(n_runs=1, ok=lambda r, k: np.nan if k == 2 else 10.0 + k)
    tr2, te2, rec = aux.with_usable_channels(tr, te)
    np.testing.assert_array_equal(tr2["ok"], tr["ok"])
    np.testing.assert_allclose(te2["ok"], [10.0, 11.0, 12.0, 13.0, 14.0])
    assert rec[0]["action"] == "filled" and rec[0]["filled_samples"] == 0


def test_a_label_is_a_category_only_its_unordered_codes_get_no_value_form():
    tr = frame(n_runs=9, fixture=lambda r, k: "ABC"[r % 3], flag=lambda r, k: "yes" if r % 2 else "no")
    tr2, _, _ = aux.with_usable_channels(tr)
    chans = {c["name"]: c for c in channels_of(tr2)}
    assert chans["fixture"]["kind"] == "label" and chans["flag"]["kind"] == "logged"
    fam = fx.family("run_level_category")
    assert fam.takes(chans["fixture"])
    signals = rl.run_signals(tr2, list(chans.values()))
    kinds = {(s["channel"], s["transform"]) for s in signals}
    assert ("fixture", fx.category.CATEGORY) in kinds and ("fixture", "none") not in kinds
    assert ("flag", "none") in kinds
    train = types_summary(list(chans.values()))
    for name in ("channel", "run_level"):
        specs = [h.spec for h in fx.family(name).grid(train)]
        assert not any(sp.get("channel") == "fixture" for sp in specs)
        assert any(sp.get("channel") == "flag" for sp in specs)


def types_summary(channels):
    """The least of a training summary the channel families' grids read."""
    import types
    return types.SimpleNamespace(channels=tuple(channels), time_range=(0.0, 9.0), ranges={"load_abs": 0.0},
                                 damping_N_s_per_m=None, m_s=0.12)


def test_the_evidence_table_carries_every_column_with_what_was_done():
    rows = [{"channel": "humidity", "kind": "logged", "note": ""}, {"channel": "ok", "kind": "logged", "note": ""}]
    rec = [{"channel": "humidity", "action": "filled", "note": "3 gaps"},
           {"channel": "note", "action": "unusable", "note": "text that varies within a run"}]
    out = with_auxiliary(rows, rec)
    assert [r["channel"] for r in out] == ["humidity", "ok", "note"]
    assert out[0]["prepared"] == "filled" and out[0]["note"] == "3 gaps"
    assert out[2]["kind"] == "unusable" and out[2]["note"] == "text that varies within a run"
    assert not out[2]["significant"] and not out[2]["added"]


def test_a_test_file_without_a_channel_train_logs_is_refused_before_any_fit(tmp_path):
    from pathlib import Path

    from l1b2.data.measurements import Measurements
    from l1b2.errors import DataFormatError
    tr = Measurements(frame(pressure_bar=lambda r, k: 2.0 + r, tip_velocity_amp_m_s=lambda r, k: 0.3,
                            note=lambda r, k: "x"), {}, Path("train.csv"))
    te = Measurements(frame(n_runs=2), {}, Path("test.csv"))
    with pytest.raises(DataFormatError, match=r"test\.csv: column 'pressure_bar'.*and 1 more: note.*train\.csv"):
        aux.check_test_columns(tr, te, ("tip_velocity_amp_m_s",))
    te2 = Measurements(frame(n_runs=2, pressure_bar=lambda r, k: 2.0, note=lambda r, k: "y"), {}, Path("test.csv"))
    aux.check_test_columns(tr, te2, ("tip_velocity_amp_m_s",))   # a measured response may be absent


def test_the_columns_never_candidates_and_the_within_run_test():
    # reference: the data format's required columns plus the measured speed; a column varies within runs when
    # some run holds two values (a step between runs is not)
    from l1b2.closeloop.auxiliary import NOT_CANDIDATES, varies_within_runs
    assert NOT_CANDIDATES == {"time_s", "run", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s"}
    df = pd.DataFrame({"run": [1, 1, 2, 2], "step": [0.0, 0.0, 1.0, 1.0], "ramp": [0.0, 0.0, 1.0, 1.5]})
    assert not varies_within_runs(df, "step") and varies_within_runs(df, "ramp")
