"""The study specification (``l1b2 sweep --spec study.toml``): parsed, checked, frozen.

A study is a grid of operating points times a design over motor parameters::

    [study]
    name = "tolerances at 220 V, 0.05 kg"
    seed = 1
    engine = "inprocess"           # or "fmu" (the four FMUs through the fmpy master)
    design = "montecarlo"          # "montecarlo", "saltelli" (Sobol indices) or "grid" (nominal motor only)
    draws = 200                    # Monte-Carlo draws (saltelli: base sample N, N * (d + 2) runs)
    chunk_size = 10                # samples per task and per stored chunk

    [simulation]
    step_s = { value = 1e-3, unit = "s" }
    max_time_s = { value = 4.0, unit = "s" }

    [operating_points]             # every combination is an operating point
    V0 = { values = [220.0], unit = "V" }
    load = { values = [0.05], unit = "kg" }
    direction = { values = [1], unit = "1" }
    frequency = { values = [48500.0], unit = "Hz" }
    temperature = { values = [25.0], unit = "degC" }

    [parameters]                   # drawn parameters, by their SSV / TOML name
    "Stator.P0_N" = { distribution = "normal", mean = 6.35, sd = 0.2, bounds = [5.5, 7.2], unit = "N" }
    "Interface.mu_p" = { distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }
    "Slider.mass_kg" = { distribution = "lognormal", median = 0.1, sigma = 0.05, unit = "kg" }

    [fixed]                        # values set for every sample
    "Slider.pulley_mu" = { value = 0.0, unit = "1" }

    [outputs]
    mean_speed = { middle = 0.5 }              # over the middle half of the stroke
    speed_at = { positions = [-0.01, 0.0, 0.01], unit = "m" }
    traverse_time = true
    stall = true

Parameters are named ``Component.field`` as in the SSVs (``Interface.mu_p``)
or ``section.field`` as in the motor TOML (``interface.mu_p``); the field and
its unit are those of :func:`l1b2.physics.params.describe`. Every value states
its unit, which must be the parameter's; bounds must lie inside the
parameter's declared range (normal and log-normal draws are truncated to
the bounds, by default to that range). Anything else is refused with a
:class:`l1b2.errors.SpecError` naming the key.

Pure: :func:`parse_spec` takes the TOML text; reading files is the caller's.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field

from ..cosim.ssp import COMPONENT_PARAMS
from ..errors import SpecError
from ..physics.params import DriverParams, InterfaceParams, MotorParams, SliderParams, StatorParams, describe

ENGINES = ("inprocess", "fmu")
DESIGNS = ("montecarlo", "saltelli", "grid")
DISTRIBUTIONS = {"normal": ("mean", "sd"), "uniform": ("low", "high"), "lognormal": ("median", "sigma")}

#: operating-point variables: spec key -> (column of the results, unit)
OPERATING = {"V0": ("V0_V", "V"), "load": ("load_kg", "kg"), "direction": ("direction", "1"),
             "frequency": ("frequency_Hz", "Hz"), "temperature": ("temperature_degC", "degC")}
#: outputs a study can ask for (``stall`` is a flag, the others are numbers)
OUTPUT_NAMES = ("mean_speed", "speed_at", "traverse_time", "stall")
_PARAM_CLASSES = {"driver": DriverParams, "stator": StatorParams, "interface": InterfaceParams,
                  "slider": SliderParams}


@dataclass(frozen=True)
class ParameterDraw:
    """One drawn parameter: distribution ``kind`` with parameters ``a``, ``b``, truncated to [low, high]."""

    name: str          # canonical "Component.field"
    kind: str          # normal | uniform | lognormal
    a: float           # normal: mean, uniform: low, lognormal: median
    b: float           # normal: sd,   uniform: high, lognormal: sigma (sd of ln x)
    low: float
    high: float
    unit: str


@dataclass(frozen=True)
class StudySpec:
    """A checked study specification (see the module docstring for the TOML form)."""

    name: str
    seed: int
    engine: str
    design: str
    draws: int
    chunk_size: int
    step_s: float
    max_time_s: float
    operating: dict                      # spec key -> tuple of values (see OPERATING)
    parameters: tuple                    # ParameterDraw, in spec order
    fixed: dict = field(default_factory=dict)  # "Component.field" -> value
    outputs: tuple = OUTPUT_NAMES
    middle: float = 0.5
    positions_m: tuple = ()
    motor: str | None = None             # motor TOML path as written in the spec (relative to it)

    def operating_points(self) -> list[dict]:
        """Every combination of the operating-point values, as ``{column: value}``, in spec order."""
        keys = list(OPERATING)
        return [{OPERATING[k][0]: v for k, v in zip(keys, combo)}
                for combo in itertools.product(*(self.operating[k] for k in keys))]

    def fingerprint(self) -> str:
        """Hash of everything that decides the samples and their results (not the number of workers)."""
        doc = dataclasses.asdict(self)
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


# ---------------------------------------------------------------------------
# parsing
# ---------------------------------------------------------------------------

def _fail(source: str, key: str, problem: str):
    raise SpecError(f"{source}: {key}: {problem}")


def _known_keys(source: str, prefix: str, table: dict, allowed) -> None:
    for k in table:
        if k not in allowed:
            _fail(source, f"{prefix}.{k}" if prefix else k,
                  f"unknown key (expected one of {', '.join(allowed)})")


def _number(source: str, key: str, value, *, integer=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(source, key, f"expected a finite number, got {value!r}")
    if integer and value != int(value):
        _fail(source, key, f"expected an integer, got {value!r}")
    return int(value) if integer else float(value)


def _quantity(source: str, key: str, entry, unit: str) -> float:
    """``{ value = x, unit = "u" }`` with the expected unit."""
    if not isinstance(entry, dict) or "value" not in entry:
        _fail(source, key, f"expected {{ value = ..., unit = \"{unit}\" }}")
    _known_keys(source, key, entry, ("value", "unit"))
    _unit(source, key, entry, unit)
    return _number(source, f"{key}.value", entry["value"])


def _unit(source: str, key: str, entry: dict, unit: str, whose: str = "the expected unit") -> None:
    if "unit" not in entry:
        _fail(source, key, f"missing 'unit' (expected \"{unit}\")")
    if entry["unit"] != unit:
        _fail(source, key, f"unit '{entry['unit']}' does not match {whose} '{unit}'")


def resolve_parameter(name: str) -> tuple[str, str, dict]:
    """``"Interface.mu_p"`` or ``"interface.mu_p"`` -> (canonical name, MotorParams attribute, describe() row).

    Raises ``KeyError`` with the problem in words when there is no such parameter.
    """
    comp, dot, fname = name.partition(".")
    by_lower = {c.lower(): c for c in COMPONENT_PARAMS}
    if not dot or comp.lower() not in by_lower:
        if comp.lower() == "operating":
            raise KeyError("operating-point values go in [operating_points] (V0, load, direction, frequency, "
                           "temperature)")
        raise KeyError(f"unknown parameter (name it Component.field with Component one of "
                       f"{', '.join(COMPONENT_PARAMS)})")
    comp = by_lower[comp.lower()]
    attr = COMPONENT_PARAMS[comp]
    rows = {d["name"]: d for d in describe(_PARAM_CLASSES[attr])}
    if fname not in rows:
        raise KeyError(f"unknown parameter; {comp} has {', '.join(rows)}")
    return f"{comp}.{fname}", attr, rows[fname]


def _flatten_parameters(table: dict, prefix: str = "") -> dict:
    """``[parameters.Interface.mu_p]`` (nested) and ``"Interface.mu_p" = {...}`` (quoted) alike."""
    out = {}
    for k, v in table.items():
        name = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict) and not ({"distribution", "value", "unit"} & set(v)) and all(
                isinstance(x, dict) for x in v.values()):
            out.update(_flatten_parameters(v, name))
        else:
            out[name] = v
    return out


def _check_range(source: str, key: str, value: float, row: dict, what: str) -> None:
    lo, hi = row.get("min"), row.get("max")
    if lo is not None and value < lo:
        _fail(source, key, f"{what} {value:g} [{row['unit']}] is below the parameter's declared minimum {lo:g}")
    if hi is not None and value > hi:
        _fail(source, key, f"{what} {value:g} [{row['unit']}] is above the parameter's declared maximum {hi:g}")


def _parse_draw(source: str, name: str, entry, nominal: MotorParams) -> ParameterDraw:
    key = f"parameters.{name}"
    try:
        canonical, attr, row = resolve_parameter(name)
    except KeyError as exc:
        _fail(source, key, exc.args[0])
    if not isinstance(entry, dict):
        _fail(source, key, "expected an inline table { distribution = ..., unit = ..., ... }")
    kind = entry.get("distribution")
    if kind not in DISTRIBUTIONS:
        _fail(source, f"{key}.distribution", f"expected one of {', '.join(DISTRIBUTIONS)}, got {kind!r}")
    pa, pb = DISTRIBUTIONS[kind]
    _known_keys(source, key, entry, ("distribution", "unit", "bounds", pa, pb))
    _unit(source, key, entry, row["unit"], "the parameter's unit")
    nominal_value = float(getattr(getattr(nominal, attr), row["name"]))
    if pa not in entry and kind != "uniform":
        entry = {**entry, pa: nominal_value}
    for p in (pa, pb):
        if p not in entry:
            _fail(source, f"{key}.{p}", f"missing (a {kind} distribution needs {pa} and {pb})")
    a = _number(source, f"{key}.{pa}", entry[pa])
    b = _number(source, f"{key}.{pb}", entry[pb])
    if kind == "uniform" and not b > a:
        _fail(source, key, f"high ({b:g}) must exceed low ({a:g})")
    if kind in ("normal", "lognormal") and not b > 0:
        _fail(source, f"{key}.{pb}", f"must be positive, got {b:g}")
    if kind == "lognormal" and not a > 0:
        _fail(source, f"{key}.{pa}", f"the median of a log-normal must be positive, got {a:g}")
    low = row["min"] if row["min"] is not None else -math.inf
    high = row["max"] if row["max"] is not None else math.inf
    if kind == "uniform":
        low, high = a, b
    if "bounds" in entry:
        bnd = entry["bounds"]
        if not isinstance(bnd, list) or len(bnd) != 2:
            _fail(source, f"{key}.bounds", f"expected [low, high], got {bnd!r}")
        low = _number(source, f"{key}.bounds", bnd[0])
        high = _number(source, f"{key}.bounds", bnd[1])
        if not high > low:
            _fail(source, f"{key}.bounds", f"high ({high:g}) must exceed low ({low:g})")
    if kind == "lognormal":
        low = max(low, 0.0)
    for what, v in (("lower bound", low), ("upper bound", high)):
        if math.isfinite(v):
            _check_range(source, f"{key}.bounds" if "bounds" in entry else key, v, row, what)
    centre = a if kind != "uniform" else 0.5 * (a + b)
    if not low <= centre <= high:
        _fail(source, f"{key}.{pa}", f"{centre:g} lies outside the bounds [{low:g}, {high:g}]")
    return ParameterDraw(canonical, kind, a, b, float(low), float(high), row["unit"])


def _parse_operating(source: str, table: dict, nominal: MotorParams) -> dict:
    _known_keys(source, "operating_points", table, tuple(OPERATING))
    defaults = {"direction": (1.0,), "frequency": (nominal.operating.f_drive_Hz,),
                "temperature": (nominal.operating.T_degC,)}
    out = {}
    for k, (_, unit) in OPERATING.items():
        key = f"operating_points.{k}"
        if k not in table:
            if k not in defaults:
                _fail(source, key, f"missing (give {{ values = [...], unit = \"{unit}\" }})")
            out[k] = defaults[k]
            continue
        entry = table[k]
        if not isinstance(entry, dict) or "values" not in entry:
            _fail(source, key, f"expected {{ values = [...], unit = \"{unit}\" }}")
        _known_keys(source, key, entry, ("values", "unit"))
        _unit(source, key, entry, unit)
        vals = entry["values"] if isinstance(entry["values"], list) else [entry["values"]]
        if not vals:
            _fail(source, f"{key}.values", "empty list")
        out[k] = tuple(_number(source, f"{key}.values", v) for v in vals)
    if any(d not in (1.0, -1.0) for d in out["direction"]):
        _fail(source, "operating_points.direction.values", f"directions are +1 or -1, got {list(out['direction'])}")
    if any(v < 0 for v in out["V0"]):
        _fail(source, "operating_points.V0.values", "V0 is an amplitude and cannot be negative")
    if any(f <= 0 for f in out["frequency"]):
        _fail(source, "operating_points.frequency.values", "the drive frequency must be positive")
    for k, (lo, hi) in OPERATING_RANGE.items():
        bad = next((v for v in out[k] if not lo <= v <= hi), None)
        if bad is not None:
            _fail(source, f"operating_points.{k}.values", f"{bad:g} {OPERATING[k][1]} is outside the range a linear "
                  f"USM rig has [{lo:g}, {hi:g}] {OPERATING[k][1]}: a unit mistake?")
    if _n_operating(out) > DEFAULT_MAX_RUNS:
        _fail(source, "operating_points", f"{_n_operating(out)} operating points (every combination of the values), "
              f"more than {DEFAULT_MAX_RUNS}")
    return out


def _parse_outputs(source: str, table) -> tuple[tuple, float, tuple]:
    if not isinstance(table, dict):
        _fail(source, "outputs", "expected a table")
    _known_keys(source, "outputs", table, OUTPUT_NAMES)
    names, middle, positions = [], 0.5, ()
    for name, entry in table.items():
        key = f"outputs.{name}"
        if entry is False:
            continue
        if name == "mean_speed" and isinstance(entry, dict):
            _known_keys(source, key, entry, ("middle",))
            middle = _number(source, f"{key}.middle", entry.get("middle", 0.5))
            if not 0 < middle <= 1:
                _fail(source, f"{key}.middle", f"a fraction of the stroke in (0, 1], got {middle:g}")
        elif name == "speed_at":
            if not isinstance(entry, dict) or "positions" not in entry:
                _fail(source, key, "expected { positions = [...], unit = \"m\" }")
            _known_keys(source, key, entry, ("positions", "unit"))
            _unit(source, key, entry, "m")
            positions = tuple(_number(source, f"{key}.positions", p) for p in entry["positions"])
            if not positions:
                continue
        elif entry is not True:
            _fail(source, key, f"expected true/false{' or { middle = ... }' if name == 'mean_speed' else ''}")
        names.append(name)
    if not names:
        _fail(source, "outputs", "no output asked for")
    return tuple(n for n in OUTPUT_NAMES if n in names), middle, positions


#: longest study specification read [characters]
MAX_SPEC_CHARS = 1_000_000


def _load_toml(text: str, source: str) -> dict:
    if len(text) > MAX_SPEC_CHARS:
        raise SpecError(f"{source}: {len(text)} characters, more than {MAX_SPEC_CHARS}: not a study specification?")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{source}: not valid TOML ({exc})") from None
    except RecursionError:
        raise SpecError(f"{source}: tables or arrays nested too deeply to be a study specification") from None


#: runs (samples x operating points) a study may have unless the user raises the limit (l1b2 sweep --max-runs)
DEFAULT_MAX_RUNS = 100_000
#: most simulation steps of one run (max_time_s / step_s): bounds each run's time and memory
MAX_STEPS_PER_RUN = 100_000
#: wall time of one simulated step by engine [s], for the estimate before a study starts (order of magnitude,
#: bench/bench_sweep.py measures the real figure)
STEP_COST_S = {"inprocess": 3e-5, "fmu": 3e-4}
#: operating-point values outside these are refused (a linear USM rig's range, as the measured-data checks)
OPERATING_RANGE = {"V0": (0.0, 1000.0), "load": (-2.0, 2.0), "frequency": (15e3, 1e6), "temperature": (-60.0, 150.0)}


def study_size(design: str, draws: int, n_parameters: int, n_operating: int, step_s: float,
               max_time_s: float, engine: str) -> dict:
    """Runs, steps per run and the worst-case CPU time [h] of a study, before anything is drawn or run.

    Samples: ``draws`` (Monte Carlo), ``draws * (d + 2)`` (Saltelli with ``d``
    parameters) or 1 (grid); runs = samples x operating points; every run
    takes at most ``max_time_s / step_s`` steps.
    """
    samples = 1 if design == "grid" else draws * (n_parameters + 2) if design == "saltelli" else draws
    steps = int(math.ceil(max_time_s / step_s))
    runs = samples * n_operating
    return {"samples": samples, "runs": runs, "steps_per_run": steps,
            "cpu_hours": runs * steps * STEP_COST_S.get(engine, STEP_COST_S["fmu"]) / 3600.0}


def check_size(spec: "StudySpec", max_runs: int = DEFAULT_MAX_RUNS, source: str = "study.toml") -> dict:
    """:func:`study_size` of ``spec``; :class:`SpecError` when it has more than ``max_runs`` runs."""
    size = study_size(spec.design, spec.draws, len(spec.parameters), _n_operating(spec.operating), spec.step_s,
                      spec.max_time_s, spec.engine)
    if size["runs"] > max_runs:
        raise SpecError(f"{source}: study.draws: the study has {size['runs']:.3g} runs ({size['samples']:.3g} samples "
                        f"x {_n_operating(spec.operating)} operating points, up to {size['cpu_hours']:.3g} CPU hours), "
                        f"more than the limit {max_runs}: reduce it, or raise the limit with --max-runs")
    return size


def _n_operating(operating: dict) -> int:
    return math.prod(len(v) for v in operating.values())


def parse_spec(text: str, source: str = "study.toml", nominal: MotorParams | None = None) -> StudySpec:
    """Parse and check a study specification (TOML text); ``nominal`` is the motor it varies.

    Raises
    ------
    SpecError
        ``"<source>: <key>: <problem>"`` for the first problem found.
    """
    from ..physics.params import load_motor
    doc = _load_toml(text, source)
    _known_keys(source, "", doc, ("study", "simulation", "operating_points", "parameters", "fixed", "outputs"))
    study = doc.get("study", {})
    _known_keys(source, "study", study, ("name", "seed", "engine", "design", "draws", "chunk_size", "motor"))
    nominal = nominal or load_motor()
    engine = study.get("engine", "inprocess")
    if engine not in ENGINES:
        _fail(source, "study.engine", f"expected one of {', '.join(ENGINES)}, got {engine!r}")
    design = study.get("design", "montecarlo")
    if design not in DESIGNS:
        _fail(source, "study.design", f"expected one of {', '.join(DESIGNS)}, got {design!r}")
    seed = _number(source, "study.seed", study.get("seed", 0), integer=True)
    draws = _number(source, "study.draws", study.get("draws", 1 if design == "grid" else 100), integer=True)
    chunk = _number(source, "study.chunk_size", study.get("chunk_size", 10), integer=True)
    if draws < 1 or chunk < 1 or seed < 0:
        bad = "study.draws" if draws < 1 else "study.chunk_size" if chunk < 1 else "study.seed"
        _fail(source, bad, "must be positive")
    sim = doc.get("simulation", {})
    _known_keys(source, "simulation", sim, ("step_s", "max_time_s"))
    step = _quantity(source, "simulation.step_s", sim["step_s"], "s") if "step_s" in sim else 1e-3
    t_max = _quantity(source, "simulation.max_time_s", sim["max_time_s"], "s") if "max_time_s" in sim else 4.0
    if not (0 < step <= 1e-3 and t_max > step):
        _fail(source, "simulation.step_s" if not 0 < step <= 1e-3 else "simulation.max_time_s",
              "need 0 < step_s <= 1e-3 s (the coupling's stability limit) and max_time_s > step_s")
    if t_max / step > MAX_STEPS_PER_RUN:
        _fail(source, "simulation.max_time_s", f"{t_max:g} s at step_s {step:g} s is {t_max / step:.3g} steps per run, "
              f"more than {MAX_STEPS_PER_RUN} (a traverse takes seconds; a stalled motor would run and grow to the "
              "end): give a shorter max_time_s")
    if "operating_points" not in doc:
        _fail(source, "operating_points", "missing (at least V0 and load)")
    operating = _parse_operating(source, doc["operating_points"], nominal)
    params = tuple(_parse_draw(source, k, v, nominal)
                   for k, v in _flatten_parameters(doc.get("parameters", {})).items())
    names = [p.name for p in params]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        _fail(source, f"parameters.{dup}", "given twice (Component.field and section.field name one parameter)")
    if design != "grid" and not params:
        _fail(source, "parameters", f"design '{design}' draws parameters but none is given (or use design = \"grid\")")
    if design == "grid" and params:
        _fail(source, "study.design", "'grid' runs the nominal motor only; remove [parameters] or use montecarlo")
    if design == "saltelli" and len(params) < 2:
        _fail(source, "parameters", "a Saltelli design needs at least two drawn parameters")
    fixed = {}
    for k, v in _flatten_parameters(doc.get("fixed", {})).items():
        try:
            canonical, _, row = resolve_parameter(k)
        except KeyError as exc:
            _fail(source, f"fixed.{k}", exc.args[0])
        if canonical in names:
            _fail(source, f"fixed.{k}", "also drawn in [parameters]")
        fixed[canonical] = _quantity(source, f"fixed.{k}", v, row["unit"])
        _check_range(source, f"fixed.{k}", fixed[canonical], row, "value")
    outputs, middle, positions = _parse_outputs(source, doc.get("outputs", {n: True for n in OUTPUT_NAMES if n != "speed_at"}))
    motor = study.get("motor")
    if motor is not None and not isinstance(motor, str):
        _fail(source, "study.motor", "expected the path of a motor TOML file")
    return StudySpec(name=str(study.get("name", source)), seed=seed, engine=engine, design=design,
                     draws=1 if design == "grid" else draws, chunk_size=chunk, step_s=step, max_time_s=t_max,
                     operating=operating, parameters=params, fixed=fixed, outputs=outputs, middle=middle,
                     positions_m=positions, motor=motor)


def motor_reference(text: str, source: str = "study.toml") -> str | None:
    """The ``study.motor`` path as written in the spec (``None``: the reference motor), read before parsing.

    The motor decides the defaults and ranges :func:`parse_spec` checks against,
    so the caller loads it first.
    """
    motor = _load_toml(text, source).get("study", {}).get("motor")
    if motor is not None and not isinstance(motor, str):
        _fail(source, "study.motor", "expected the path of a motor TOML file")
    return motor
