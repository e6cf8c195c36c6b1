"""bench/case_table.py: the closing note's table of close-loop cases, read from pytest's JUnit XML.

The outcome column must tell a pass, a failure and a known miss (a strict xfail, whose check failed) apart;
JUnit XML writes an xfail as ``<skipped type="pytest.xfail">``, which a naive reader takes for a pass.
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench" / "case_table.py"

CASES = '''
import json, pytest

def _row(case):
    return json.dumps({"world": "w", "case": case, "traced_to": ["load"], "added": [], "before": 0.05,
                       "after": 0.04, "b0": None, "wall_s": 1.0})

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


def test_case_table_tells_pass_fail_and_known_miss_apart(tmp_path):
    (tmp_path / "test_cases.py").write_text(CASES)
    xml = tmp_path / "cases.xml"
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                    str(tmp_path / "test_cases.py"), f"--junitxml={xml}"], cwd=tmp_path, capture_output=True)
    spec = importlib.util.spec_from_file_location("case_table", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    outcome = {r["case"]: r["test"] for r in mod.rows([xml])}
    assert outcome == {"a": "pass", "b": "fail", "c": "known miss (xfail)"}
