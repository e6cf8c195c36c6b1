"""Fan a study's seeds out through the parallel engine and collect the rows.

Every (case, seed) is one task of :func:`l1b2.cluster.run_tasks` (a Dask
client, or this process when ``client`` is None); the rows come back in
completion order and the result sorts them, so the result does not depend on
the number of workers.
"""

from __future__ import annotations

import time
from dataclasses import asdict

from ..cluster import run_tasks
from ..errors import L1B2Error
from .control import control_one
from .recovery import TARGETS, FitSettings, recover_one
from .result import StudyResult
from .world import World

STUDIES = ("coverage", "control")


class StudyError(L1B2Error):
    """A study cannot be set up (unknown study or injection, no seeds)."""


def study_tasks(study: str, seeds, world: World, injections=None, clean_fit: bool = True,
                fit: FitSettings = FitSettings(), loop_settings: dict | None = None) -> tuple:
    """``(function, [argument tuples])`` of every task of the study."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise StudyError("a study needs at least one seed")
    if study == "coverage":
        names = list(injections or TARGETS)
        unknown = [n for n in names if n not in TARGETS]
        if unknown:
            raise StudyError(f"no recovery target for injection(s) {', '.join(unknown)}; known: {', '.join(TARGETS)}")
        return recover_one, [(n, s, world, fit, clean_fit) for n in names for s in seeds]
    if study == "control":
        return control_one, [(s, world, loop_settings or {}) for s in seeds]
    raise StudyError(f"unknown study {study!r}; known: {', '.join(STUDIES)}")


def run_study(study: str, seeds, *, world: World = World(), injections=None, client=None, clean_fit: bool = True,
              fit: FitSettings = FitSettings(), loop_settings: dict | None = None, progress=None) -> StudyResult:
    """Run every task of the study (on ``client``, else here) and return the :class:`StudyResult`.

    ``progress``: called with each finished row (e.g. to print it).
    """
    fn, args = study_tasks(study, seeds, world, injections, clean_fit, fit, loop_settings)
    t0 = time.perf_counter()
    rows = []
    for _, row in run_tasks(fn, args, client=client, name=f"l1b2-study-{study}"):
        rows.append(row)
        if progress:
            progress(row)
    n_workers = len(client.nthreads()) if client is not None else 1
    settings = {"seeds": [int(s) for s in seeds], "world": world.to_dict(),
                "injections": list(injections or TARGETS) if study == "coverage" else [],
                "fit": asdict(fit) if study == "coverage" else None, "clean_fit": clean_fit,
                "loop_settings": loop_settings or {}}
    info = {"tasks": len(args), "workers": n_workers, "wall_time_s": round(time.perf_counter() - t0, 1),
            "task_seconds": round(sum(r["wall_s"] for r in rows), 1)}
    return StudyResult(study, rows, settings, info)
