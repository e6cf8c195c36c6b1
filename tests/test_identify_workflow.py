"""`l1b2 identify` on the virtual rig's data (issue 4): held-out accuracy, report, refusal of bad input."""

import json

import pandas as pd
import pytest
from l1b2.cli import main as cli_main
from rigcache import rig_dir


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    out = tmp_path_factory.mktemp("ident")
    code = cli_main(["identify", "--train", str(rig_dir() / "all.csv"), "--out", str(out)])
    assert code == 0
    return out, json.loads((out / "identification.json").read_text())


def test_held_out_free_run_meets_the_papers_accuracy(identified):
    # reference: issue targets on the rig's data: held-out free-run p95 < 5 % (paper Sect. 5.2), nrmse < 3 %
    _, rep = identified
    test = rep["metrics"]["test"]["free_run"]
    assert test["p95_abs_rel_error"] < 0.05
    assert test["nrmse"] < 0.03
    assert rep["metrics"]["test"]["one_step"]["nrmse"] < test["nrmse"]  # one step is the easier task


def test_paper_split_and_report_contents(identified):
    # reference: the paper's split (test = |load| 0.05 kg) and the report fields the issue asks for
    out, rep = identified
    assert rep["data"]["test_runs"] == 16 and rep["data"]["train_runs"] == 56
    for name, p in rep["parameters"].items():
        assert {"value", "stderr", "ci95", "unit"} <= set(p)
    assert set(rep["paper_monomials"]) >= {"alpha", "beta", "p"}
    assert rep["unidentifiable"], "the paper's full Eq. 35 parameterisation has null directions"
    assert rep["convergence"] and rep["fit_time_s"] > 0
    assert len(rep["figures"]) == 16 and all((out / f.split("/")[-1]).exists() for f in rep["figures"])
    assert "aic" in rep and "bic" in rep
    assert (out / "fit_report.txt").read_text().strip()
    # the fit against the runs' level law: a good fit of the rig's data beats it, so no warning
    law = rep["checks"]["level_law"]
    assert law["train_free_run_nrmse"] == pytest.approx(rep["metrics"]["train"]["free_run"]["nrmse"])
    assert 0 < law["train_free_run_nrmse"] < law["level_law_nrmse"] and not law["above"]


@pytest.mark.parametrize("problem", ["missing_column", "mm_positions", "bad_direction", "time_backwards"])
def test_bad_input_is_refused_with_one_line_and_nothing_written(tmp_path, capsys, problem):
    # reference: the rig data format (docs/reference/data-format.md) "Bad input": one clear message, nothing written
    df = pd.read_csv(rig_dir() / "all.csv").iloc[:3000].copy()
    if problem == "missing_column":
        df = df.drop(columns=["voltage_V"])
    elif problem == "mm_positions":
        df["position_m"] *= 1000
    elif problem == "bad_direction":
        df.loc[100, "direction"] = 0
    else:
        df.loc[200, "time_s"] = df.loc[199, "time_s"] - 1e-3
    bad = tmp_path / "bad.csv"
    df.to_csv(bad, index=False)
    out = tmp_path / "out"
    code = cli_main(["identify", "--train", str(bad), "--out", str(out), "--slider-mass", "0.12"])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("l1b2: error:") and "bad.csv" in err
    assert not out.exists()
