"""The tutorial (docs/tutorial.md) end to end, as a newcomer follows it, in an empty folder.

Their own CSV has no speed column and an extra column; identify, close-loop, export and the exported FMUs
in fmpy follow. Budget: 5 minutes on 2 cores (the data are small: 16 traverses at a 1 ms step).
"""

from __future__ import annotations

import json
import re
import time

import pandas as pd

from test_readme_examples import ROOT, blocks, run_blocks

TUTORIAL = ROOT / "docs" / "tutorial.md"


def _schema_keys(page: str) -> list[str]:
    """The top-level keys listed in the first table of a schema page (first column, `a`, `b` ...)."""
    text = (ROOT / "docs" / "reference" / page).read_text(encoding="utf-8")
    table = text[text.index("| key |"):].split("\n\n", 1)[0]
    keys = []
    for row in table.splitlines()[2:]:
        keys += re.findall(r"`([a-z0-9_]+)`", row.split("|")[1])
    return keys


def test_tutorial_end_to_end(tmp_path, monkeypatch):
    work = tmp_path / "newcomer folder"
    work.mkdir()
    t0 = time.perf_counter()
    ns = run_blocks(TUTORIAL, work, monkeypatch, include_slow=True)
    wall = time.perf_counter() - t0
    assert wall < 300.0, f"the tutorial took {wall:.0f} s (budget 300 s on 2 cores)"

    # their CSV: no speed column, an extra column, read as it is
    csv = pd.read_csv(work / "my_rig.csv")
    assert "speed_m_s" not in csv.columns and "supply_current_A" in csv.columns

    ident = json.loads((work / "ident" / "identification.json").read_text())
    assert set(_schema_keys("identification-json.md")) <= set(ident), "identification.json vs its schema page"
    assert ident["metrics"]["test"]["free_run"]["nrmse"] < 0.05          # the paper's 5 % target
    report = json.loads((work / "report" / "report.json").read_text())
    assert set(_schema_keys("report-json.md")) <= set(report), "report.json vs its schema page"

    for f in ("calibrated/fmus/Predictor.fmu", "dist/L1B2Motor.fmu", "dist/L1B2Motor.ssp",
              "dist/fmus/Predictor.fmu", "motor_in_fmpy.png"):
        assert (work / f).stat().st_size > 0, f
    # the motor in fmpy runs the whole stroke at the reference motor's speed (no-load 150-300 mm/s at 324 V)
    res = ns["res"]
    assert 0.15 < res["v"].max() < 0.30 and res["s"][-1] > 0.02
    # the predictor's steady speed at 324 V, 0.05 kg lies within the speeds measured on the held-out run
    held_out = csv.query("voltage_V == 324 and load_kg == 0.05 and direction == 1")
    v_meas = held_out["position_m"].diff() / held_out["time_s"].diff()
    v_pred = ns["pred"]["v_steady"][-1]
    assert v_meas.quantile(0.05) < v_pred < v_meas.quantile(0.99)


def test_tutorial_runs_every_block():
    # the tutorial's blocks are all run by the test above, except `make demo` (the target itself)
    skipped = [b for b in blocks(TUTORIAL) if b["mark"] == "skip"]
    assert len(skipped) == 1 and "make demo" in skipped[0]["body"]
