"""Parameter sets as frozen dataclasses, loaded from ``system_models/``.

A parameter file is TOML. Each subsystem is a table, each parameter an inline
table with its value, its SI unit (checked against the unit the dataclass
declares) and the reason the value was chosen::

    [stator]
    f_l0_Hz = { value = 49.0e3, unit = "Hz", source = "L1 above the drive ..." }

Every field of a dataclass declares its unit and description in
``dataclasses.field(metadata=...)``; :func:`describe` lists them and the FMU
wrappers use the same metadata for their ``modelDescription.xml``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ParameterError
from ..units import G_M_S2  # noqa: F401  (re-exported: the physics' gravity constant)

#: Folder holding the embedded reference parameter set and system structure.
REFERENCE_MOTOR_FILE = "reference_motor.toml"


def _system_models_dir() -> Path:
    """The motor files: ``l1b2/system_models`` of an installed package, else the checkout's ``system_models/``.

    The wheel installs the repository's top-level ``system_models/`` as the
    package data folder ``l1b2.system_models`` (see ``pyproject.toml``); an
    editable install and a plain checkout find the same folder in the repository.
    """
    import importlib.util
    top = __name__.split(".")[0]
    try:
        spec = importlib.util.find_spec(f"{top}.system_models")
    except (ImportError, ValueError):
        spec = None
    for loc in (spec.submodule_search_locations or []) if spec is not None else []:
        if (Path(loc) / REFERENCE_MOTOR_FILE).is_file():
            return Path(loc)
    return Path(__file__).resolve().parents[3] / "system_models"


#: folder of the embedded motor files (TOML, SSD, SSVs)
SYSTEM_MODELS_DIR = _system_models_dir()


def p(unit: str, description: str, *, min: float | None = None, max: float | None = None):
    """Declare a physical parameter field (no default: every value comes from a file)."""
    return field(metadata={"unit": unit, "description": description, "min": min, "max": max})


def _validated(obj) -> None:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        lo, hi = f.metadata.get("min"), f.metadata.get("max")
        unit = f.metadata.get("unit", "")
        if not math.isfinite(value):
            raise ParameterError(f"{type(obj).__name__}.{f.name} [{unit}] = {value} is not finite")
        if lo is not None and value < lo:
            raise ParameterError(
                f"{type(obj).__name__}.{f.name} [{unit}] = {value} is below its minimum {lo}")
        if hi is not None and value > hi:
            raise ParameterError(
                f"{type(obj).__name__}.{f.name} [{unit}] = {value} is above its maximum {hi}")


@dataclass(frozen=True)
class DriverParams:
    """H-bridge inverter and LC resonance tank (paper Sect. 3.1, Eq. 1-4)."""

    L_H: float = p("H", "series tank inductance at the reference temperature and frequency", min=1e-9)
    C1_F: float = p("F", "matching capacitor in parallel with the stator", min=0.0)
    C_m_F: float = p("F", "clamped capacitance of the piezoelectric stator", min=1e-15)
    R_m_ohm: float = p("Ohm", "equivalent (motional + loss) resistance of the stator", min=1e-6)
    T_ref_degC: float = p("degC", "reference temperature of L")
    f_ref_Hz: float = p("Hz", "reference frequency of L and C1", min=1.0)
    L_temp_coeff_per_K: float = p("1/K", "relative drift of L per kelvin (Eq. 4)")
    L_freq_coeff_per_Hz: float = p("1/Hz", "relative drift of L per hertz (Eq. 4)")
    C1_freq_coeff_per_Hz: float = p("1/Hz", "relative drift of C1 per hertz (Eq. 4)")
    V0_sat_V: float = p("V", "output saturation amplitude of the drive, V0 = V_sat tanh(V0_lin/V_sat) (0 = off)",
                        min=0.0)

    def __post_init__(self):
        _validated(self)


@dataclass(frozen=True)
class StatorParams:
    """Rectangular PZT stator with its L1 and B2 modes (paper Sect. 3.2, Eq. 5-16)."""

    length_m: float = p("m", "stator length L", min=1e-4)
    width_m: float = p("m", "stator width (in-plane bending height of the B2 mode)", min=1e-4)
    thickness_m: float = p("m", "stator thickness", min=1e-4)
    density_kg_m3: float = p("kg/m3", "density rho of the piezoceramic", min=1.0)
    f_l0_Hz: float = p("Hz", "L1 natural frequency without contact at the reference temperature", min=1.0)
    f_b0_Hz: float = p("Hz", "B2 natural frequency without axial load at the reference temperature", min=1.0)
    zeta_l: float = p("1", "L1 modal damping ratio", min=0.0, max=1.0)
    zeta_b: float = p("1", "B2 modal damping ratio", min=0.0, max=1.0)
    A_l_N_per_V: float = p("N/V", "electromechanical coupling factor of the L1 mode", min=0.0)
    A_b_N_per_V: float = p("N/V", "electromechanical coupling factor of the B2 mode", min=0.0)
    alpha0: float = p("1", "conversion factor F_p = alpha0 * P (Eq. 16)", min=0.0)
    P0_N: float = p("N", "nominal compressive axial (preload) force at the bar centre", min=0.0)
    preload_stiffness_N_per_m: float = p("N/m", "stiffness of the preload spring", min=0.0)
    bar_dev_1_m: float = p("m", "friction-bar deviation from the guide line: Legendre P1 coefficient")
    bar_dev_2_m: float = p("m", "friction-bar deviation: Legendre P2 coefficient")
    bar_dev_3_m: float = p("m", "friction-bar deviation: Legendre P3 coefficient")
    bar_half_length_m: float = p("m", "half length of the friction bar (position scale of the deviation)", min=1e-4)
    bar_wave_amp_m: float = p("m", "amplitude of a periodic waviness of the friction bar (0 = off)")
    bar_wave_period_m: float = p("m", "period of the friction-bar waviness", min=1e-5)
    bar_bump_amp_m: float = p("m", "height of a local bump (Gaussian) on the friction bar (0 = off)")
    bar_bump_center_m: float = p("m", "position of the bump")
    bar_bump_width_m: float = p("m", "standard deviation of the bump", min=1e-5)
    df_dT_l_Hz_per_K: float = p("Hz/K", "thermal drift of the L1 frequency (0 = off)")
    df_dT_b_Hz_per_K: float = p("Hz/K", "thermal drift of the B2 frequency (0 = off)")
    T_ref_degC: float = p("degC", "reference temperature of the modal frequencies")
    thermal_tau_s: float = p("s", "thermal time constant of the stator (0 = off: stator at ambient temperature)",
                             min=0.0)
    heating_K_per_V2: float = p("K/V2", "steady temperature rise of the stator per V0^2 (dielectric and mechanical loss)",
                                min=0.0)
    asym_b: float = p("1", "relative B2 coupling asymmetry between CH1 and CH2 (0 = symmetric, off)",
                      min=-0.5, max=0.5)

    def __post_init__(self):
        _validated(self)

    @property
    def area_m2(self) -> float:
        """Cross-section S [m^2]."""
        return self.width_m * self.thickness_m

    @property
    def I_m4(self) -> float:
        """Second moment of area for in-plane bending [m^4]."""
        return self.thickness_m * self.width_m ** 3 / 12.0


@dataclass(frozen=True)
class InterfaceParams:
    """Stator tip / friction bar contact (paper Sect. 3.3, Eq. 17-20)."""

    k_e_N_per_m: float = p("N/m", "equivalent contact stiffness of the friction layer", min=1.0)
    mu_p: float = p("1", "dynamic (slip) friction coefficient", min=0.0)
    sigma_N_s_per_m: float = p("N.s/m", "viscous friction coefficient in the slip phase", min=0.0)
    u_m_m: float = p("m", "stick/slip threshold of relative displacement", min=0.0)

    def __post_init__(self):
        _validated(self)


@dataclass(frozen=True)
class SliderParams:
    """Slider on its linear guide (paper Sect. 3.4, Eq. 21-22)."""

    mass_kg: float = p("kg", "slider mass m_s", min=1e-6)
    c_r_N_s_per_m: float = p("N.s/m", "viscous damping of the guide", min=0.0)
    mu_sd: float = p("1", "dynamic friction coefficient of the guide", min=0.0)
    mu_ss: float = p("1", "static friction coefficient of the guide (>= mu_sd)", min=0.0)
    kappa: float = p("1", "share of F_p loading the guide (Eq. 22: 1, Eq. 29: 0.5)", min=0.0, max=1.0)
    s_min_m: float = p("m", "end stop at the negative end of the stroke")
    s_max_m: float = p("m", "end stop at the positive end of the stroke")
    load_inertia: float = p("1", "1 = the hanging load mass is accelerated with the slider, 0 = not",
                            min=0.0, max=1.0)
    pulley_mu: float = p("1", "Coulomb friction of the load path (pulley) per load weight g|m_load| (0 = off)",
                         min=0.0)

    def __post_init__(self):
        _validated(self)
        if self.s_max_m <= self.s_min_m:
            raise ParameterError(f"SliderParams: s_max_m ({self.s_max_m}) must exceed s_min_m ({self.s_min_m})")
        if self.mu_ss < self.mu_sd:
            raise ParameterError(f"SliderParams: mu_ss ({self.mu_ss}) must be >= mu_sd ({self.mu_sd})")


@dataclass(frozen=True)
class OperatingPoint:
    """Nominal drive of the reference rig (paper Sect. 5.1)."""

    V_s_V: float = p("V", "supply voltage of the H bridge", min=0.0)
    duty: float = p("1", "duty ratio of the PWM signal", min=0.0, max=1.0)
    f_drive_Hz: float = p("Hz", "drive (switching) frequency", min=1.0)
    T_degC: float = p("degC", "stator temperature")

    def __post_init__(self):
        _validated(self)


@dataclass(frozen=True)
class MotorParams:
    """The whole motor: one frozen dataclass per subsystem plus the nominal drive."""

    driver: DriverParams
    stator: StatorParams
    interface: InterfaceParams
    slider: SliderParams
    operating: OperatingPoint
    name: str = "motor"
    source: str = ""

    def replace(self, **changes) -> "MotorParams":
        """Return a copy with ``subsystem__field=value`` or whole-subsystem changes."""
        subs: dict[str, dict[str, Any]] = {}
        top: dict[str, Any] = {}
        for key, value in changes.items():
            if "__" in key:
                sub, name = key.split("__", 1)
                subs.setdefault(sub, {})[name] = value
            else:
                top[key] = value
        for sub, kv in subs.items():
            top[sub] = dataclasses.replace(getattr(self, sub), **kv)
        return dataclasses.replace(self, **top)


_SECTIONS = {
    "driver": DriverParams,
    "stator": StatorParams,
    "interface": InterfaceParams,
    "slider": SliderParams,
    "operating": OperatingPoint,
}


def describe(cls) -> list[dict[str, Any]]:
    """Name, unit, description, min and max of every field of a parameter dataclass."""
    return [
        {"name": f.name, **{k: f.metadata.get(k) for k in ("unit", "description", "min", "max")}}
        for f in dataclasses.fields(cls)
        if "unit" in f.metadata
    ]


def _build(cls, table: dict, path: Path, section: str):
    kwargs = {}
    declared = {f.name: f for f in dataclasses.fields(cls) if "unit" in f.metadata}
    for name in table:
        if name not in declared:
            given = table[name].get("unit") if isinstance(table[name], dict) else None
            raise ParameterError(f"{path}: [{section}] unknown parameter '{name}'"
                                 + (f" [{given}]" if given is not None else ""))
    for name, f in declared.items():
        unit = f.metadata["unit"]
        if name not in table:
            raise ParameterError(f"{path}: [{section}] missing parameter '{name}' [{unit}]")
        entry = table[name]
        if not isinstance(entry, dict) or "value" not in entry:
            raise ParameterError(
                f"{path}: [{section}] '{name}' [{unit}] must be an inline table with 'value' and 'unit'")
        if entry.get("unit") != unit:
            raise ParameterError(
                f"{path}: [{section}] '{name}' has unit '{entry.get('unit')}', expected '{unit}'")
        value = entry["value"]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{path}: [{section}] '{name}' [{unit}] value {value!r} is not a number")
        kwargs[name] = float(value)
    try:
        return cls(**kwargs)
    except ParameterError as exc:
        raise ParameterError(f"{path}: [{section}] {exc}") from None


def load_motor(path: str | Path | None = None) -> MotorParams:
    """Load a motor parameter set (default: the embedded reference motor).

    Raises
    ------
    ParameterError
        Naming the file, section, field and unit of the first problem.
    """
    path = Path(path) if path is not None else SYSTEM_MODELS_DIR / REFERENCE_MOTOR_FILE
    try:
        text = path.read_text()
    except OSError as exc:
        raise ParameterError(f"{path}: cannot read parameter file ({exc.strerror})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path}: not valid TOML ({exc})") from None
    parts = {}
    for section, cls in _SECTIONS.items():
        if section not in doc:
            raise ParameterError(f"{path}: missing section [{section}]")
        parts[section] = _build(cls, doc[section], path, section)
    meta = doc.get("meta", {})
    return MotorParams(**parts, name=str(meta.get("name", path.stem)), source=str(path))


def embedded_motors() -> list[str]:
    """Names of the motor files shipped in ``system_models/`` (``l1b2 rig --motor NAME``)."""
    return sorted(p.stem for p in SYSTEM_MODELS_DIR.glob("*.toml"))


def motor_file(name: str) -> Path:
    """Path of the embedded motor ``name`` (e.g. ``reference_motor``, ``realistic_motor``)."""
    path = SYSTEM_MODELS_DIR / f"{name}.toml"
    if not path.is_file():
        raise ParameterError(f"unknown motor '{name}'; embedded motors: {', '.join(embedded_motors())} "
                             f"(or give a parameter file with --params)")
    return path


def sources(path: str | Path | None = None) -> dict[str, dict[str, str]]:
    """The recorded reason for every value of a parameter file (``source`` keys)."""
    path = Path(path) if path is not None else SYSTEM_MODELS_DIR / REFERENCE_MOTOR_FILE
    doc = tomllib.loads(Path(path).read_text())
    return {
        sec: {k: v.get("source", "") for k, v in doc[sec].items() if isinstance(v, dict)}
        for sec in _SECTIONS
    }
