"""Parameter sets: l1b2.physics.params and the reference motor (system_models/reference_motor.toml)."""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib

import numpy as np
import pytest
from l1b2.errors import ParameterError
from l1b2.physics import driver as drv
from l1b2.physics import stator as st
from l1b2.physics.params import (
    REFERENCE_MOTOR_FILE,
    SYSTEM_MODELS_DIR,
    MotorParams,
    describe,
    load_motor,
    sources,
)

REF_TOML = SYSTEM_MODELS_DIR / REFERENCE_MOTOR_FILE
SECTIONS = ("driver", "stator", "interface", "slider", "operating")


def _edit(text: str, section: str, field: str, new_line: str | None) -> str:
    """Replace (or delete, new_line=None) the line of ``field`` inside ``[section]``."""
    out, current, done = [], None, False
    for line in text.splitlines():
        m = re.match(r"^\s*\[([^\]]+)\]\s*$", line)
        if m:
            current = m.group(1).strip()
        if current == section and re.match(rf"^\s*{re.escape(field)}\s*=", line):
            done = True
            if new_line is not None:
                out.append(new_line)
            continue
        out.append(line)
    assert done, f"{field} not found in [{section}]"
    return "\n".join(out) + "\n"


def _insert(text: str, section: str, new_line: str) -> str:
    lines = text.splitlines()
    idx = next(i for i, l in enumerate(lines) if l.strip() == f"[{section}]")
    lines.insert(idx + 1, new_line)
    return "\n".join(lines) + "\n"


def _field_line(section, field, value, unit):
    return f'{field} = {{ value = {value}, unit = "{unit}", source = "test" }}'


@pytest.fixture()
def ref_text():
    return REF_TOML.read_text()


def _load_modified(tmp_path, text):
    path = tmp_path / "modified_motor.toml"
    path.write_text(text)
    return path


def test_reference_motor_loads_with_the_files_values():
    # reference: independent tomllib parse of the TOML, field by field
    mp = load_motor()
    doc = tomllib.loads(REF_TOML.read_text())
    assert mp.name == doc["meta"]["name"]
    for sec in SECTIONS:
        values = getattr(mp, sec)
        declared = {d["name"]: d["unit"] for d in describe(type(values))}
        assert set(declared) == set(doc[sec])
        for name, unit in declared.items():
            assert doc[sec][name]["unit"] == unit
            assert getattr(values, name) == float(doc[sec][name]["value"])
    # every value carries the reason it was chosen
    srcs = sources()
    for sec in SECTIONS:
        assert all(isinstance(v, str) and v.strip() for v in srcs[sec].values()), sec


def _check_message(exc, path, section, field, *units):
    msg = str(exc.value)
    assert str(path) in msg
    assert section in msg
    assert field in msg
    for u in units:
        assert u in msg, f"unit {u!r} not named in: {msg}"


def test_wrong_unit_is_refused(tmp_path, ref_text):
    # reference: the unit declared by the dataclass ("Hz") versus the file's ("kHz")
    path = _load_modified(tmp_path, _edit(ref_text, "stator", "f_b0_Hz", _field_line("stator", "f_b0_Hz", 48.0, "kHz")))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, "stator", "f_b0_Hz", "kHz", "'Hz'")


def test_missing_field_is_refused(tmp_path, ref_text):
    # reference: every declared field is required
    path = _load_modified(tmp_path, _edit(ref_text, "stator", "A_l_N_per_V", None))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, "stator", "A_l_N_per_V", "N/V")


def test_unknown_field_is_refused_naming_its_unit(tmp_path, ref_text):
    # reference: the unit written in the file for the unknown field must appear in the message
    path = _load_modified(tmp_path, _insert(ref_text, "interface", _field_line("interface", "sigma2_N_s_per_m",
                                                                                  1.0, "N.s/m")))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, "interface", "sigma2_N_s_per_m", "N.s/m")


def test_unknown_field_is_refused(tmp_path, ref_text):
    # reference: no silent acceptance of a parameter the model does not have
    path = _load_modified(tmp_path, _insert(ref_text, "interface", _field_line("interface", "sigma2_N_s_per_m",
                                                                                  1.0, "N.s/m")))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, "interface", "sigma2_N_s_per_m")


@pytest.mark.parametrize("bad", ['"3e7"', "true", "[3e7]"])
def test_non_number_is_refused(tmp_path, ref_text, bad):
    # reference: values must be TOML numbers
    path = _load_modified(tmp_path, _edit(ref_text, "interface", "k_e_N_per_m",
                                          f'k_e_N_per_m = {{ value = {bad}, unit = "N/m", source = "test" }}'))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, "interface", "k_e_N_per_m", "N/m")


@pytest.mark.parametrize("section, field, value, unit", [
    ("stator", "density_kg_m3", 0.5, "kg/m3"),      # below min 1
    ("stator", "zeta_b", 1.5, "1"),                 # above max 1
    ("operating", "duty", 1.2, "1"),                # above max 1
    ("driver", "L_H", -1e-3, "H"),                  # below min
    ("interface", "k_e_N_per_m", "nan", "N/m"),     # not finite
    ("slider", "c_r_N_s_per_m", "-inf", "N.s/m"),   # not finite
])
def test_out_of_range_is_refused(tmp_path, ref_text, section, field, value, unit):
    # reference: min/max declared in the dataclass metadata
    path = _load_modified(tmp_path, _edit(ref_text, section, field, _field_line(section, field, value, unit)))
    with pytest.raises(ParameterError) as exc:
        load_motor(path)
    _check_message(exc, path, section, field, f"[{unit}]")


def test_missing_section_and_bad_toml_are_refused(tmp_path, ref_text):
    # reference: file-level problems also raise ParameterError naming the file
    text = re.sub(r"\[operating\][^\[]*", "", ref_text)
    path = _load_modified(tmp_path, text)
    with pytest.raises(ParameterError, match=r"operating"):
        load_motor(path)
    bad = tmp_path / "bad.toml"
    bad.write_text("[driver\nL_H = 1")
    with pytest.raises(ParameterError, match=re.escape(str(bad))):
        load_motor(bad)
    with pytest.raises(ParameterError, match="cannot read"):
        load_motor(tmp_path / "does_not_exist.toml")


def test_motor_params_replace(motor):
    # reference: dataclass semantics - a changed copy, original untouched, validation applied
    mp2 = motor.replace(stator__zeta_b=0.02, slider__mass_kg=0.2)
    assert mp2.stator.zeta_b == 0.02 and mp2.slider.mass_kg == 0.2
    assert motor.stator.zeta_b != 0.02 and motor.slider.mass_kg != 0.2
    assert mp2.stator.f_b0_Hz == motor.stator.f_b0_Hz and mp2.driver == motor.driver
    whole = motor.replace(interface=dataclasses.replace(motor.interface, mu_p=0.3), name="other")
    assert whole.interface.mu_p == 0.3 and whole.name == "other"
    with pytest.raises(ParameterError):
        motor.replace(stator__zeta_b=2.0)
    with pytest.raises(ParameterError):
        motor.replace(slider__mu_ss=0.01)  # below mu_sd
    with pytest.raises(TypeError):
        motor.replace(stator__no_such_field=1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        motor.stator.zeta_b = 0.5  # type: ignore[misc]
    assert isinstance(mp2, MotorParams)


def test_every_field_declares_a_known_unit():
    # reference: l1b2.units has a definition for every declared unit (needed by FMU and SSP files)
    from l1b2.units import UNITS
    mp = load_motor()
    for sec in SECTIONS:
        for d in describe(type(getattr(mp, sec))):
            assert d["unit"] in UNITS, (sec, d["name"], d["unit"])
            assert d["description"]


# ---------------------------------------------------------------------------
# Physics-notes targets that are pure parameter facts
# ---------------------------------------------------------------------------

def test_drive_frequency_lies_between_the_resonances(motor):
    # reference: design targets (docs/explanation/physics.md) - drive 48.5 kHz between the B2 and L1 resonances
    f = motor.operating.f_drive_Hz
    assert f == pytest.approx(48500.0)
    assert motor.stator.f_b0_Hz < f < motor.stator.f_l0_Hz
    P = st.axial_force_N(motor.stator, np.linspace(motor.slider.s_min_m, motor.slider.s_max_m, 41))
    assert np.all(st.b2_frequency_rad_s(motor.stator, P) / (2 * np.pi) < f)


def test_preload_in_the_papers_range(motor):
    # reference: design targets (docs/explanation/physics.md) - preload F_p = alpha0 P of order 5-8 N (paper Table 1: p(0) = 6.06 N)
    sp = motor.stator
    assert sp.alpha0 != 1.0  # Eq. 16 asks alpha0 != 1
    assert 5.0 <= sp.alpha0 * sp.P0_N <= 8.0
    s = np.linspace(motor.slider.s_min_m, motor.slider.s_max_m, 85)
    Fp = st.preload_N(sp, s)
    assert np.all((Fp >= 5.0) & (Fp <= 8.0))


def test_time_scales_match_physics_notes(motor):
    # reference: design targets (docs/explanation/physics.md) - envelopes settle in ~1/(zeta w) ~ 0.3 ms, slider m/c_r tens of ms
    w = 2 * np.pi * motor.operating.f_drive_Hz
    for zeta in (motor.stator.zeta_l, motor.stator.zeta_b):
        assert 0.1e-3 < 1.0 / (zeta * w) < 1.0e-3
    tau_slider = motor.slider.mass_kg / motor.slider.c_r_N_s_per_m
    assert 10e-3 <= tau_slider <= 100e-3
    assert motor.slider.mu_ss >= motor.slider.mu_sd
    assert motor.slider.s_min_m < 0 < motor.slider.s_max_m
    assert motor.slider.s_max_m - motor.slider.s_min_m >= 0.040  # ~40 mm traverses (Fig. 9)


def test_tank_is_tuned_to_the_drive(motor):
    # reference: Eq. 3 with the file's L, C1 + C_m, R_m puts the zero-phase frequency at the drive (0.5 %)
    d = motor.driver
    w0 = math.sqrt(1 / (d.L_H * (d.C1_F + d.C_m_F)) - 1 / (d.R_m_ohm ** 2 * (d.C1_F + d.C_m_F) ** 2))
    assert w0 / (2 * math.pi) == pytest.approx(motor.operating.f_drive_Hz, rel=5e-3)
    assert float(drv.tank_resonance_rad_s(d.L_H, d.C1_F + d.C_m_F, d.R_m_ohm)) == pytest.approx(w0, rel=1e-12)
