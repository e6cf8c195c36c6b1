"""What a worker does: co-simulate the traverses of one chunk of samples and reduce each to its outputs.

A sample is one traverse of the stroke from rest at the end stop behind to
the far one (:func:`l1b2.rig.experiment.simulate_traverse`, the rig's
traverse without the encoder) with the sample's parameters applied to the
study's motor. Outputs, all in the direction of travel:

``mean_speed_m_s``
    the stroke's middle ``middle`` fraction divided by the time taken to
    cross it (0 when the slider does not get across);
``speed_at_<p>mm_m_s``
    the slider speed when it first passes position p (0 when it never gets
    there, NaN when p lies outside the stroke);
``traverse_time_s``
    time from rest to the far end stop, interpolated within the step (NaN
    when it does not get there);
``stalled``
    the slider did not reach the far end stop within ``max_time_s``.

A sample whose simulation raises is recorded with ``status = "failed"`` and
the message in ``error`` (outputs NaN); the other samples of its chunk go on.

With the FMU engine, the FMU folder comes from the coordinating process
(``fmu_dir``); a worker that does not see it (another machine) builds the
FMUs once into its own per-user cache. Each worker process extracts every
FMU once and reuses it for all its traverses (:func:`l1b2.cosim.master.extracted`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..physics.params import MotorParams
from ..rig.experiment import RigPlan, RunSpec, apply_overrides, simulate_traverse
from .spec import StudySpec


@dataclass(frozen=True)
class TaskContext:
    """Everything a worker needs besides the samples (small, picklable)."""

    motor: MotorParams            # the study's motor with the [fixed] values applied
    engine: str
    fmu_dir: str | None
    step_s: float
    max_time_s: float
    outputs: tuple
    middle: float
    positions_m: tuple
    parameters: tuple             # names of the drawn parameters ("Component.field")

    @classmethod
    def from_spec(cls, spec: StudySpec, motor: MotorParams, fmu_dir=None) -> "TaskContext":
        return cls(apply_overrides(motor, spec.fixed), spec.engine, None if fmu_dir is None else str(fmu_dir),
                   spec.step_s, spec.max_time_s, spec.outputs, spec.middle, spec.positions_m,
                   tuple(p.name for p in spec.parameters))


def speed_column(position_m: float) -> str:
    """Column of the speed at a position: ``speed_at_+10mm_m_s``."""
    return f"speed_at_{position_m * 1e3:+g}mm_m_s"


def output_columns(ctx: TaskContext) -> dict[str, str]:
    """Output columns of a study and their units, in order."""
    cols = {}
    for name in ctx.outputs:
        if name == "mean_speed":
            cols["mean_speed_m_s"] = "m/s"
        elif name == "speed_at":
            cols.update({speed_column(p): "m/s" for p in ctx.positions_m})
        elif name == "traverse_time":
            cols["traverse_time_s"] = "s"
        elif name == "stall":
            cols["stalled"] = "1"
    return cols


def simulate_sample(sample: dict, motor: MotorParams, ctx: TaskContext) -> dict:
    """The co-simulated traverse of one sample (``motor`` has the sample's parameters)."""
    plan = RigPlan(f_drive_Hz=float(sample["frequency_Hz"]), ambient_degC=float(sample["temperature_degC"]),
                   step_s=ctx.step_s, max_run_s=ctx.max_time_s)
    spec = RunSpec(int(sample["sample_id"]), float(sample["V0_V"]), float(sample["load_kg"]),
                   int(sample["direction"]))
    return simulate_traverse(motor, spec, plan, ctx.engine, ctx.fmu_dir, nominal=ctx.motor)


def _first_crossing(x: np.ndarray, t: np.ndarray, target: float) -> float | None:
    """Index (fractional) where ``x`` first reaches ``target``; None if it never does."""
    hit = np.nonzero(x >= target - 1e-12)[0]
    if not len(hit):
        return None
    k = int(hit[0])
    if k == 0 or x[k] == x[k - 1]:
        return float(k)
    return k - 1 + (target - x[k - 1]) / (x[k] - x[k - 1])


def _at(y: np.ndarray, k: float) -> float:
    i = int(np.floor(k))
    if i + 1 >= len(y):
        return float(y[-1])
    return float(y[i] + (k - i) * (y[i + 1] - y[i]))


def traverse_outputs(r: dict, motor: MotorParams, direction: int, ctx: TaskContext) -> dict:
    """The outputs of one traverse (see the module docstring)."""
    t, s, v = (np.asarray(r[k], dtype=float) for k in ("time", "Slider.s", "Slider.v"))
    sl = motor.slider
    s_start = sl.s_min_m if direction > 0 else sl.s_max_m
    stroke = sl.s_max_m - sl.s_min_m
    x = (s - s_start) * direction           # distance travelled from the start stop
    reached = float(np.asarray(r["Slider.at_stop"])[-1]) == float(direction)
    out = {}
    if "mean_speed" in ctx.outputs:
        xa, xb = 0.5 * stroke * (1 - ctx.middle), 0.5 * stroke * (1 + ctx.middle)
        ka, kb = _first_crossing(x, t, xa), _first_crossing(x, t, xb)
        out["mean_speed_m_s"] = (xb - xa) / (_at(t, kb) - _at(t, ka)) if ka is not None and kb is not None \
            and _at(t, kb) > _at(t, ka) else 0.0
    if "speed_at" in ctx.outputs:
        for p in ctx.positions_m:
            xp = (p - s_start) * direction
            k = _first_crossing(x, t, xp) if 0 <= xp <= stroke else None
            out[speed_column(p)] = (np.nan if not 0 <= xp <= stroke
                                    else 0.0 if k is None else _at(v, k) * direction)
    if "traverse_time" in ctx.outputs:
        k = _first_crossing(x, t, stroke) if reached else None
        out["traverse_time_s"] = _at(t, k) if k is not None else float(t[-1]) if reached else np.nan
    if "stall" in ctx.outputs:
        out["stalled"] = not reached
    return out


def run_sample(sample: dict, ctx: TaskContext, traverse: Callable | None = None) -> dict:
    """Outputs, ``status`` and ``error`` of one sample; an exception of its simulation marks it failed."""
    traverse = traverse or simulate_sample
    try:
        motor = apply_overrides(ctx.motor, {k: float(sample[k]) for k in ctx.parameters})
        r = traverse(sample, motor, ctx)
        out = traverse_outputs(r, motor, int(sample["direction"]), ctx)
        out.update(status="ok", error="")
    except Exception as exc:  # noqa: BLE001 - any failure of one sample is recorded, the study goes on
        out = {c: (None if c == "stalled" else np.nan) for c in output_columns(ctx)}
        out.update(status="failed", error=f"{type(exc).__name__}: {exc}".splitlines()[0][:500])
    return {"sample_id": int(sample["sample_id"]), **out}


def run_chunk(chunk_id: int, samples: list[dict], ctx: TaskContext, traverse: Callable | None = None) -> tuple:
    """``(chunk_id, [result rows])`` for a chunk of samples (runs on a worker)."""
    return chunk_id, [run_sample(s, ctx, traverse) for s in samples]
