"""Output folders: checked before any computation, complete or untouched, one writer at a time (issue 14, items 3-4).

l1b2.workflows.output_dir, and the commands that write through it (identify,
compare, rig, export); the extrapolation guard and strict JSON of identify
(item 2); one-line errors for every failure path (item 4).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from l1b2.cli import main as cli_main
from l1b2.errors import IdentificationError, OutputError
from l1b2.workflows import OUTPUT_MARKER, output_dir
from test_units_plausibility import synthetic_frame, write


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ---------------------------------------------------------------------------
# the helper
# ---------------------------------------------------------------------------

def test_complete_result_replaces_the_previous_one_without_stale_files(tmp_path):
    out = tmp_path / "res"
    with output_dir(out, command="identify") as tmp:
        assert tmp.parent == tmp_path and tmp != out and not out.exists()
        (tmp / "identification.json").write_text("{}")
        (tmp / "fig10_test_run_1.png").write_text("old")
    assert _names(out) == [OUTPUT_MARKER, "fig10_test_run_1.png", "identification.json"]
    with output_dir(out, command="identify") as tmp:
        (tmp / "identification.json").write_text('{"new": 1}')
    # the previous run's figure is gone: no stale file beside the new result
    assert _names(out) == [OUTPUT_MARKER, "identification.json"]
    assert _names(tmp_path) == ["res"]  # no temporary folder or lock left
    assert (out.stat().st_mode & 0o777) == 0o777 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize("failure", [RuntimeError, KeyboardInterrupt])
def test_interrupted_run_leaves_the_previous_result_untouched(tmp_path, failure):
    out = tmp_path / "res"
    with output_dir(out) as tmp:
        (tmp / "report.json").write_text('{"complete": true}')
    with pytest.raises(failure):
        with output_dir(out) as tmp:
            (tmp / "new.png").write_text("half")
            raise failure()
    assert _names(out) == [OUTPUT_MARKER, "report.json"]
    assert json.loads((out / "report.json").read_text()) == {"complete": True}
    assert _names(tmp_path) == ["res"]


def test_refused_before_the_body_runs(tmp_path):
    ran = []
    a_file = tmp_path / "file.txt"
    a_file.write_text("mine")
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    for target, fragment in ((a_file, "exists and is not a folder"), (foreign, "not written by this command")):
        with pytest.raises(OutputError, match=fragment):
            with output_dir(target, command="identify"):
                ran.append(target)
    assert ran == []
    assert a_file.read_text() == "mine" and (foreign / "notes.txt").read_text() == "mine"


def test_empty_folder_and_older_results_of_the_same_command_are_replaced(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with output_dir(empty, command="identify") as tmp:
        (tmp / "identification.json").write_text("{}")
    older = tmp_path / "older"  # written by an earlier version (no marker), only the command's own files
    older.mkdir()
    (older / "identification.json").write_text("{}")
    (older / "fig10_test_run_3.png").write_text("")
    with output_dir(older, command="identify") as tmp:
        (tmp / "identification.json").write_text('{"v": 2}')
    assert _names(older) == [OUTPUT_MARKER, "identification.json"]


def test_missing_parents_are_created_and_removed_again_on_failure(tmp_path):
    out = tmp_path / "a" / "b" / "res"
    with pytest.raises(ValueError):
        with output_dir(out):
            raise ValueError("input refused")
    assert _names(tmp_path) == []


def test_second_concurrent_writer_is_refused_and_a_dead_writers_lock_is_taken_over(tmp_path):
    out = tmp_path / "res"
    with output_dir(out) as tmp:
        (tmp / "a.json").write_text("{}")
        with pytest.raises(OutputError, match="another l1b2 run .* is writing this output folder"):
            with output_dir(out):
                pass
    # a lock left by a process that no longer exists (killed run) does not block
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    import socket
    (tmp_path / ".res.lock").write_text(f"{int(dead.stdout)} {socket.gethostname()}")
    (tmp_path / ".res.tmp-1-stale").mkdir()  # its half-written folder
    with output_dir(out) as tmp:
        (tmp / "b.json").write_text("{}")
    assert _names(tmp_path) == ["res"] and _names(out) == [OUTPUT_MARKER, "b.json"]


def test_two_cli_runs_on_one_folder_one_is_refused(tmp_path):
    # reference: issue 14 item 3 - two runs on one --out both printed "wrote ..." and one was lost
    train = write(tmp_path, synthetic_frame(), "train")
    code = (
        "import sys, time\n"
        "from l1b2.ident import estimator\n"
        "fit = estimator.PredictorIdentifier.fit\n"
        "def slow(self, *a, **k):\n"
        "    time.sleep(4); return fit(self, *a, **k)\n"
        "estimator.PredictorIdentifier.fit = slow\n"
        "from l1b2.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    args = ["identify", "--train", str(train), "--out", str(tmp_path / "out"), "--order", "3", "--starts", "1",
            "--no-plots"]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    first = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env=env)
    lock = tmp_path / ".out.lock"
    deadline = time.time() + 60
    while not lock.exists() and time.time() < deadline and first.poll() is None:
        time.sleep(0.05)
    second = subprocess.run([sys.executable, "-m", "l1b2.cli", *args], capture_output=True, text=True, env=env)
    out1, err1 = first.communicate(timeout=600)
    assert first.returncode == 0, err1
    assert second.returncode != 0
    assert second.stderr.count("\n") == 1 and "another l1b2 run" in second.stderr
    assert "wrote" not in second.stdout
    assert (tmp_path / "out" / "identification.json").exists()


# ---------------------------------------------------------------------------
# whose folder it is (issue 30): another command's result, the command's own input, the current folder
# ---------------------------------------------------------------------------

def _result_of(folder: Path, command: str, files: dict[str, str]) -> None:
    with output_dir(folder, command=command) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text)


def _contents(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in folder.iterdir() if p.is_file()}


def test_identify_out_at_the_rig_folder_it_reads_is_refused_nothing_deleted(tmp_path, capsys, monkeypatch):
    # reference: issue 30 - identify --out <rig folder> deleted train.csv, test.csv, all.csv and rig_truth.json
    _fit_must_not_run(monkeypatch)
    rig = tmp_path / "rig"
    frame = synthetic_frame()
    _result_of(rig, "rig", {"rig_truth.json": "{}", "all.csv": "x"})
    train = write(rig, frame, "train")
    before = _contents(rig)
    code = cli_main(["identify", "--train", str(train), "--out", str(rig)])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1, err
    assert "holds this command's input" in err or "result of 'l1b2 rig'" in err
    assert _contents(rig) == before


def test_a_result_of_another_command_is_never_replaced(tmp_path):
    # reference: issue 30 - close-loop --report-dir at an identify result deleted identification.json
    res = tmp_path / "ident"
    _result_of(res, "identify", {"identification.json": '{"p": 1}'})
    with pytest.raises(OutputError, match=r"holds the result of 'l1b2 identify'"):
        with output_dir(res, command="close-loop"):
            raise AssertionError("body ran")
    assert _contents(res)["identification.json"] == '{"p": 1}'
    _result_of(res, "identify", {"identification.json": '{"p": 2}'})  # the same command may replace it
    assert _contents(res)["identification.json"] == '{"p": 2}'


def test_a_folder_holding_an_input_is_refused_even_without_a_marker(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "identification.json").write_text("{}")   # only names the command would write ...
    nested = data / "runs"
    nested.mkdir()
    (nested / "fig10_test_run_1.png").write_text("")  # ... and the input deeper inside
    with pytest.raises(OutputError, match="holds this command's input"):
        with output_dir(data, command="identify", inputs=(nested / "fig10_test_run_1.png",)):
            raise AssertionError("body ran")
    assert (nested / "fig10_test_run_1.png").exists()


def test_out_dot_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    # reference: issue 30 - `--out .` was an internal error (exit 3, traceback)
    _fit_must_not_run(monkeypatch)
    work = tmp_path / "work"
    work.mkdir()
    train = write(work, synthetic_frame(), "train")
    monkeypatch.chdir(work)
    for out in (".", str(tmp_path)):
        code = cli_main(["identify", "--train", str(train), "--out", out])
        err = capsys.readouterr().err
        assert code == 2 or code == 1, (code, err)
        assert err.count("\n") == 1 and "current folder" in err, err
    assert train.exists()


@pytest.mark.parametrize("complete", [True, False])
def test_a_swap_killed_between_its_two_renames_is_finished_or_rolled_back(tmp_path, complete):
    # reference: issue 30 - dying between the renames left no --out and the old result as a hidden folder
    out = tmp_path / "res"
    _result_of(out, "identify", {"identification.json": "old"})
    os.replace(out, tmp_path / ".res.old-99999")          # first rename done, then killed
    half = tmp_path / ".res.tmp-99999-x"
    half.mkdir()
    (half / "identification.json").write_text("new")
    if complete:                                        # the marker is written last: the new result was whole
        (half / OUTPUT_MARKER).write_text(json.dumps({"command": "identify"}))
    with pytest.raises(ValueError):
        with output_dir(out, command="identify"):
            raise ValueError("this run's input refused")
    assert _contents(out)["identification.json"] == ("new" if complete else "old")
    assert _names(tmp_path) == ["res"]


# ---------------------------------------------------------------------------
# temporary FMU extractions
# ---------------------------------------------------------------------------

_SIGTERM_CHILD = """
import os, signal, sys, time
from pathlib import Path
from l1b2.cosim import master
folder = master.extracted(Path(sys.argv[1]))
print(folder, flush=True)
time.sleep(60)
"""


def test_fmu_extractions_are_removed_on_sigterm_and_stale_ones_at_next_start(tmp_path, fmus):
    import signal
    tmp_root = tmp_path / "tmp"
    tmp_root.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp_root), "OPENBLAS_NUM_THREADS": "1"}
    child = subprocess.Popen([sys.executable, "-c", _SIGTERM_CHILD, str(fmus["Slider"])], stdout=subprocess.PIPE,
                             text=True, env=env)
    folder = Path(child.stdout.readline().strip())
    assert folder.parent == tmp_root and (folder / "modelDescription.xml").exists()
    child.send_signal(signal.SIGTERM)
    assert child.wait(timeout=60) == 128 + signal.SIGTERM
    assert list(tmp_root.iterdir()) == []
    # a run killed with SIGKILL cannot clean up: the next process that extracts an FMU does
    child = subprocess.Popen([sys.executable, "-c", _SIGTERM_CHILD, str(fmus["Slider"])], stdout=subprocess.PIPE,
                             text=True, env=env)
    folder = Path(child.stdout.readline().strip())
    child.kill()
    child.wait(timeout=60)
    assert folder.exists()
    mine = tmp_root / "l1b2-fmu-notapid-x"             # not a pid: not ours to judge, left alone
    mine.mkdir()
    from l1b2.cosim.master import remove_stale_extractions
    assert remove_stale_extractions(str(tmp_root)) == [str(folder)]
    assert sorted(p.name for p in tmp_root.iterdir()) == ["l1b2-fmu-notapid-x"]


# ---------------------------------------------------------------------------
# the commands
# ---------------------------------------------------------------------------

def _fit_must_not_run(monkeypatch):
    from l1b2.ident import estimator

    def refuse(self, *a, **k):
        raise AssertionError("the fit ran although the output folder is unusable")
    monkeypatch.setattr(estimator.PredictorIdentifier, "fit", refuse)


def test_identify_out_is_a_file_one_line_before_fitting(tmp_path, capsys, monkeypatch):
    # reference: issue 14 item 4 - FileExistsError after the whole fit
    _fit_must_not_run(monkeypatch)
    train = write(tmp_path, synthetic_frame(), "train")
    target = tmp_path / "taken"
    target.write_text("not a folder")
    code = cli_main(["identify", "--train", str(train), "--out", str(target)])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "exists and is not a folder" in err
    assert target.read_text() == "not a folder"


@pytest.mark.parametrize("command", [["compare"], ["rig", "--engine", "inprocess", "--quiet"], ["export"]])
def test_other_commands_refuse_a_file_as_output_before_working(tmp_path, capsys, command):
    target = tmp_path / "taken"
    target.write_text("x")
    t0 = time.perf_counter()
    code = cli_main([command[0], "--out", str(target), *command[1:]])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "exists and is not a folder" in err
    assert time.perf_counter() - t0 < 10  # refused up front, not after the work
    assert target.read_text() == "x"


def test_numerical_failure_in_the_fit_is_an_identification_error(monkeypatch):
    # reference: issue 14 item 4 - LinAlgError: SVD did not converge reached the user as a traceback
    from l1b2.ident import estimator
    from l1b2.ident.estimator import PredictorIdentifier

    def broken(*a, **k):
        raise np.linalg.LinAlgError("SVD did not converge")
    monkeypatch.setattr(estimator, "fisher_uncertainty", broken)
    df = synthetic_frame()
    with pytest.raises(IdentificationError, match="the data do not determine .* because LinAlgError: SVD did not"):
        PredictorIdentifier(order=3, n_starts=1, fixed="recommended").fit(df, 0.1)


def test_internal_error_is_one_line_without_traceback(capsys, monkeypatch):
    import l1b2.cli as cli

    def bug(args):
        raise KeyError("oops")
    monkeypatch.setattr(cli, "cmd_injections", bug)
    monkeypatch.delenv("L1B2_TRACEBACK", raising=False)
    parser_cmd = cli.build_parser().parse_args(["injections"])
    assert parser_cmd.func is not None
    monkeypatch.setattr(cli, "build_parser", lambda: _parser_with(cli, bug))
    code = cli.main(["injections"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "internal error (KeyError" in err and "Traceback" not in err


def _parser_with(cli, func):
    import argparse
    ap = argparse.ArgumentParser(prog="l1b2")
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("injections").set_defaults(func=func)
    return ap


# ---------------------------------------------------------------------------
# extrapolation guard (item 2)
# ---------------------------------------------------------------------------

def test_extrapolation_is_flagged_diverged_runs_excluded_and_json_strict(tmp_path, capsys):
    # reference: issue 14 item 2 - TRAIN limited to |s| <= 8 mm, TEST over the full stroke gave
    # "free_run nrmse inf%", a mean error of 6.8e183 % and Infinity in identification.json
    full = synthetic_frame()
    train = write(tmp_path, full[full["position_m"].abs() <= 0.008], "train_8mm")
    test = write(tmp_path, synthetic_frame(seed=5), "test_full")
    out = tmp_path / "out"
    code = cli_main(["identify", "--train", str(train), "--test", str(test), "--out", str(out), "--order", "6",
                     "--starts", "1"])
    printed = capsys.readouterr().out
    assert code == 0
    text = (out / "identification.json").read_text()
    rep = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    assert "Infinity" not in text and "NaN" not in text
    checks = rep["checks"]
    assert checks["training_range"]["position_m"][1] <= 0.008
    flagged = checks["test_runs_outside_training_range"]
    assert len(flagged) == rep["data"]["test_runs"] == 12
    assert all("position_m" in f["outside"] and "voltage_V" not in f["outside"] for f in flagged)
    assert "runs outside the training range (position_m 12)" in printed
    for kind in ("one_step", "free_run"):
        m = rep["metrics"]["test"][kind]
        assert m["n_runs"] == 12 and m["n_diverged_runs"] == len(m["diverged_runs"])
        for key in ("nrmse", "mean_abs_rel_error", "p95_abs_rel_error"):
            assert m[key] is None or (np.isfinite(m[key]) and m[key] < 10), (kind, key, m[key])
    free = rep["metrics"]["test"]["free_run"]
    assert free["n_diverged_runs"] > 0 and "diverged" in printed
    assert "inf%" not in printed and "nan%" not in printed


def test_voltage_and_load_outside_train_are_flagged(tmp_path):
    from l1b2.data.coverage import data_range, outside_range
    df = synthetic_frame()
    train = df[(df["voltage_V"] == 220.0) & (df["load_kg"] <= 0.0)]
    test = df[~df.index.isin(train.index)]
    flagged = outside_range(test, data_range(train))
    by_run = {f["run"]: set(f["outside"]) for f in flagged}
    for run, g in test.groupby("run"):
        expect = set()
        if g["voltage_V"].iloc[0] == 324.0:
            expect.add("voltage_V")
        if g["load_kg"].iloc[0] > 0:
            expect.add("load_kg")
        assert by_run.get(run, set()) == expect, run


def test_a_sweep_never_writes_into_another_commands_result(tmp_path, capsys):
    res = tmp_path / "ident"
    _result_of(res, "identify", {"identification.json": "{}"})
    spec = tmp_path / "study.toml"
    spec.write_text("[study]\n")
    code = cli_main(["sweep", "--spec", str(spec), "--out", str(res), "--workers", "0", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "result of 'l1b2 identify'" in err, err
    assert sorted(p.name for p in res.iterdir()) == [OUTPUT_MARKER, "identification.json"]
