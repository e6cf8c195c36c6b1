"""Close the loop on the realistic motor variant (issue 11): ten clean control seeds, and the command line's
report of a realistic case round by round.

The checks are the realistic world's (``tests/realistic_cases.py``): a control's held-out free-run nrmse never
more than 2 % (relative) above the baseline, what was added reported; an injected case's regressor among the first
two traced and ``a^2 <= b0^2 + (b^2 - b0^2)/4`` on TEST (b: baseline, a: extended, b0: the same seed without the
effect). A module of its own so that ``make test``'s two workers, which take whole modules, can run it beside the
single effects (``tests/conftest.py``, ``COSTLY_FIRST``).
"""

import json

import pytest
from l1b2.cli import main as cli_main
from realistic_cases import case_dir, check_control, clean_baseline, run_case


@pytest.mark.slow
@pytest.mark.parametrize("seeds", [pytest.param(range(30, 35), marks=pytest.mark.ci_slow, id="30-34"),
                                   pytest.param(range(35, 40), id="35-39")])   # CI: the first five (0080, 0131)
def test_realistic_control_ten_seeds(seeds, record_property):
    for seed in seeds:
        check_control(run_case((), seed)[0], f"clean {seed}", record_property)


@pytest.mark.slow    # make test-slow (decision 0131; was ci_slow, 0080)
def test_realistic_load_path_effect_report_rounds(tmp_path, capsys):
    # reference: issue 11: report.json gains diagnosis.effects and rounds; the CLI prints a table per round;
    # report.md shows each round; the held-out error cut in quadrature of the excess over the clean world.
    # `--workers 1`: the refits in this process (that a cluster gives the same refits is test_closeloop_parallel.py's
    # check; the CLI's default local cluster runs in test_tutorial.py)
    d = case_dir(("pulley_friction",), 1)
    out = tmp_path / "cl"
    assert cli_main(["close-loop", "--train", str(d / "train.csv"), "--test", str(d / "test.csv"),
                     "--report-dir", str(out), "--quiet", "--no-plots", "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "round" in printed and "CV gain" in printed
    rep = json.loads((out / "report.json").read_text())
    eff = rep["diagnosis"]["effects"]
    assert eff and rep["diagnosis"]["effect"] == eff[0]["effect"]
    assert "load" in rep["diagnosis"]["traced_to"][:2]
    for e in eff:
        assert e["regressors"] and e["cv_gain"] >= 0.03 and e["parameters"]
        assert all({"value", "stderr", "ci95", "unit"} <= set(p) for p in e["parameters"].values())
    rounds = rep["rounds"]
    assert rounds[0]["round"] == 0 and rounds[0]["added"] is None and len(rounds) == len(eff) + 1
    assert rep["extended"] == rounds[-1]["metrics"]
    md = (out / "report.md").read_text()
    assert "## Rounds" in md
    b = rep["baseline"]["test"]["free_run"]["nrmse"]
    a = rep["extended"]["test"]["free_run"]["nrmse"]
    b0 = clean_baseline(1)
    assert a ** 2 <= b0 ** 2 + (b ** 2 - b0 ** 2) / 4, (b0, b, a)
