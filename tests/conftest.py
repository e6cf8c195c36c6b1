"""Shared fixtures of the physics / FMU test suite.

* ``motor``: the embedded reference motor (``l1b2.physics.params.load_motor()``).
* ``fmus`` / ``fmu_dir``: the four subsystem FMUs, built ONCE per session into
  a temporary folder with :func:`l1b2.fmi.build.build_subsystem_fmus`.
* ``isolated``: run a module-level worker function of a test file in a fresh
  Python process and return its JSON result.  Every test that *instantiates*
  a PythonFMU FMU uses it: PythonFMU's native loader keeps process-wide state
  (the slave module stays in ``sys.modules``), so one crashing or leaking
  instantiation must not take the whole pytest session down, and each test
  sees a clean process, the way a simulation tool would load the FMU.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from l1b2.physics.params import load_motor

REPO = Path(__file__).resolve().parents[1]
_RESULT_TAG = "@@L1B2-RESULT@@"

_RUNNER = f"""
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("_l1b2_isolated_worker", sys.argv[1])
mod = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mod)
result = getattr(mod, sys.argv[2])(*json.loads(sys.argv[3]))
sys.stdout.flush()
print({_RESULT_TAG!r} + json.dumps(result), flush=True)
"""


#: The test modules that cost the most CPU in ``make test``, the most expensive first (measured per module,
#: decision 0030). ``make test`` hands whole modules to its two workers (pytest-xdist ``--dist loadscope``
#: with ``--no-loadscope-reorder``) in the collection order, which this list sets: the long modules start
#: first and the short ones, in their usual order after them, fill the gaps, so that both workers finish at
#: about the same time. (xdist's own order, by number of tests, started the few long close-loop modules last.)
COSTLY_FIRST = (
    "test_closeloop_realistic.py",  # two realistic-world control close loops, thirteen injected cases (ci_slow)
    "test_closeloop_realistic_controls.py",  # ten realistic control seeds, the CLI's report of one case (ci_slow)
    "test_closeloop.py",  # reference-world close loops, their exports
    "test_closeloop_channels.py",  # one realistic close loop with two logged channels (ci_slow)
    "test_readme_examples.py",  # the pages' commands: rig, identify, close loop, export
    "test_extended_predictor_fmu.py",  # native FMUs compiled per effect kind, FMI 2.0 and 3.0
    "test_export.py",
    "test_fmus.py",
    "test_tutorial.py",  # the tutorial end to end (one ~60 s test, else handed out among the last modules)
    "test_identify.py",
    "test_closeloop_chain.py",  # one reference-world close loop
    "test_chost.py",
    "test_sweep.py",
    "test_fmu_misuse.py",
    "test_effect_plugin.py",  # one close loop with the toy family, its export
    "test_interface.py",
    "test_output_dirs.py",
    "test_identify_workflow.py",
    "test_hostile_inputs.py",
)


def pytest_collection_modifyitems(config, items):
    """Collection order: the modules of :data:`COSTLY_FIRST` first, in its order; each module's tests and the
    other modules keep their order (a stable sort)."""
    rank = {name: i for i, name in enumerate(COSTLY_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="session")
def motor():
    return load_motor()


@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """The four subsystem FMUs of the reference motor, built once per session."""
    from l1b2.fmi.build import build_subsystem_fmus

    dest = tmp_path_factory.mktemp("fmus")
    return {name: Path(p) for name, p in build_subsystem_fmus(dest).items()}


@pytest.fixture(scope="session")
def fmu_dir(fmus) -> Path:
    folders = {p.parent for p in fmus.values()}
    assert len(folders) == 1
    return folders.pop()


@dataclass
class IsolatedResult:
    value: object
    stdout: str
    stderr: str
    returncode: int


def _run_isolated(module_file, func_name, *args, timeout=300, check=True) -> IsolatedResult:
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("MPLBACKEND", "Agg")
    proc = subprocess.run(
        [sys.executable, "-c", _RUNNER, str(module_file), func_name, json.dumps(list(args))],
        capture_output=True, text=True, timeout=timeout, cwd=str(REPO), env=env,
    )
    value = None
    for line in proc.stdout.splitlines():
        if line.startswith(_RESULT_TAG):
            value = json.loads(line[len(_RESULT_TAG):])
    res = IsolatedResult(value, proc.stdout, proc.stderr, proc.returncode)
    if check and (proc.returncode != 0 or value is None):
        raise AssertionError(
            f"isolated worker {func_name} exited with code {proc.returncode}"
            f" (negative = killed by signal, -11 = segmentation fault)\n"
            f"--- stdout (tail) ---\n{proc.stdout[-3000:]}\n--- stderr (tail) ---\n{proc.stderr[-3000:]}")
    return res


@pytest.fixture(scope="session")
def isolated():
    """``isolated(__file__, "worker", *json_args, check=True) -> IsolatedResult``."""
    return _run_isolated


# ---------------------------------------------------------------------------
# Export (l1b2.fmi.export): every deliverable built and validated once per session
# ---------------------------------------------------------------------------

@pytest.fixture(scope="session")
def predictor_setup() -> dict:
    """A cheap Eq. 29 predictor (``l1b2.predictor.model.example_params``) standing in for an identification result."""
    from l1b2.predictor.model import example_params
    from l1b2.predictor.setup import PredictorSetup
    return PredictorSetup(example_params(), 0.1, 1e-3).to_dict()


@pytest.fixture(scope="session")
def exported(tmp_path_factory, predictor_setup):
    """``(out_dir, manifest)`` of :func:`l1b2.fmi.export.export_all` for the reference motor, built once per session."""
    from l1b2.fmi.export import export_all
    out = tmp_path_factory.mktemp("dist")
    return out, export_all(out, predictor=predictor_setup)


@pytest.fixture(scope="session")
def load_bench():
    """Load a script of ``bench/`` as a module: ``load_bench("blind_effects_fifth")`` (``bench/`` put on
    ``sys.path`` first, for the scripts' imports of their siblings)."""
    bench = str(REPO / "bench")

    def load(name: str):
        if bench not in sys.path:
            sys.path.insert(0, bench)
        spec = importlib.util.spec_from_file_location(name, REPO / "bench" / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    return load


# ---------------------------------------------------------------------------
# Close loop (l1b2.closeloop.loop): the sensor stages' wiring with their decisions given
# ---------------------------------------------------------------------------

class OwnSpeedPhysics:
    """A physics model that predicts a frame's own speed column, in free run and one step ahead."""

    def predict_free_run(self, df):
        from l1b2.data.columns import SPEED
        return df[SPEED].to_numpy()

    def predict_one_step(self, df):
        return self.predict_free_run(df)


@pytest.fixture
def sensor_stages(monkeypatch):
    """``run(df, **decided)``: ``CloseLoop._sensor_stages`` on TRAIN ``df`` (every sample on the mask, no TEST)
    from round 0 of a model that predicts each frame's own speed (:class:`OwnSpeedPhysics`), with the decisions of
    the stages named in ``decided`` (``stamps``, ``encoder``) replaced by ``(record, stage or None)`` (a kept stage
    comes with that same model; the others decide as they do). Returns ``(iteration, record, the TRAIN frame the
    rounds fit)``."""
    import numpy as np
    from l1b2.closeloop import encoder, stamps
    from l1b2.closeloop.acceptance import EffectSet
    from l1b2.closeloop.loop import CloseLoop, _Iteration
    modules = {"stamps": stamps, "encoder": encoder}

    def run(df, **decided):
        for name, (rec, stage) in decided.items():
            out = (rec, None if stage is None else (OwnSpeedPhysics(), stage))
            monkeypatch.setattr(modules[name], "decide", lambda *a, _out=out, **k: _out)
        it, rec = _Iteration(model=OwnSpeedPhysics(), effects=EffectSet(), rounds=[{"round": 0}]), {}
        return it, rec, CloseLoop()._sensor_stages(it, rec, df, None, np.ones(len(df), bool), 0.1, [])
    return run
