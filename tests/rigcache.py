"""Rig experiments shared by several test modules (generated once per test session, in-process engine)."""

import tempfile
from pathlib import Path

from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment

_CACHE: dict = {}
_ROOT = Path(tempfile.mkdtemp(prefix="l1b2_rigcache_"))


#: the two worlds of the close-the-loop tests: the reference motor (Eq. 29 almost exact) and the
#: realistic variant (Eq. 29 not exact: Coulomb-dominated friction, V0-dependent load slope)
WORLDS = {"reference": None, "realistic": "realistic_motor.toml"}

#: each world's rig: the reference world's rig is noise-free (every run of the same conditions alike);
#: the realistic world's rig has a 1 mm/s white noise on the speed channel and a 2 % run-to-run scatter
#: of the contact's preload and friction coefficient (clean baseline held-out nrmse 3.45 -> 3.59 %,
#: seed 21), so that different seeds are different data, not only the same runs in another order
RIG_NOISE = {"reference": {}, "realistic": {"speed_noise_m_s": 1e-3, "run_scatter": 0.02}}


def world_plan(world: str, seed: int) -> RigPlan:
    """The paper's 72-run plan at a 1 ms step, run order and noise from ``seed``, with the world's rig noise."""
    return RigPlan(step_s=1e-3, seed=seed, **RIG_NOISE[world])


def rig_dir(name: str = "clean", injections=(), injection_seed=None, plan: RigPlan | None = None,
            world: str = "reference") -> Path:
    """Folder with all/train/test.csv of a rig experiment (the paper's 72-run plan by default).

    The runs are simulated in this process, one after the other: a local Dask cluster would give the same
    data (``run_experiment``'s contract, checked in ``test_sweep.py``) but its start-up costs about 20 times
    the CPU of the 72 runs themselves, and the test workers already use the machine's cores.
    """
    key = (name, tuple(injections), injection_seed, plan, world)
    if key not in _CACHE:
        plan = plan or RigPlan(step_s=1e-3)
        mp = load_motor(SYSTEM_MODELS_DIR / WORLDS[world]) if WORLDS[world] else load_motor()
        df, truth = run_experiment(plan, mp, injections=list(injections), engine="inprocess", workers=1,
                                   injection_seed=injection_seed)
        out = _ROOT / f"{name}_{len(_CACHE)}"
        write_experiment(df, out, mp, plan, truth)
        _CACHE[key] = out
    return _CACHE[key]


def case_row(world: str, case: str, res, b0: float | None = None) -> str:
    """One close-the-loop case as a JSON line: what a closing note's table needs.

    Recorded by the close-loop tests with ``record_property("case", ...)``;
    ``pytest --junitxml=FILE`` keeps them (``python bench/case_table.py FILE`` prints the table).
    """
    import json
    d = res.diagnosis
    b, a = held_out_nrmse(res)
    return json.dumps({"world": world, "case": case, "traced_to": d["traced_to"],
                       "added": [e["label"] for e in d["effects"]], "before": b, "after": a, "b0": b0,
                       "wall_s": res.wall_time_s, "channels": channels_summary(d.get("channels_considered") or [])})


def channels_summary(considered: list[dict]) -> dict:
    """What the loop considered beyond its fixed regressors, from ``diagnosis.channels_considered``.

    ``channels``: the logged and protocol channels that were candidates (rows of kind ``"response"`` are
    listed by the loop but are not candidates); ``run_signals``: the run-level signals tested (each
    channel's run mean and the model's inputs, one per row of ``run_level``); ``significant``: the channels
    that passed the within-run screen, by name (an input row's ``significant`` is its run-level evidence), then the run-level signals that passed theirs, as
    ``"<signal> (run)"``.
    """
    rows = [c for c in considered if c["kind"] != "response"]
    runl = [e for c in rows for e in c.get("run_level") or []]
    sig = [c["channel"] for c in rows if c["significant"] and c["kind"] != "input"]  # an input's is its run level
    sig += [f"{e['signal']} (run)" for e in runl if e["significant"]]
    return {"channels": sum(c["kind"] != "input" for c in rows), "run_signals": len(runl), "significant": sig}


def held_out_nrmse(res) -> tuple[float, float]:
    """TEST free-run nrmse of a close-loop result, ``(baseline, final)`` (final = baseline if nothing was added)."""
    b = res.before["test"]["free_run"]["nrmse"]
    a = res.after["test"]["free_run"]["nrmse"] if res.after is not None else b
    return b, a


def assert_round_trips(res) -> None:
    """``report.json`` of a close-loop result reads back into an equal result (``from_dict(to_dict(r)) == r``)."""
    import json

    from l1b2.closeloop.result import CloseLoopResult
    rep = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    back = CloseLoopResult.from_dict(rep)
    assert back == res and back.to_dict() == rep
