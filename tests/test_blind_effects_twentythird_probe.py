"""The twenty-third audit's probes (``bench/blind_effects_twentythird_probe.py``): the replaced run values against
their formulas written out, and the patched rules in the loop's own functions."""
import numpy as np
import pandas as pd
import pytest


@pytest.fixture
def probe(load_bench, monkeypatch):
    from l1b2.closeloop import runlevel, selection
    for mod, name in ((runlevel, "run_signals"), (runlevel, "_times_direction"), (selection, "search_count")):
        monkeypatch.setattr(mod, name, getattr(mod, name))     # restored after the test
    return load_bench("blind_effects_twentythird_probe")


def test_the_replaced_values(probe):
    v = np.array([220.0, 255.0, 290.0, 324.0])
    w = probe.drive_weight(v)
    assert w == pytest.approx((v - 272.25) / 272.25, rel=1e-14)
    c = np.array([12.0, 16.0, 20.0, 24.0])                       # mean 18, sd sqrt(20)
    assert probe.replaced_values("vx", c, w) == pytest.approx((c - 18.0) * w, rel=1e-14)
    z2 = (c - 18.0) ** 2 / 20.0                                  # 1.8, 0.2, 0.2, 1.8: mean 1
    assert probe.replaced_values("q", c, w) == pytest.approx(z2 - 1.0, rel=1e-12)
    assert probe.replaced_values("qv", c, w) == pytest.approx((z2 - 1.0) * w, rel=1e-12)
    assert probe.replaced_values("q", np.full(4, 3.0), w) == pytest.approx(np.zeros(4))   # constant: no shape
    with pytest.raises(ValueError, match="grid1"):
        probe.replaced_values("grid1", c, w)


def _frame():
    rows = []
    for run, (v0, d, p) in enumerate([(220.0, 1, 12.0), (255.0, -1, 16.0), (290.0, 1, 21.0), (324.0, -1, 25.0)], 1):
        for k in range(30):
            rows.append({"run": run, "time_s": run + 0.01 * k, "position_m": d * (0.001 * k - 0.015),
                         "voltage_V": v0, "direction": d, "load_kg": 0.0, "speed_m_s": 0.1 * d,
                         "p_hPa": p + 0.01 * np.sin(k)})
    return pd.DataFrame(rows)


@pytest.mark.parametrize("mode", ["vx", "q", "qv"])
def test_the_patched_run_signals_hold_the_replaced_values(probe, mode):
    from l1b2.closeloop import runlevel
    from l1b2.closeloop.candidates import channels_of
    df = _frame()
    before = {(s["channel"], s["transform"]): s["values"] for s in runlevel.run_signals(df, channels_of(df))}
    probe.patch(mode)
    after = {(s["channel"], s["transform"]): s["values"] for s in runlevel.run_signals(df, channels_of(df))}
    c = df.groupby("run")["p_hPa"].mean().to_numpy()
    w = (np.array([220.0, 255.0, 290.0, 324.0]) - 272.25) / 272.25
    assert before[("p_hPa", "drive")] == pytest.approx((c - c.mean()) * np.array([1, -1, 1, -1]))
    expected = {"vx": (c - c.mean()) * w,
                "q": (c - c.mean()) ** 2 / c.var() - 1.0,
                "qv": ((c - c.mean()) ** 2 / c.var() - 1.0) * w}[mode]
    assert after[("p_hPa", "drive")] == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert after[("p_hPa", "none")] == pytest.approx(before[("p_hPa", "none")])   # the channel's mean is kept


def test_grid1_drops_the_grid_count_and_a_bad_mode_is_refused(probe):
    from l1b2.closeloop import selection
    probe.patch("grid1")
    assert selection.search_count(object()) == 1
    with pytest.raises(SystemExit, match="MODE: one of grid1, vx, q, qv"):
        probe.main(["sideways", "paschen_glow_clamp", "1"])
