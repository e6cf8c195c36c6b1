"""The test suite's own scheduling list (``conftest.COSTLY_FIRST``, decision 0030) names real test modules, and
every module that ``make test`` runs a slow test of."""

import re
from pathlib import Path

from conftest import COSTLY_FIRST, pytest_collection_modifyitems

HERE = Path(__file__).resolve().parent


def test_every_module_of_the_costly_first_list_exists_once():
    # reference: the files of tests/; a renamed module would silently lose its place at the front
    assert len(set(COSTLY_FIRST)) == len(COSTLY_FIRST)
    assert [n for n in COSTLY_FIRST if not (HERE / n).is_file()] == []


def test_every_module_with_a_slow_test_that_make_test_runs_is_listed():
    # reference: the files of tests/ that mark a test ci_slow (a slow test make test runs, decision 0080); a module
    # missing from the list would be handed out among the last and decide alone when its worker ends
    mark = re.compile(r"^\s*@pytest\.mark\.ci_slow\b|marks=\(?pytest\.mark\.ci_slow\b", re.M)
    marked = sorted(p.name for p in HERE.glob("test_*.py") if mark.search(p.read_text(encoding="utf-8")))
    assert marked and [n for n in marked if n not in COSTLY_FIRST] == []


class _Item:
    def __init__(self, name, i):
        self.path, self.i = Path("tests") / name, i


def test_the_listed_modules_come_first_and_every_module_keeps_its_tests_order():
    # reference: the list's order for the listed modules, the collection's order for the rest and within a module
    names = ["test_a.py", COSTLY_FIRST[-1], "test_b.py", COSTLY_FIRST[0], "test_a.py", COSTLY_FIRST[-1]]
    items = [_Item(n, i) for i, n in enumerate(names)]
    pytest_collection_modifyitems(None, items)
    listed = [it for it in items if it.path.name in COSTLY_FIRST]
    assert items[:len(listed)] == listed
    assert [it.i for it in items[len(listed):]] == [0, 2, 4]
    got = [(it.path.name, it.i) for it in listed]
    assert got == sorted(got, key=lambda p: (COSTLY_FIRST.index(p[0]), p[1]))
