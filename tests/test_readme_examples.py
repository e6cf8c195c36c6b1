"""The README's Python examples run as written (on a small rig data set in a temporary folder)."""

from __future__ import annotations

import re
from pathlib import Path


from l1b2.physics.params import load_motor
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment

README = Path(__file__).resolve().parents[1] / "README.md"


def _examples() -> list[str]:
    text = README.read_text()
    section = text[text.index("## From Python"):text.index("## Use the FMUs in your simulator")]
    return re.findall(r"```python\n(.*?)```", section, flags=re.S)


def test_readme_has_the_three_examples():
    blocks = _examples()
    assert len(blocks) == 3
    assert "PredictorIdentifier" in blocks[0] and "close_loop" in blocks[1] and "CoSimulation" in blocks[2]


def test_readme_examples_run(tmp_path, monkeypatch):
    # reference: the README itself; every block runs in one namespace, in order, on rig data
    monkeypatch.chdir(tmp_path)
    plan = RigPlan(voltages_V=(220.0, 324.0), loads_kg=(-0.05, 0.0, 0.05, 0.09), step_s=1e-3)
    mp = load_motor()
    df, truth = run_experiment(plan, mp, engine="inprocess")
    write_experiment(df, tmp_path / "rigdata", mp, plan, truth)
    namespace: dict = {}
    for block in _examples():
        exec(compile(block, str(README), "exec"), namespace)  # noqa: S102 - our own documentation
    assert (tmp_path / "runs.png").stat().st_size > 0
    assert (tmp_path / "closeloop_report" / "report.json").is_file()
    assert (tmp_path / "cosim.png").stat().st_size > 0
    assert namespace["run"].to_pandas()["Slider.v"].abs().max() > 0.05
