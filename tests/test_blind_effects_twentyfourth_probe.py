"""The twenty-fourth and twenty-fifth audits' probes (``bench/blind_effects_twentyfourth_probe.py``): the patched
rules in the loop's own functions, on frames and signals made here."""
import numpy as np
import pandas as pd
import pytest


@pytest.fixture
def probe(load_bench, monkeypatch):
    from l1b2.closeloop import derived, runlevel
    from l1b2.predictor.effects import channels
    for mod, name in ((runlevel, "searches_blocks"), (derived, "with_run_travel"), (runlevel, "_times_direction"),
                      (channels, "run_signal")):
        monkeypatch.setattr(mod, name, getattr(mod, name))     # restored after the test
    return load_bench("blind_effects_twentyfourth_probe")


class _Evidence:
    def __init__(self, p_value):
        self.p_value = p_value


def test_blocks_are_searched_beside_a_significant_signal(probe):
    from l1b2.closeloop import runlevel
    strong = [_Evidence(1e-9)]
    assert not runlevel.searches_blocks(strong, 1e-3)        # the loop's rule: a signal has Wald evidence
    assert runlevel.searches_blocks([_Evidence(0.5)], 1e-3)
    probe.patch("blocks")
    assert runlevel.searches_blocks(strong, 1e-3) and runlevel.searches_blocks([], 1e-3)


def _frame(start):
    """Two runs, each from its own stop: forward from -15 mm, backward from +15 mm."""
    rows = []
    for run, d in ((1, 1), (2, -1)):
        for k in range(20):
            rows.append({"run": run, "time_s": run + 0.01 * k, "position_m": d * (0.0015 * k) + start[d],
                         "voltage_V": 220.0, "direction": d, "load_kg": 0.0, "speed_m_s": 0.15 * d})
    return pd.DataFrame(rows)


def test_notravel_leaves_the_frames_as_they_are(probe):
    from l1b2.closeloop import derived
    from l1b2.closeloop.runclock import TRAVEL_COLUMN
    train, test = _frame({1: -0.015, -1: 0.015}), _frame({1: -0.015, -1: 0.015})
    tr, te, rec = derived.with_run_travel(train, test)
    assert rec["derived"] and TRAVEL_COLUMN in tr.columns and TRAVEL_COLUMN in te.columns
    assert tr[TRAVEL_COLUMN].to_numpy()[[0, 19, 20, 39]] == pytest.approx([0.0, 0.0285, 0.0, 0.0285], abs=1e-12)
    probe.patch("notravel")
    tr, te, rec = derived.with_run_travel(train, test)
    assert tr is train and te is test and not rec["derived"] and TRAVEL_COLUMN not in tr.columns
    assert np.array_equal(tr.columns, train.columns)


def test_square_replaces_a_logged_channels_drive_signal_and_its_realisation(probe):
    from l1b2.closeloop import runlevel
    from l1b2.predictor.effects import channels
    sg = {"channel": "fibre_angle_deg", "transform": "none", "values": np.array([-60.0, 0.0, 30.0, 150.0])}
    d = np.array([1.0, -1.0, 1.0, -1.0])
    assert runlevel._times_direction(sg, d)["values"] == pytest.approx([-90.0, 30.0, 0.0, -120.0])    # (c - 30) d
    probe.patch("square")
    out = runlevel._times_direction(sg, d)
    assert out["values"] == pytest.approx([90.0 ** 2, 30.0 ** 2, 0.0, 120.0 ** 2])
    assert out["transform"] == "drive" and out["centre"] == 30.0 and out["channel"] == "fibre_angle_deg"
    x = {"run:fibre_angle_deg": np.array([-60.0, 30.0]), "run:load_kg": np.array([0.05, -0.02]),
         "d": np.array([1.0, -1.0])}
    assert channels.run_signal(x, "fibre_angle_deg", "drive", 30.0) == pytest.approx([90.0 ** 2, 0.0])
    assert channels.run_signal(x, "fibre_angle_deg", "none", 30.0) == pytest.approx([-90.0, 0.0])   # kept
    assert channels.run_signal(x, "fibre_angle_deg", "square", 30.0, 2.0) == pytest.approx([8280.0, 0.0])   # kept
    assert channels.run_signal(x, "load_kg", "drive") == pytest.approx([0.05, 0.02])    # an input's: d m, kept


def test_a_bad_mode_is_refused(probe):
    with pytest.raises(ValueError, match="blocks, notravel, square"):
        probe.patch("sideways")
    with pytest.raises(SystemExit, match="MODE: one of blocks, notravel, square"):
        probe.main(["sideways", "stop_magnet_latch", "1"])
    with pytest.raises(SystemExit, match="MODE: one of blocks, notravel, square"):
        probe.main(["--audit", "blind_effects"])
