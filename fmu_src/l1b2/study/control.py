"""Control: the close-the-loop job on a world without any injected effect, seed by seed.

One seed runs the rig world (no injection), then
:func:`l1b2.closeloop.loop.close_loop` on TRAIN with TEST held out, in this
process (the study fans the seeds out, not the refits). The row holds the
held-out (TEST) free-run nrmse and 95th percentile of the absolute relative
error (``p95``) of the baseline and of the final model (the baseline's when
nothing was added), their ratio, and what was traced and added.
"""

from __future__ import annotations

import time

from ..closeloop.loop import close_loop
from .world import World, world_data

#: the issue's rule: the loop's held-out nrmse at most this much (relative) above the baseline's
CONTROL_TOLERANCE = 0.02


def control_one(seed: int, world: World = World(), settings: dict | None = None) -> dict:
    """One control seed: a flat row (see the module); ``settings``: :class:`l1b2.closeloop.loop.CloseLoop`'s."""
    t0 = time.perf_counter()
    train, test, _ = world_data(world, seed)
    res = close_loop(train, test, **(settings or {}))
    before = res.before["test"]["free_run"]
    after = res.after["test"]["free_run"] if res.after is not None else before
    d = res.diagnosis
    return {"study": "control", "seed": int(seed), "world": world.motor,
            "nrmse_before": float(before["nrmse"]), "nrmse_after": float(after["nrmse"]),
            "ratio": float(after["nrmse"] / before["nrmse"]),
            "p95_before": float(before["p95_abs_rel_error"]), "p95_after": float(after["p95_abs_rel_error"]),
            "within_tolerance": bool(after["nrmse"] <= (1 + CONTROL_TOLERANCE) * before["nrmse"]),
            "traced_to": ",".join(d["traced_to"]), "added": ",".join(e["label"] for e in d["effects"]),
            "loop_wall_s": float(res.wall_time_s), "wall_s": round(time.perf_counter() - t0, 2)}
