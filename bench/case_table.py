"""Print the close-the-loop cases recorded by the tests (``pytest --junitxml=FILE``) as a markdown table.

Usage: python bench/case_table.py FILE.xml [FILE.xml ...]
"""
import json
import sys
import xml.etree.ElementTree as ET


def rows(paths):
    for path in paths:
        for case in ET.parse(path).getroot().iter("testcase"):
            skipped = case.find("skipped")
            if case.find("failure") is not None or case.find("error") is not None:
                outcome = "fail"
            elif skipped is not None and skipped.get("type") == "pytest.xfail":
                outcome = "known miss (xfail)"  # a strict xfail: the check failed, as recorded in the test
            else:
                outcome = "pass"
            for prop in case.iter("property"):
                if prop.get("name") == "case":
                    yield {**json.loads(prop.get("value")), "test": outcome}


def cell(text: str) -> str:
    """A markdown table cell: a ``|`` in a name (``|load_kg|``, the load size) escaped, not a column break."""
    return text.replace("|", "\\|")


def channels_cell(ch) -> str:
    """The column "channels considered": how many channels and run-level signals, and which were significant."""
    if ch is None:
        return "-"  # a case recorded before the column existed
    sig = ", ".join(ch["significant"]) or "none"
    return f"{ch['channels']} channels + {ch['run_signals']} run-level signals; significant: {sig}"


def main(argv):
    print("| world | case | test | traced_to | effects added | TEST free-run nrmse before -> after | b0 "
          "| channels considered |")
    print("|---|---|---|---|---|---|---|---|")
    for r in sorted(rows(argv), key=lambda r: (r["world"], r["case"])):
        b0 = f"{100 * r['b0']:.2f} %" if r.get("b0") is not None else ""
        print(f"| {r['world']} | {cell(r['case'])} | {r['test']} | {cell(', '.join(r['traced_to']) or '-')} | "
              f"{cell(', '.join(r['added']) or '-')} | {100 * r['before']:.2f} -> {100 * r['after']:.2f} % | {b0} | "
              f"{cell(channels_cell(r.get('channels')))} |")


if __name__ == "__main__":
    main(sys.argv[1:])
