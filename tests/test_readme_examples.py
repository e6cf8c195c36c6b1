"""Every code block of README.md and docs/**/*.md runs as written.

Convention for fenced blocks (checked here, so a block cannot go untested by accident):

* ```` ```python ```` blocks run with ``exec``, ```` ```bash ```` blocks with ``bash -e``, in the page's
  order, in one fresh folder per page (Python blocks of a page share one namespace). The folder holds
  ``rigdata/`` (a small virtual-rig data set in the data format), ``dist/`` (``l1b2 export``) and links to
  the repository's ``fmu_src`` and ``system_models``, as a clone does; ``l1b2`` and ``python`` are the
  test's interpreter's.
* ```` ```csv ````, ```` ```json ```` and ```` ```toml ```` blocks are parsed (a study spec also by the spec
  reader); ```` ```text ```` blocks are output or diagrams and are not run.
* ``<!-- snippet: skip (reason) -->`` on the line before a block: not run, and the reason is required
  (e.g. the Makefile targets themselves, or a second machine). ``<!-- snippet: slow -->``: run only by
  the slow test of the page (``-m slow``).
* ``docs/tutorial.md`` is run end to end by ``tests/test_tutorial.py``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
FENCE = re.compile(r"^(?P<indent> *)```(?P<lang>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
MARK = re.compile(r"<!--\s*snippet:\s*(?P<kind>skip|slow)\s*(?P<reason>\(.*\))?\s*-->\s*$")
RUN = {"python", "bash"}
PARSE = {"csv", "json", "toml"}
KNOWN = RUN | PARSE | {"text"}
SEPARATE = {"docs/tutorial.md",          # its own test (tests/test_tutorial.py), with timing and outputs checked
            "docs/how-to/python-api.md"}  # run by test_python_api_examples_produce_their_outputs


def blocks(path: Path) -> list[dict]:
    text = path.read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1].strip()
        mark = MARK.match(before)
        line = text[:m.start()].count("\n") + 1
        out.append(dict(lang=m.group("lang").strip(), body=textwrap.dedent(m.group("body")), line=line,
                        mark=mark.group("kind") if mark else None,
                        reason=(mark.group("reason") or "") if mark else ""))
    return out


def rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def _runnable_pages(slow: bool) -> list:
    params = []
    for page in PAGES:
        if rel(page) in SEPARATE:
            continue
        bl = [b for b in blocks(page) if b["lang"] in RUN and b["mark"] != "skip"]
        if not bl:
            continue
        has_slow = any(b["mark"] == "slow" for b in bl)
        if slow and has_slow:
            params.append(pytest.param(page, id=rel(page), marks=pytest.mark.slow))
        elif not slow and any(b["mark"] != "slow" for b in bl):
            params.append(pytest.param(page, id=rel(page)))
    return params


# ---------------------------------------------------------------------------
# the convention itself
# ---------------------------------------------------------------------------

def test_every_block_follows_the_convention():
    problems = []
    for page in PAGES:
        for b in blocks(page):
            where = f"{rel(page)}:{b['line']}"
            if b["lang"] not in KNOWN:
                problems.append(f"{where}: block language {b['lang']!r} is none of {sorted(KNOWN)}")
            if b["mark"] == "skip" and len(b["reason"]) < 8:
                problems.append(f"{where}: a skipped block needs a reason, <!-- snippet: skip (why) -->")
    assert not problems, "\n".join(problems)


def _outside_words() -> tuple[str, ...]:
    """What a file would write to point outside the repository: ``../<folder>`` for every folder beside the
    checkout that is not itself a checkout of this project, ``<folder>/<entry>`` for each of its entries (suffix
    dropped), and the name of the physics document those folders hold."""
    words = ["physics notes"]
    for sibling in sorted(ROOT.parent.iterdir()):
        if sibling.name.startswith(".") or not sibling.is_dir() or (sibling / "fmu_src").is_dir():
            continue
        words.append(f"../{sibling.name}")
        words += [f"{sibling.name}/{entry.stem}" for entry in sibling.iterdir() if not entry.name.startswith(".")]
    return tuple(dict.fromkeys(words))


def test_nothing_points_outside_the_repository():
    # reference: the repository is self-contained (the data format and physics decisions live in docs/); the
    # forbidden words come from the folders beside the checkout, so this file names none of them
    words = _outside_words()
    hits = []
    for folder in ("fmu_src", "tests", "bench", "docs", "system_models"):
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in {".py", ".md", ".toml", ".c", ".ssd"} and path.is_file():
                text = path.read_text(encoding="utf-8", errors="replace")
                for word in words:
                    if word in text and path != Path(__file__):
                        hits.append(f"{rel(path)}: {word}")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    hits += [f"README.md: {w}" for w in words if w in readme]
    assert not hits, "\n".join(hits)


@pytest.mark.parametrize("page", [p for p in PAGES if any(b["lang"] in PARSE for b in blocks(p))], ids=rel)
def test_data_blocks_parse(page):
    for b in blocks(page):
        if b["lang"] == "json":
            json.loads(b["body"])
        elif b["lang"] == "toml":
            doc = tomllib.loads(b["body"])
            if "study" in doc:
                from l1b2.sweep.spec import parse_spec
                parse_spec(b["body"], source=f"{rel(page)}:{b['line']}")
        elif b["lang"] == "csv":
            from io import StringIO

            from l1b2.data.columns import REQUIRED_COLUMNS
            df = pd.read_csv(StringIO(b["body"]))
            assert set(REQUIRED_COLUMNS) <= set(df.columns), f"{rel(page)}:{b['line']}"


# ---------------------------------------------------------------------------
# running the blocks
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """rigdata/ (16 traverses, in-process, 1 ms) and dist/ (l1b2 export), made once for all pages."""
    from l1b2.fmi.export import export_all
    from l1b2.physics.params import load_motor
    from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment

    base = tmp_path_factory.mktemp("docs_base")
    plan = RigPlan(voltages_V=(220.0, 324.0), loads_kg=(-0.09, 0.0, 0.05, 0.09), step_s=1e-3)
    mp = load_motor()
    df, truth = run_experiment(plan, mp, engine="inprocess")
    write_experiment(df, base / "rigdata", mp, plan, truth)
    export_all(base / "dist", mp=None, predictor=None)
    return base


def _folder(prepared: Path, tmp_path: Path, page: Path) -> Path:
    """The page's folder; rigdata/ and dist/ only when the page does not make them itself."""
    work = tmp_path / "work"
    work.mkdir()
    text = page.read_text(encoding="utf-8")
    if "--out rigdata" not in text:
        shutil.copytree(prepared / "rigdata", work / "rigdata")
    if "--out dist" not in text:
        (work / "dist").symlink_to(prepared / "dist")
    for name in ("fmu_src", "system_models"):
        (work / name).symlink_to(ROOT / name)
    return work


def run_blocks(page: Path, work: Path, monkeypatch, include_slow: bool, timeout_s: float = 600.0) -> dict:
    """Run the page's blocks in ``work``; the Python blocks' namespace."""
    monkeypatch.chdir(work)
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env.setdefault("MPLBACKEND", "Agg")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    namespace: dict = {"__name__": "__doc_snippet__"}
    for b in blocks(page):
        if b["lang"] not in RUN or b["mark"] == "skip" or (b["mark"] == "slow" and not include_slow):
            continue
        where = f"{rel(page)}:{b['line']}"
        if b["lang"] == "python":
            exec(compile(b["body"], where, "exec"), namespace)  # noqa: S102 - our own documentation
        else:
            proc = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", b["body"]], cwd=work, env=env,
                                  capture_output=True, text=True, timeout=timeout_s)
            assert proc.returncode == 0, f"{where} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n" \
                                         f"{proc.stderr[-3000:]}"
    import matplotlib.pyplot as plt
    plt.close("all")
    return namespace


@pytest.mark.parametrize("page", _runnable_pages(slow=False))
def test_page_blocks_run(page, prepared, tmp_path, monkeypatch):
    run_blocks(page, _folder(prepared, tmp_path, page), monkeypatch, include_slow=False)


@pytest.mark.parametrize("page", _runnable_pages(slow=True))
def test_page_blocks_run_with_slow(page, prepared, tmp_path, monkeypatch):
    run_blocks(page, _folder(prepared, tmp_path, page), monkeypatch, include_slow=True)


def test_python_api_examples_produce_their_outputs(prepared, tmp_path, monkeypatch):
    # reference: the how-to's own words: runs.png, the close-loop report, the co-simulation's plot
    page = ROOT / "docs/how-to/python-api.md"
    work = _folder(prepared, tmp_path, page)
    run_blocks(page, work, monkeypatch, include_slow=False)
    assert (work / "runs.png").stat().st_size > 0
    assert (work / "closeloop_report" / "report.json").is_file()
    assert (work / "cosim.png").stat().st_size > 0


def test_docs_build_strict(tmp_path):
    # reference: the issue - `make docs` builds with no warnings (mkdocs --strict); skipped without mkdocs
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    pytest.importorskip("mkdocstrings")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert (tmp_path / "site" / "reference" / "fmu-variables" / "index.html").is_file()
    html = (tmp_path / "site" / "reference" / "fmu-variables" / "index.html").read_text()
    assert "V_s" in html and "Slider.s0" in html


def test_readme_is_short_and_links_into_the_docs():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    for page in re.findall(r"\]\((docs/[^)#]+)", text):
        assert (ROOT / page).is_file(), page
