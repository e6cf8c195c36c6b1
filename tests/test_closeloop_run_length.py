"""A logged channel whose run means follow the runs' lengths (a reading that accumulates over each run) is offered at
the sample level only: its share written out, the flag, its levels and no run-level signal."""

import numpy as np
import pytest
from test_closeloop_along_stroke import _runs


def _t_run(df):
    t = df["time_s"].to_numpy()
    return t - df.groupby("run")["time_s"].transform("min").to_numpy()


def test_the_share_is_the_runs_slopes_times_their_mean_times_written_out():
    from l1b2.closeloop.candidates import run_length_share
    df = _runs()                                   # 8 runs of 0.21-0.80 s
    t_run, run = _t_run(df), df["run"].to_numpy()
    power = 2.0 + 0.1 * df["level"]                # an energy meter reset at each run's start [J]
    df = df.assign(meter_J=power * t_run + 0.01 * df["noise"],
                   heated_C=25.0 + df["level"] + 0.2 * t_run + 0.05 * df["noise"])
    for name in ("meter_J", "heated_C"):
        slopes, tbars, means = [], [], []
        for r in np.unique(run):
            k = run == r
            slopes.append(np.polyfit(t_run[k], df[name].to_numpy()[k], 1)[0])
            tbars.append(t_run[k].mean())
            means.append(df[name].to_numpy()[k].mean())
        delta = np.array(slopes) * (np.array(tbars) - min(tbars))
        want = np.sum((delta - delta.mean()) ** 2) / np.sum((np.array(means) - np.mean(means)) ** 2)
        assert run_length_share(df, name) == pytest.approx(min(want, 1.0), rel=1e-9), name
    assert run_length_share(df, "meter_J") > 0.9   # half of each run's length times its rate
    assert run_length_share(df, "heated_C") < 0.05  # a drift within runs small beside the levels between runs
    assert run_length_share(df, "level") < 1e-20   # constant within every run
    assert np.isnan(run_length_share(df.assign(flat=1.0), "flat"))


def test_an_accumulating_channel_is_flagged_offered_at_the_sample_level_and_has_no_run_signal():
    from l1b2.closeloop.candidates import RUN_LENGTH_SHARE, channels_of, run_length_share
    from l1b2.closeloop.runlevel import run_signals
    from l1b2.predictor.effects.channels import levels_of
    df = _runs()
    t_run = _t_run(df)
    df = df.assign(meter_J=(2.0 + 0.1 * df["level"]) * t_run + 0.01 * df["noise"],
                   temp_C=25.0 + df["level"] + 0.2 * t_run + 0.05 * df["noise"])
    ch = {c["name"]: c for c in channels_of(df)}
    assert ch["meter_J"]["run_length"] and levels_of(ch["meter_J"]) == ("sample",)
    assert not ch["temp_C"]["run_length"] and set(levels_of(ch["temp_C"])) == {"sample", "run"}
    assert not ch["level"]["run_length"] and levels_of(ch["level"]) == ("run",)
    names = {sg["channel"] for sg in run_signals(df, channels_of(df))}
    assert "temp_C" in names and "level" in names and "meter_J" not in names
    # at the edge: a meter whose rate's spread between runs carries as much as the runs' lengths is kept
    mixed = df.assign(meter_J=(0.2 + 3.0 * df["level"]) * t_run)
    share = run_length_share(mixed, "meter_J")
    assert share < RUN_LENGTH_SHARE and not {c["name"]: c for c in channels_of(mixed)}["meter_J"]["run_length"]


def test_the_channels_record_says_why_it_has_no_run_level_form():
    from l1b2.closeloop.evidence import channels_considered
    chans = ({"name": "meter_J", "kind": "logged", "within_run": True, "sd": 1.0, "run_length": True},
             {"name": "hall_mT", "kind": "logged", "within_run": True, "sd": 1.0, "along_stroke": True},
             {"name": "temp_C", "kind": "logged", "within_run": True, "sd": 1.0})
    rows = {r["channel"]: r for r in channels_considered(chans, [], 1e-3, 0.05, set(), None, [])}
    assert rows["meter_J"]["per_sample_only"] == "its run means follow the runs' lengths"
    assert rows["hall_mT"]["per_sample_only"] == "read along the stroke"
    assert rows["temp_C"]["per_sample_only"] is None
