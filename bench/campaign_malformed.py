#!/usr/bin/env python
"""Malformed-data campaign against ``l1b2 identify`` and ``l1b2 close-loop`` (issue 14).

Generates malformed files from a virtual-rig data set and runs the CLI on
each (in-process, through ``l1b2.cli.main``, exactly the console entry
point), then prints one table row per input class:

    tried | refused | traceback | written | silently wrong | accepted

* refused: non-zero exit with exactly one line ``l1b2: error: ...``;
* traceback: an exception escaped the CLI, or it printed "internal error"
  (its last-resort line for a bug);
* written: the output folder (or any other new file) exists after a refusal;
* silently wrong: exit 0 where the ground truth is known to be wrong (a unit
  mistake, an extrapolation without a flag, metrics with inf/NaN), or a JSON
  report with NaN/Infinity;
* accepted: exit 0 (for structural corruptions that left a valid file, e.g.
  a deleted sample, this is right).

Usage::

    python bench/campaign_malformed.py [--rig DIR] [--work DIR] [--full-plan] [--structural N] [--close-loop]

Without ``--rig`` a reduced rig plan (2 voltages x 5 loads x 2 directions,
``l1b2 rig --engine inprocess --quiet --no-plots``) is generated, so that
accepted files fit in seconds (identify with ``--order 3 --starts 1``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from l1b2.cli import main as cli_main

FAST = ["--order", "3", "--starts", "1", "--no-plots"]
CLOSE_FAST = ["--order", "3", "--folds", "2", "--no-plots", "--quiet"]


# ---------------------------------------------------------------------------
# running the CLI
# ---------------------------------------------------------------------------

def run_cli(argv: list[str]) -> dict:
    out, err = io.StringIO(), io.StringIO()
    escaped = None
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli_main(argv)
        except BaseException as exc:  # noqa: BLE001 - a traceback is what we count
            code, escaped = -1, f"{type(exc).__name__}: {exc}"
    return {"code": code, "stdout": out.getvalue(), "stderr": err.getvalue(), "escaped": escaped,
            "seconds": time.perf_counter() - t0}


def strict(path: Path) -> bool:
    try:
        json.loads(path.read_text(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
        return True
    except ValueError:
        return False


def judge(res: dict, out: Path, folder_before: set, folder: Path, expect: str, report: str) -> dict:
    """Classify one run. ``expect``: 'refuse' (known wrong input), 'flag' (extrapolation), 'any' (unknown)."""
    err = res["stderr"]
    one_line = err.count("\n") == 1 and err.startswith("l1b2: error:")
    traceback = res["escaped"] is not None or "internal error" in err or "Traceback" in err
    refused = res["code"] != 0 and one_line and not traceback
    new_files = set(p.name for p in folder.iterdir()) - folder_before
    written = res["code"] != 0 and bool(new_files)
    accepted = res["code"] == 0
    wrong = False
    rep_path = out / report
    if accepted:
        if rep_path.exists() and not strict(rep_path):
            wrong = True
        if expect == "refuse":
            wrong = True
        if expect == "flag":
            rep = json.loads(rep_path.read_text()) if rep_path.exists() else {}
            checks = rep.get("checks") or {}
            wrong = wrong or not checks.get("test_runs_outside_training_range")
        if "inf%" in res["stdout"] or "nan%" in res["stdout"]:
            wrong = True
    return {"refused": refused, "traceback": traceback, "written": written, "wrong": wrong, "accepted": accepted,
            "message": (err.strip() or res["escaped"] or "")[:300]}


# ---------------------------------------------------------------------------
# malformed files
# ---------------------------------------------------------------------------

def scale(col, factor):
    return lambda df: df.assign(**{col: df[col] * factor})


UNIT_MISTAKES = {
    "load in g": (scale("load_kg", 1e3), None),
    "load in g, |load| <= 50 g": (lambda df: df.assign(load_kg=np.clip(df["load_kg"] * 1e3, -50, 50)), None),
    "time in ms": (scale("time_s", 1e3), None),
    "time in ms, no speed column": (lambda df: scale("time_s", 1e3)(df).drop(columns=["speed_m_s"]), None),
    "voltage in kV": (scale("voltage_V", 1e-3), None),
    "voltage in mV": (scale("voltage_V", 1e3), None),
    "position x10": (scale("position_m", 10.0), None),
    "position x100": (scale("position_m", 100.0), None),
    "position in mm": (scale("position_m", 1e3), None),
    "position x10, no speed column": (lambda df: scale("position_m", 10.0)(df).drop(columns=["speed_m_s"]), None),
    "speed in mm/s": (scale("speed_m_s", 1e3), None),
    "speed unsigned": (lambda df: df.assign(speed_m_s=df["speed_m_s"].abs()), None),
    "frequency in kHz": (scale("frequency_Hz", 1e-3), None),
    "frequency / 10": (scale("frequency_Hz", 0.1), None),
    "temperature in K": (lambda df: df.assign(temperature_C=298.15), None),
    "slider mass in g (sidecar)": (lambda df: df, {"slider_mass_kg": 120.0}),
    "encoder in um (sidecar)": (lambda df: df, {"encoder_resolution_m": 0.05}),
    # issue 30: mistakes inside the per-column ranges
    "load in N": (scale("load_kg", 9.80665), None),
    "load in lb": (scale("load_kg", 1 / 0.45359237), None),
    "load x10": (scale("load_kg", 10.0), None),
    "load sign flipped": (scale("load_kg", -1.0), None),
    "temperature in degF": (lambda df: df.assign(temperature_C=77.0), None),
    "time x100": (scale("time_s", 100.0), None),
}


def write_pair(df: pd.DataFrame, path: Path, sidecar: dict) -> Path:
    df.to_csv(path, index=False)
    path.with_suffix(".json").write_text(json.dumps(sidecar))
    return path


def structural_cases(text: str, n: int, seed: int) -> list[tuple[str, str]]:
    """n corruptions of a CSV text: (kind, corrupted text)."""
    rng = random.Random(seed)
    lines = text.split("\n")
    header, body = lines[0], [ln for ln in lines[1:] if ln]
    junk = ["", "nan", "inf", "1,5", "abc", "1e308", "-1", "0", "2", " ", "\"", "0x10", "--1", "∞", "TRUE"]
    out = []
    kinds = ["cell", "delete_line", "duplicate_line", "swap_lines", "truncate_line", "blank_line", "drop_column",
             "rename_column", "semicolon_decimal_comma", "tab", "bom", "empty", "header_only", "nul_byte",
             "mixed_line_separator"]
    for i in range(n):
        kind = kinds[i % len(kinds)]
        b = list(body)
        h = header.split(",")
        k = rng.randrange(len(b))
        if kind == "cell":
            cells = b[k].split(",")
            cells[rng.randrange(len(cells))] = rng.choice(junk)
            b[k] = ",".join(cells)
        elif kind == "delete_line":
            del b[k]
        elif kind == "duplicate_line":
            b.insert(k, b[k])
        elif kind == "swap_lines":
            m = rng.randrange(len(b))
            b[k], b[m] = b[m], b[k]
        elif kind == "truncate_line":
            b[k] = b[k][: rng.randrange(max(len(b[k]), 1))]
        elif kind == "blank_line":
            b.insert(k, "")
        elif kind in ("drop_column", "rename_column"):
            j = rng.randrange(len(h))
            if kind == "drop_column":
                h = h[:j] + h[j + 1:]
                b = [",".join(c for i2, c in enumerate(ln.split(",")) if i2 != j) for ln in b]
            else:
                h[j] = rng.choice([h[j].upper(), h[j].split("_")[0] + "_mm", "", "x"])
        elif kind == "semicolon_decimal_comma":
            h = [";".join(h)]
            b = [ln.replace(",", ";").replace(".", ",") for ln in b]
        elif kind == "tab":
            h = ["\t".join(h)]
            b = [ln.replace(",", "\t") for ln in b]
        elif kind == "mixed_line_separator":
            b[k] = b[k].replace(",", ";")
        elif kind == "nul_byte":
            b[k] = b[k][:3] + "\x00" + b[k][3:]
        if kind == "bom":
            out.append((kind, "\ufeff" + text))
        elif kind == "empty":
            out.append((kind, ""))
        elif kind == "header_only":
            out.append((kind, header + "\n"))
        else:
            out.append((kind, "\n".join([",".join(h)] + b) + "\n"))
    return out


# ---------------------------------------------------------------------------
# the campaign
# ---------------------------------------------------------------------------

class Campaign:
    def __init__(self, rig: Path, work: Path, close_loop: bool):
        self.rig, self.work, self.close_loop = rig, work, close_loop
        self.all = pd.read_csv(rig / "all.csv")
        self.train = pd.read_csv(rig / "train.csv")
        self.test = pd.read_csv(rig / "test.csv")
        self.sidecar = json.loads((rig / "all.json").read_text())
        self.rows: dict[str, list[dict]] = {}
        self.n = 0

    def case_dir(self) -> Path:
        self.n += 1
        d = self.work / f"case{self.n:03d}"
        d.mkdir(parents=True)
        return d

    def record(self, cls: str, verdict: dict, note: str) -> None:
        self.rows.setdefault(cls, []).append({**verdict, "note": note})

    def identify(self, cls, note, train_df, test_df=None, sidecar=None, expect="refuse", extra=(), text=None):
        d = self.case_dir()
        side = {**self.sidecar, **(sidecar or {})}
        train_side = self.sidecar if test_df is not None else side  # with TEST, only TEST's sidecar is wrong
        if text is not None:
            (d / "train.csv").write_text(text, encoding="utf-8")
            (d / "train.json").write_text(json.dumps(train_side))
        else:
            write_pair(train_df, d / "train.csv", train_side)
        argv = ["identify", "--train", str(d / "train.csv"), "--out", str(d / "out"), *FAST, *extra]
        if test_df is not None:
            write_pair(test_df, d / "test.csv", side)
            argv += ["--test", str(d / "test.csv")]
        before = set(p.name for p in d.iterdir())
        res = run_cli(argv)
        self.record(cls, judge(res, d / "out", before, d, expect, "identification.json"), note)

    def close(self, cls, note, test_df, sidecar=None, expect="refuse"):
        d = self.case_dir()
        write_pair(self.train, d / "train.csv", self.sidecar)
        write_pair(test_df, d / "test.csv", {**self.sidecar, **(sidecar or {})})
        argv = ["close-loop", "--train", str(d / "train.csv"), "--test", str(d / "test.csv"), "--report-dir",
                str(d / "out"), *CLOSE_FAST]
        before = set(p.name for p in d.iterdir())
        res = run_cli(argv)
        self.record(cls, judge(res, d / "out", before, d, expect, "report.json"), note)

    def run(self, n_structural: int) -> None:
        base = self.all.assign(temperature_C=25.0)
        for name, (f, side) in UNIT_MISTAKES.items():
            self.identify("wrong units in TRAIN (identify)", name, f(base), sidecar=side)
            self.identify("wrong units in TEST (identify --test)", name, self.train.assign(temperature_C=25.0),
                          f(self.test.assign(temperature_C=25.0)), sidecar=side if side else None)
            if self.close_loop:
                self.close("wrong units in TEST (close-loop)", name, f(self.test.assign(temperature_C=25.0)),
                           sidecar=side)
        text = self.all.to_csv(index=False, lineterminator="\n")
        for kind, corrupted in structural_cases(text, n_structural, seed=14):
            self.identify("structural corruption (identify)", kind, None, text=corrupted, expect="any")
        one = self.all[self.all["run"] == self.all["run"].iloc[0]]
        self.identify("single-run TRAIN", "one run", one)
        inner = self.train[self.train["position_m"].abs() <= 0.008]
        self.identify("extrapolation (TEST outside TRAIN)", "TRAIN |s| <= 8 mm, TEST full stroke", inner,
                      self.test, expect="flag")
        lo_v = self.train[self.train["voltage_V"] < self.train["voltage_V"].max()]
        self.identify("extrapolation (TEST outside TRAIN)", "TEST voltage above TRAIN's", lo_v,
                      self.test[self.test["voltage_V"] == self.test["voltage_V"].max()], expect="flag")
        light = self.train[self.train["load_kg"].abs() < 0.04]
        self.identify("extrapolation (TEST outside TRAIN)", "TEST loads above TRAIN's", light,
                      self.all[self.all["load_kg"].abs() > 0.06], expect="flag")
        # --out pointing at an existing file
        d = self.case_dir()
        write_pair(self.all, d / "all.csv", self.sidecar)
        (d / "taken").write_text("x")
        before = set(p.name for p in d.iterdir())
        res = run_cli(["identify", "--train", str(d / "all.csv"), "--out", str(d / "taken"), *FAST])
        v = judge(res, d / "taken", before, d, "refuse", "identification.json")
        v["written"] = (d / "taken").read_text() != "x"
        self.record("--out is an existing file", v, f"{res['seconds']:.1f} s to refuse")
        # valid control
        self.identify("valid control (identify)", "rig data as written", self.all, expect="any")
        self.run_issue30()

    def run_issue30(self) -> None:
        """The cases of issue 30 the original campaign lacked (whole-file physics, TEST vs TRAIN, hostile input)."""
        base = self.all.assign(temperature_C=25.0)
        runs = list(pd.unique(base["run"]))
        zero = [r for r in runs if base.loc[base.run == r, "load_kg"].iloc[0] == 0.0]
        d = base.copy()
        d.loc[d.run == zero[0], "voltage_V"] = 0.0
        self.identify("run contradicts its speed (identify)", "one run's voltage zeroed", d)
        d = base.copy()
        m = d.run == zero[1]
        d.loc[m, "direction"] = -d.loc[m, "direction"]
        self.identify("run contradicts its speed (identify)", "one run's direction flipped", d)
        d = base.copy()
        idx = d.index[d.run == runs[2]]
        d.loc[idx[len(idx) // 2]:, "time_s"] += 1e6
        self.identify("clock jump (identify)", "1e6 s inside a run", d)
        test = self.test.assign(temperature_C=25.0)
        train = self.train.assign(temperature_C=25.0)
        self.identify("TEST against TRAIN (identify --test)", "TEST direction flipped", train,
                      test.assign(direction=-test["direction"]))
        self.identify("TEST against TRAIN (identify --test)", "TEST sidecar slider mass in lb", train, test,
                      sidecar={"slider_mass_kg": self.sidecar["slider_mass_kg"] / 0.45359237})
        self.identify("TEST against TRAIN (identify --test)", "TEST directions never seen in TRAIN",
                      train[train["direction"] == 1], test[test["direction"] == -1], expect="flag")
        # strict sidecars
        d = self.case_dir()
        write_pair(base, d / "train.csv", self.sidecar)
        (d / "train.json").write_text('{"slider_mass_kg": 0.12, "slider_mass_kg": 0.5}')
        self._run_dir("strict sidecar", "duplicate key", d, ["identify", "--train", str(d / "train.csv"), "--out",
                                                             str(d / "out"), *FAST])
        d = self.case_dir()
        write_pair(base, d / "train.csv", self.sidecar)
        (d / "train.json").write_text('{"a":' * 100_000 + "1" + "}" * 100_000)
        self._run_dir("strict sidecar", "nested 100,000 deep", d, ["identify", "--train", str(d / "train.csv"),
                                                                   "--out", str(d / "out"), *FAST])
        big = base.assign(run=[str(int(r) + 2**63 + 5) for r in base["run"]])
        self.identify("run ids beyond int64", "ids 2^63 + k", big, expect="any")

    def _run_dir(self, cls: str, note: str, d: Path, argv: list[str], expect: str = "refuse") -> None:
        before = set(p.name for p in d.iterdir())
        res = run_cli(argv)
        self.record(cls, judge(res, d / "out", before, d, expect, "identification.json"), note)

    def output_folders(self) -> list[tuple[str, str, int]]:
        """Output-folder scenarios of issue 30: (scenario, first line of stderr, files lost)."""
        rows = []
        d = self.case_dir()
        rig = d / "rig"
        shutil.copytree(self.rig, rig)
        before = {p.name: p.read_bytes() for p in rig.iterdir() if p.is_file()}
        res = run_cli(["identify", "--train", str(rig / "train.csv"), "--out", str(rig), *FAST])
        lost = sum(1 for n, b in before.items() if not (rig / n).exists() or (rig / n).read_bytes() != b)
        rows.append(("identify --out <the rig folder it reads>", res["stderr"].strip()[:110], lost))
        ident = d / "ident"
        res = run_cli(["identify", "--train", str(rig / "train.csv"), "--out", str(ident), *FAST])
        kept = (ident / "identification.json").read_bytes() if res["code"] == 0 else b""
        res = run_cli(["close-loop", "--train", str(rig / "train.csv"), "--report-dir", str(ident), *CLOSE_FAST])
        lost = int(bool(kept) and (not (ident / "identification.json").exists()
                                   or (ident / "identification.json").read_bytes() != kept))
        rows.append(("close-loop --report-dir <an identify result>", res["stderr"].strip()[:110], lost))
        import os
        cwd = os.getcwd()
        work = d / "cwd"
        work.mkdir()
        shutil.copy(rig / "train.csv", work / "train.csv")
        shutil.copy(rig / "train.json", work / "train.json")
        os.chdir(work)
        try:
            res = run_cli(["identify", "--train", "train.csv", "--out", ".", *FAST])
        finally:
            os.chdir(cwd)
        lost = int(not (work / "train.csv").exists())
        rows.append(("identify --out .", res["stderr"].strip()[:110], lost))
        return rows

    def table(self) -> str:
        head = f"{'input class':42s} {'tried':>5s} {'refused':>7s} {'traceback':>9s} {'written':>7s} " \
               f"{'silently wrong':>14s} {'accepted':>8s}"
        lines = [head, "-" * len(head)]
        tot = np.zeros(6, int)
        for cls, rows in self.rows.items():
            c = np.array([len(rows), sum(r["refused"] for r in rows), sum(r["traceback"] for r in rows),
                          sum(r["written"] for r in rows), sum(r["wrong"] for r in rows),
                          sum(r["accepted"] for r in rows)])
            tot += c
            lines.append(f"{cls:42s} {c[0]:5d} {c[1]:7d} {c[2]:9d} {c[3]:7d} {c[4]:14d} {c[5]:8d}")
        lines.append("-" * len(head))
        lines.append(f"{'total':42s} {tot[0]:5d} {tot[1]:7d} {tot[2]:9d} {tot[3]:7d} {tot[4]:14d} {tot[5]:8d}")
        return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", type=Path, help="folder of `l1b2 rig` (default: generate a reduced plan)")
    ap.add_argument("--work", type=Path, help="folder for the malformed files (default: a temporary one)")
    ap.add_argument("--full-plan", action="store_true", help="generate the paper's full 72-run plan")
    ap.add_argument("--structural", type=int, default=60, help="number of structural corruptions")
    ap.add_argument("--close-loop", action="store_true", help="also run close-loop on the wrong-unit TEST files")
    ap.add_argument("--details", action="store_true", help="print every case's message")
    args = ap.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="l1b2_campaign_"))
    rig = args.rig
    if rig is None:
        rig = work / "rig"
        plan = [] if args.full_plan else ["--voltages=250,324", "--loads=-0.07,-0.05,0,0.05,0.07"]
        res = run_cli(["rig", "--out", str(rig), "--engine", "inprocess", "--quiet", "--no-plots",
                       "--step", "0.001", *plan])
        if res["code"] != 0:
            print(res["stderr"], file=sys.stderr)
            return 1
    c = Campaign(rig, work / "cases", args.close_loop)
    t0 = time.perf_counter()
    c.run(args.structural)
    if args.details:
        for cls, rows in c.rows.items():
            for r in rows:
                flag = "WRONG " if r["wrong"] else ("TRACEBACK " if r["traceback"] else "")
                print(f"[{cls}] {r['note']}: {flag}{'accepted' if r['accepted'] else r['message']}")
    print(c.table())
    print()
    print(f"{'output-folder scenario':48s} {'files lost':>10s}  message")
    for name, msg, lost in c.output_folders():
        print(f"{name:48s} {lost:10d}  {msg}")
    print(f"({time.perf_counter() - t0:.0f} s; files in {work})")
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
