"""bench/case_table.py: the closing note's table of close-loop cases, read from pytest's JUnit XML.

The outcome column must tell a pass, a failure and a known miss (a strict xfail, whose check failed) apart;
JUnit XML writes an xfail as ``<skipped type="pytest.xfail">``, which a naive reader takes for a pass.
The column "channels considered" counts the channels and run-level signals of the diagnosis's
``channels_considered`` and names the significant ones.
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

from rigcache import channels_summary

BENCH = Path(__file__).resolve().parents[1] / "bench" / "case_table.py"

CASES = '''
import json, pytest

CHANNELS = {"channels": 2, "run_signals": 3, "significant": ["temperature_C", "|load_kg| (run)"]}

def _row(case):
    row = {"world": "w", "case": case, "traced_to": ["load"], "added": [], "before": 0.05,
           "after": 0.04, "b0": None, "wall_s": 1.0}
    if case != "c":  # "c" stands for a case recorded before the column existed
        row["channels"] = CHANNELS
    return json.dumps(row)

def test_passes(record_property):
    record_property("case", _row("a"))

def test_fails(record_property):
    record_property("case", _row("b"))
    assert False

@pytest.mark.xfail(strict=True, raises=AssertionError, reason="known")
def test_known_miss(record_property):
    record_property("case", _row("c"))
    assert False
'''


def _table_module():
    spec = importlib.util.spec_from_file_location("case_table", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _cases_xml(tmp_path):
    (tmp_path / "test_cases.py").write_text(CASES)
    xml = tmp_path / "cases.xml"
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                    str(tmp_path / "test_cases.py"), f"--junitxml={xml}"], cwd=tmp_path, capture_output=True)
    return xml


def test_case_table_tells_pass_fail_and_known_miss_apart(tmp_path):
    outcome = {r["case"]: r["test"] for r in _table_module().rows([_cases_xml(tmp_path)])}
    assert outcome == {"a": "pass", "b": "fail", "c": "known miss (xfail)"}


def test_the_table_shows_the_channels_considered_and_the_significant_ones(tmp_path, capsys):
    _table_module().main([str(_cases_xml(tmp_path))])
    out = capsys.readouterr().out.splitlines()
    assert all(len(ln.replace("\\|", "").split("|")) == 10 for ln in out)     # 8 columns on every line
    lines = {ln.split(" | ")[1]: ln for ln in out[2:]}
    assert lines["a"].endswith("| 2 channels + 3 run-level signals; significant: temperature_C, \\|load_kg\\| (run) |")
    assert lines["c"].endswith("| - |")  # recorded without the column


def test_channels_summary_counts_candidates_and_run_level_signals_and_names_the_significant():
    def ev(signal, significant):
        return {"signal": signal, "significant": significant}
    considered = [
        {"channel": "temperature_C", "kind": "logged", "significant": True, "run_level": [ev("temperature_C", False)]},
        {"channel": "vibrometer", "kind": "response", "significant": False, "run_level": []},
        {"channel": "time_s", "kind": "protocol", "significant": False, "run_level": [ev("time_s", True)]},
        {"channel": "supply_V", "kind": "logged", "significant": False},  # constant: no run-level row
        {"channel": "load_kg", "kind": "input", "significant": True,
         "run_level": [ev("d*load_kg", False), ev("|load_kg|", True)]},
        {"channel": "voltage_V", "kind": "input", "significant": False, "run_level": [ev("voltage_V", False)]},
    ]
    # channels: the three logged/protocol rows (not the response, not the inputs); run-level signals: 1+1+2+1
    assert channels_summary(considered) == {
        "channels": 3, "run_signals": 5,
        "significant": ["temperature_C", "time_s (run)", "|load_kg| (run)"]}
