"""TEST values of a logged channel outside TRAIN's range (issue 28, item 1): an added effect of the channel
extrapolates there (the linear shape and the run-level family) or is held at the range's end (the quadratic and odd
shapes), and the report says how much of TEST that is.

Fast unit tests on a frame written out here, with the samples and runs outside TRAIN's range counted by hand.
"""

import types

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import ranges
from l1b2.closeloop.report import Diagnosis, channel_range_line
from l1b2.data.coverage import values_outside


def _frame(runs, coil, loads, dirs) -> pd.DataFrame:
    """11 samples per run: ``coil`` gives each run's (first, last) channel value, linear in between."""
    n = 11
    return pd.DataFrame({"run": np.repeat(runs, n),
                         "coil_A": np.concatenate([np.linspace(a, b, n) for a, b in coil]),
                         "load_kg": np.repeat(loads, n), "direction": np.repeat(dirs, n).astype(float)})


# TRAIN: coil_A's samples span [0, 4] (tolerance 2 % of 4 = 0.08), its run means [0.5, 3.5] (tolerance 0.06);
# d * load spans [-0.1, 0.2] (tolerance 0.006)
TRAIN = _frame([1, 2, 3, 4], [(0, 1), (1, 2), (2, 3), (3, 4)], [0.0, 0.1, 0.2, 0.1], [1, -1, 1, -1])
# TEST: run 11 inside everywhere; run 12 has 5 samples above 4.08 (4.1 .. 4.5) and its mean 4.0 above 3.56;
# run 13 lies within the samples' tolerance (-0.05 .. 0.05) but its mean 0.0 is below 0.44, and d * load = -0.15
TEST = _frame([11, 12, 13], [(1, 2), (3.5, 4.5), (-0.05, 0.05)], [0.05, 0.05, 0.15], [1, -1, -1])


def _added(label, **spec):
    return types.SimpleNamespace(label=label, spec=spec)


ADDED = [
    _added("A", kind="channel", channel="coil_A", level="sample", form="force", mean=2.0, sd=1.0),
    _added("B", kind="channel", channel="coil_A", level="sample", form="damping", shape="quadratic", mean=2.0,
           sd=1.0, lo=0.0, hi=4.0),
    _added("C", kind="channel", channel="coil_A", level="run", form="friction", mean=2.0, sd=1.0),
    _added("D", kind="run_level", channel="load_kg", transform="drive", mean=0.0, sd=0.1),
    _added("E", kind="run_level", channel="load_kg", transform="abs", mean=0.1, sd=0.05),
    _added("F", kind="run_level_category", channel="coil_A", n_levels=2, level_0=0.0, level_1=1.0,
           share_0=0.5),
    _added("G", kind="channel", channel="not_in_test", level="sample", form="force", mean=0.0, sd=1.0),
    _added("H", kind="load_path_friction"),
]


def test_values_outside_counts_samples_and_runs_beyond_trains_range_and_its_tolerance():
    train = np.array([0.0, 4.0, 2.0, np.nan])
    test = np.array([4.07, 4.09, -0.5, 1.0, 2.0, np.nan])     # 4.07 within 4 + 0.08; 4.09 and -0.5 outside
    runs = np.array([1, 1, 2, 3, 3, 4])
    out = values_outside(train, test, runs)
    assert out["train"] == [0.0, 4.0] and out["test"] == [-0.5, 4.09]
    assert out["samples_outside"] == pytest.approx(2 / 5)      # the NaN sample left out, its run too
    assert out["runs_outside"] == 2 and out["test_runs"] == 3
    assert values_outside(train, test, runs, tolerance=0.0)["samples_outside"] == pytest.approx(3 / 5)


def test_channel_ranges_records_every_signal_an_added_effect_reads_with_the_share_of_test_outside():
    recs = ranges.channel_ranges(ADDED, TRAIN, TEST)
    assert [(r["channel"], r["level"], r["transform"]) for r in recs] == [
        ("coil_A", "sample", "none"), ("coil_A", "run", "none"), ("load_kg", "run", "drive"),
        ("load_kg", "run", "abs")]     # no category (unseen levels' own check), no column TEST lacks, no named effect
    sample, run, drive, size = recs
    assert sample["effects"] == {"A": "extrapolates", "B": "clipped"}
    assert sample["train"] == [0.0, 4.0] and sample["test"] == [-0.05, 4.5]
    assert sample["samples_outside"] == pytest.approx(5 / 33) and sample["runs_outside"] == 1
    assert sample["test_runs"] == 3
    assert run["effects"] == {"C": "extrapolates"} and run["signal"] == "coil_A (run mean)"
    assert run["train"] == pytest.approx([0.5, 3.5])
    assert run["samples_outside"] == pytest.approx(22 / 33) and run["runs_outside"] == 2
    assert drive["signal"] == "d*load_kg (run mean)" and drive["train"] == pytest.approx([-0.1, 0.2])
    assert drive["samples_outside"] == pytest.approx(11 / 33) and drive["runs_outside"] == 1
    assert size["runs_outside"] == 0 and size["samples_outside"] == 0.0
    assert ranges.channel_ranges(ADDED, TRAIN, None) == []


def test_a_logged_channels_signal_times_the_direction_is_ranged_about_its_centre():
    # d (run mean - 2): TRAIN's runs -1.5, 0.5, 0.5, -1.5 (tolerance 2 % of 2); TEST's -0.5, -2.0, +2.0: two runs
    # outside (uncentred, d * run mean: TRAIN [-3.5, 2.5], TEST 1.5, -4.0, 0.0, one run)
    [rec] = ranges.channel_ranges([_added("I", kind="run_level", channel="coil_A", transform="drive", centre=2.0,
                                          mean=0.0, sd=1.0)], TRAIN, TEST)
    assert rec["signal"] == "d*coil_A (run mean)" and rec["train"] == pytest.approx([-1.5, 0.5])
    assert rec["test"] == pytest.approx([-2.0, 2.0])
    assert rec["runs_outside"] == 2 and rec["samples_outside"] == pytest.approx(22 / 33)


def test_a_logged_channels_curvature_is_ranged_about_its_centre_less_its_line():
    # (m - 2)^2 - (m - 2): TRAIN's runs 3.75, 0.75, -0.25, 0.75 (tolerance 2 % of 4); TEST's 0.75, 2.0, 6.0: one
    # run outside (without the line, (m - 2)^2: TRAIN [0.25, 2.25], TEST 0.25, 4.0, 4.0, two runs)
    [rec] = ranges.channel_ranges([_added("Q", kind="run_level", channel="coil_A", transform="square", centre=2.0,
                                          slope=1.0, mean=0.0, sd=1.0)], TRAIN, TEST)
    assert rec["signal"] == "coil_A^2 (run mean)" and rec["train"] == pytest.approx([-0.25, 3.75])
    assert rec["test"] == pytest.approx([0.75, 6.0])
    assert rec["runs_outside"] == 1 and rec["samples_outside"] == pytest.approx(11 / 33)


def test_the_report_prints_one_line_per_channel_outside_and_none_for_a_channel_inside():
    sample, run, drive, size = ranges.channel_ranges(ADDED, TRAIN, TEST)
    assert channel_range_line(sample) == (
        "TEST has 15.2% of its samples (1 of 3 runs) with coil_A outside TRAIN's range [0, 4] (TEST: [-0.05, 4.5]): "
        "the effects of it there `A` extrapolate linearly; `B` are held at TRAIN's range's end (saturate)")
    assert channel_range_line(run).startswith("TEST has 66.7% of its samples (2 of 3 runs) with coil_A (run mean) "
                                              "outside TRAIN's range [0.5, 3.5]")
    assert channel_range_line(size) == ""
    from l1b2.closeloop.result import markdown_report
    from test_report_values import minimal_report
    rep = minimal_report()
    rep["diagnosis"] = {**rep["diagnosis"], "channel_ranges": [sample, size, drive]}
    lines = [line for line in markdown_report(rep).splitlines() if "outside TRAIN's range" in line]
    assert lines == [f"* {channel_range_line(sample)}", f"* {channel_range_line(drive)}"]
    assert "outside TRAIN's range" not in markdown_report(minimal_report())


def test_the_cli_warns_per_channel_outside_and_an_older_report_without_the_field_still_loads(capsys):
    from l1b2.console import print_input_checks
    sample, run, drive, size = ranges.channel_ranges(ADDED, TRAIN, TEST)
    print_input_checks({}, {}, [channel_range_line(sample), channel_range_line(size)])
    assert capsys.readouterr().out.splitlines() == [f"  warning: {channel_range_line(sample)}"]
    old = {"significant": False, "traced_to": [], "effect": None, "effect_shape": None,
           "effect_description": None, "effects": [], "message": "no significant missing effect"}
    assert Diagnosis.from_dict(old).channel_ranges == []
    d = Diagnosis.from_dict({**old, "channel_ranges": [sample]})
    assert Diagnosis.from_dict(d.to_dict()) == d


def test_the_report_says_how_far_the_speed_column_is_from_the_positions_derivative():
    from l1b2.closeloop.report import chain_line
    from l1b2.closeloop.result import markdown_report
    from test_report_values import minimal_report
    rec = {"accepted": False, "rel_rms_mismatch": 0.2134, "cv_gain": 0.0008, "p_value": 0.0756}
    want = ("Measurement chain: the speed column differs from the position's derivative by 21.3% of the speed's "
            "rms; the speed channel's test (held-out gain 0.1%, p 0.076): no filter passed the test.")
    assert chain_line(rec) == want
    assert chain_line({**rec, "accepted": True}).endswith(": its filter was kept.")
    assert "found but not applied" in chain_line({**rec, "refused_by_harm_guard": True})
    assert chain_line({"accepted": False, "reason": "no speed column"}) == \
        "Measurement chain: not tested (no speed column)."
    assert chain_line({}) == ""
    rep = minimal_report()
    rep["diagnosis"] = {**rep["diagnosis"], "measurement_chain": rec}
    assert want in markdown_report(rep).splitlines()
    assert "Measurement chain" not in markdown_report(minimal_report())
