"""MkDocs hooks: pages generated from the code's own declarations.

Markers a page may hold (an HTML comment on a line of its own):

* ``<!-- l1b2:fmu-variables NAME -->``: the variable table of FMU ``NAME``
  (Driver, Stator, Interface, Slider, L1B2Motor, Predictor), from the block's
  declaration (:meth:`l1b2.cosim.blocks.Block.variables`) with the reference
  motor's values, i.e. what ``modelDescription.xml`` of the built FMU holds;
* ``<!-- l1b2:cli -->``: the help of every ``l1b2`` command, from the parser;
* ``<!-- l1b2:include FILE -->``: a Markdown file of the repository root
  (``CHANGELOG.md``), headings shifted down one level, links into ``docs/``
  rewritten relative to the page; the page says so when the file is absent;
* ``<!-- l1b2:decisions -->``: a list of the decision records in
  ``docs/decisions/`` (each also added to the navigation).

Links of the included and the decision pages that point outside the site
become code spans (the site is built with ``--strict``).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
MARKER = re.compile(r"^<!-- l1b2:(\S+)\s*(\S*)\s*-->\s*$", re.M)
LINK = re.compile(r"(?<!!)\[([^\]]*)\]\(([^)\s]+)\)")


def _fmt(x) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, float):
        return f"{x:.6g}"
    return str(x)


def _escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def fmu_variable_table(name: str) -> str:
    from l1b2.cosim.blocks import motor_defaults
    from l1b2.fmi.build import BLOCKS
    from l1b2.physics.params import load_motor

    mp = load_motor()
    cls = BLOCKS[name]
    if name == "Predictor":
        defaults = cls.baked_defaults(mp)
    else:
        defaults = motor_defaults(mp)
    variables = cls.variables(cls.params_from_defaults(defaults))
    rows = ["| name | causality | unit | start | min | max | description |", "|---|---|---|---|---|---|---|"]
    for v in variables:
        rows.append(f"| `{v.name}` | {v.causality} | {v.unit} | {_fmt(v.start)} | {_fmt(v.min)} | {_fmt(v.max)} "
                    f"| {_escape(v.description)} |")
    return "\n".join(rows) + f"\n\n{len(variables)} variables.\n"


def cli_reference() -> str:
    from l1b2.cli import build_parser

    parser = build_parser()
    out = ["```text", parser.format_help().rstrip(), "```", ""]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    seen = set()
    for name, p in sub.choices.items():
        if id(p) in seen:
            continue
        seen.add(id(p))
        out += [f"## `l1b2 {name}`", "", "```text", p.format_help().rstrip(), "```", ""]
    return "\n".join(out)


def _outside_links_to_code(markdown: str, page_dir: Path) -> str:
    """Links to files that are not pages or assets of the site become code spans."""
    def fix(m):
        text, target = m.group(1), m.group(2)
        if re.match(r"^[a-z]+://|^#|^mailto:", target):
            return m.group(0)
        path = (page_dir / target.split("#")[0]).resolve()
        if path.is_file() and DOCS in path.parents:
            return m.group(0)
        return f"{text} (`{target}`)" if text.strip("`") != target else f"`{target}`"
    return LINK.sub(fix, markdown)


def include(filename: str, page_dir: Path) -> str:
    path = ROOT / filename
    if not path.is_file():
        return f"*`{filename}` is not in this version of the repository yet.*\n"
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"^(#+) ", lambda m: "#" + m.group(1) + " ", text, flags=re.M)
    # links written relative to the repository root, e.g. docs/decisions/x.md
    text = LINK.sub(lambda m: f"[{m.group(1)}]({m.group(2)[5:]})" if m.group(2).startswith("docs/") else m.group(0),
                    text)
    return _outside_links_to_code(text, page_dir)


def decision_files() -> list[Path]:
    folder = DOCS / "decisions"
    return sorted(p for p in folder.glob("*.md") if p.name != "index.md") if folder.is_dir() else []


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return path.stem.replace("-", " ")


def decisions_index() -> str:
    files = decision_files()
    if not files:
        return "*No decision records in this version of the repository yet.*\n"
    return "\n".join(f"* [{_title(p)}](decisions/{p.name})" for p in files) + "\n"


def on_config(config, **kwargs):
    files = decision_files()
    index = DOCS / "decisions" / "index.md"
    if index.is_file():
        files = [index] + files
    for entry in config["nav"] or []:
        if isinstance(entry, dict) and "Decisions" in entry and files:
            first = entry["Decisions"]
            entry["Decisions"] = [first] + [{_title(p): f"decisions/{p.name}"} for p in files]
    return config


def on_page_markdown(markdown, page, config, files, **kwargs):
    page_dir = (DOCS / page.file.src_path).parent

    def expand(m):
        kind, arg = m.group(1), m.group(2)
        if kind == "fmu-variables":
            return fmu_variable_table(arg)
        if kind == "cli":
            return cli_reference()
        if kind == "include":
            return include(arg, page_dir)
        if kind == "decisions":
            return decisions_index()
        raise ValueError(f"{page.file.src_path}: unknown marker l1b2:{kind}")

    markdown = MARKER.sub(expand, markdown)
    if page.file.src_path.startswith("decisions/"):
        markdown = _outside_links_to_code(markdown, page_dir)
    return markdown
