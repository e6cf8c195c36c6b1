"""Time and evaluations per stage on the terminal (issue 29): `l1b2 identify` and `l1b2 close-loop` print them."""

import json

from l1b2.cli import main as cli_main
from l1b2.console import stage_lines
from test_units_plausibility import synthetic_frame, write


def test_stage_lines_of_both_record_forms_and_their_total():
    # close loop's records (wall_s, identifications) and an identification's (time_s, nfev only where it evaluates)
    loop = [{"stage": "baseline", "wall_s": 1.25, "cpu_s": 1.0, "identifications": 1, "nfev": 76},
            {"stage": "round 1: scoring", "wall_s": 2.5, "cpu_s": 2.0, "identifications": 0, "nfev": 0},
            {"stage": "round 1: cross-validating", "wall_s": 4.0, "cpu_s": 2.5, "identifications": 16, "nfev": 320}]
    lines = stage_lines(loop)
    assert len(lines) == 1 + 3 + 1 and lines[0].split()[0] == "stage"
    assert lines[1].split() == ["baseline", "1.2", "1.0", "1", "76"]   # 1.25 s to one decimal (half to even)
    assert lines[3].split()[-4:] == ["4.0", "2.5", "16", "320"]
    # total: 1.25 + 2.5 + 4.0 = 7.75 s wall, 1.0 + 2.0 + 2.5 = 5.5 s CPU, 1 + 0 + 16 fits, 76 + 0 + 320 evaluations
    assert lines[-1].split() == ["total", "7.8", "5.5", "17", "396"]
    ident = [{"stage": "start", "time_s": 0.5, "cpu_s": 0.25},
             {"stage": "search (alternate)", "time_s": 3.0, "cpu_s": 2.75, "nfev": 221},
             {"stage": "uncertainty", "time_s": 0.25, "cpu_s": 0.25}]
    lines = stage_lines(ident)
    assert lines[1].split() == ["start", "0.5", "0.2", "-", "-"]
    assert lines[2].split()[-4:] == ["3.0", "2.8", "-", "221"]
    assert lines[-1].split() == ["total", "3.8", "3.2", "-", "221"]   # 3.75 s wall, 3.25 s CPU


def test_identify_prints_each_stage_of_its_fit(tmp_path, capsys):
    train = write(tmp_path, synthetic_frame(), "train")
    out = tmp_path / "out"
    assert cli_main(["identify", "--train", str(train), "--out", str(out), "--order", "3", "--starts", "1",
                     "--no-plots"]) == 0
    printed = capsys.readouterr().out.splitlines()
    stages = json.loads((out / "identification.json").read_text())["convergence"]["stages"]
    at = printed.index("time and evaluations per stage of the fit:")
    rows = [ln.split() for ln in printed[at + 2:at + 3 + len(stages)]]
    assert [r[-1] for r in rows[:-1]] == [str(s["nfev"]) if "nfev" in s else "-" for s in stages]
    assert [s["stage"] for s in stages][-1] == "uncertainty" and rows[-2][0] == "uncertainty"
    assert rows[-1][0] == "total" and int(rows[-1][-1]) == sum(s.get("nfev", 0) for s in stages) > 0
