"""The units of the channels the close loop derives from the log, as Predictor.fmu's inputs declare them.

The rule is the naming rule of :func:`l1b2.units.column_unit`: a lag (``X_lag<n>r``) or a step (``X_step``) of a
column has the column's unit (a step of an offset unit its coherent one), an event clock (``X_since_s``) and the run's
clock (``time_in_run_s``) are in s, the run's travel (``travel_in_run_m``) in m, a logarithm (``ln_Q``) is
dimensionless and its description says of what in which unit. References: the units written out per channel, and
the base units of FMI 2.0's ``UnitDefinitions`` written out (V = kg m2 s-3 A-1).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from l1b2.cosim.composite import PredictorBlock
from l1b2.predictor import effects as fx
from l1b2.predictor.effects import ExtendedPredictor, IdentifiedEffect
from l1b2.units import column_unit, unit_note


def _session() -> pd.DataFrame:
    """Sixteen runs of one session: the voltage a run setting (changes most runs), ``heater_W`` a logged run setting,
    ``clamp_id`` a step channel (changes every fifth run), pauses from 0.5 s to 20 s."""
    volts = [200.0, 260.0, 300.0, 260.0, 200.0, 300.0, 240.0, 280.0] * 2
    heater = [0.0, 5.0, 10.0, 5.0, 0.0, 10.0, 5.0, 0.0] * 2
    pauses = [0.5, 2.0, 20.0, 1.0, 5.0, 0.7, 12.0, 3.0] * 2
    rows, t = [], 0.0
    for k in range(16):
        for i in range(5):
            rows.append({"time_s": t + 0.01 * i, "run": k + 1, "position_m": 0.001 * i, "voltage_V": volts[k],
                         "direction": 1 if k % 2 == 0 else -1, "load_kg": 0.0, "speed_m_s": 0.1,
                         "heater_W": heater[k], "clamp_id": float(k // 5)})
        t += 0.04 + pauses[k]
    return pd.DataFrame(rows)


def test_every_channel_the_loop_derives_from_a_session_has_its_unit():
    # reference: the units written out per derived channel (the derivations run on a session that makes each)
    from l1b2.closeloop.events import with_event_clocks
    from l1b2.closeloop.lags import with_lagged_channels
    from l1b2.closeloop.pauses import COLUMN, REFERENCE_S, with_pause_channel
    from l1b2.closeloop.runclock import with_run_clock, with_run_travel
    df = _session()
    d, _, _ = with_event_clocks(df, None)
    d, _, _ = with_lagged_channels(d, None)
    d, _, _ = with_pause_channel(d, None)
    d, _, _ = with_run_clock(d, None)
    d, _, _ = with_run_travel(d, None)
    derived = [c for c in d.columns if c not in df.columns]
    want = {"clamp_id_since_s": "s", "voltage_V_lag3r": "V", "voltage_V_lag10r": "V", "voltage_V_step": "V",
            "heater_W_lag3r": "W", "heater_W_lag10r": "W", "ln_pause_s": "1", "time_in_run_s": "s",
            "travel_in_run_m": "m"}
    assert sorted(derived) == sorted(want)                       # not vacuous: each derivation made its channel
    assert {c: column_unit(c) for c in derived} == want
    assert COLUMN == "ln_pause_s" and REFERENCE_S == 1.0         # the name states ln(p / 1 s)
    assert unit_note(COLUMN) == "ln(pause_s / 1 s): the natural logarithm of pause_s in s, dimensionless"
    assert unit_note("voltage_V_step") == unit_note("heater_W_lag3r") == unit_note("time_in_run_s") == unit_note("travel_in_run_m") == ""


def test_the_naming_rule_of_derived_names():
    # reference: the rule written out, name by name
    want = {"temperature_C_lag3r": "degC", "temperature_C_step": "K",   # a difference of degC is in K
            "frequency_Hz_lag10r": "Hz", "line_pressure_bar_step": "bar", "belt_speed_m_s_lag3r": "m/s",
            "ln_pause_s_lag3r": "1", "ln_gap_m": "1", "voltage_V_lag25r": "V",
            "fixture_id_step": None, "fixture_id_lag3r": None, "test_step": None, "ln_foo": None, "_step": None,
            "_lag3r": None, "voltage_V_lagr": None, "voltage_V_lag3r_logged": None}
    assert {n: column_unit(n) for n in want} == want
    assert unit_note("ln_pause_s_lag3r") == unit_note("ln_pause_s")
    assert unit_note("ln_foo") == "ln(foo): the natural logarithm of foo in its column's own unit"   # no unit named


def _run_level(channel: str, mean: float, sd: float) -> IdentifiedEffect:
    h = fx.family("run_level").hypotheses([{"channel": channel, "transform": "none", "mean": mean, "sd": sd,
                                            "run_spread": 0.0}])[0]
    return IdentifiedEffect(h.family, f"run_level_{channel}", dict(h.spec), tuple(h.names), tuple(h.units), (0.1, 0.2, 0.3),
                            (0.01,) * 3, h.description, (h.regressor,), h.structural)


CHANNELS = {"voltage_V_step": ("V", 12.0, 60.0), "voltage_V_lag3r": ("V", 260.0, 30.0),
            "ln_pause_s": ("1", 1.0, 1.2), "clamp_id_since_s": ("s", 40.0, 20.0), "heater_W_lag10r": ("W", 4.0, 2.0)}


def _model() -> ExtendedPredictor:
    from test_extended_predictor_fmu import _setups
    base, refit = _setups(1.02)
    return ExtendedPredictor(base, refit, tuple(_run_level(c, m, s) for c, (_, m, s) in CHANNELS.items()), None,
                             {"train": "train.csv"})


def test_the_block_declares_each_derived_channels_input_in_its_unit():
    ins = {v.name: v for v in PredictorBlock.variables(_model()) if v.causality == "input"}
    assert {c: ins[c].unit for c in CHANNELS} == {c: u for c, (u, _, _) in CHANNELS.items()}
    assert "ln(pause_s / 1 s): the natural logarithm of pause_s in s, dimensionless" in ins["ln_pause_s"].description
    assert not any("unit is not known" in ins[c].description for c in CHANNELS)
    assert "natural logarithm" not in ins["voltage_V_step"].description


def test_the_exported_fmu_declares_the_units_with_valid_unit_definitions(tmp_path):
    # reference: FMI 2.0 BaseUnit exponents written out; fmpy's validation of the FMU
    import xml.etree.ElementTree as ET
    import zipfile

    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    from l1b2.fmi.export import export_calibrated
    man = export_calibrated(_model(), tmp_path / "out")
    recs = {r["name"]: r["unit"] for r in man["channel_inputs"]}
    assert recs == {c: u for c, (u, _, _) in CHANNELS.items()}
    path = tmp_path / "out" / "fmus" / "Predictor.fmu"
    assert validate_fmu(str(path)) == []
    var = {v.name: v for v in read_model_description(str(path)).modelVariables}
    assert {c: (var[c].causality, var[c].unit) for c in CHANNELS} == {c: ("input", u)
                                                                      for c, (u, _, _) in CHANNELS.items()}
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    units = {u.get("name"): u.find("BaseUnit").attrib for u in root.find("UnitDefinitions")}
    assert units["V"] == {"kg": "1", "m": "2", "s": "-3", "A": "-1"}
    assert units["W"] == {"kg": "1", "m": "2", "s": "-3"}
    assert units["s"] == {"s": "1"} and units["1"] == {}
    declared = {sv.find("Real").get("unit") for sv in root.find("ModelVariables") if sv.find("Real") is not None}
    assert declared <= set(units)


@pytest.mark.parametrize("name", sorted(CHANNELS))
def test_a_derived_channels_unit_is_a_defined_unit(name):
    from l1b2.units import UNITS
    assert column_unit(name) in UNITS and np.isfinite(UNITS[column_unit(name)].factor)
