"""The hazard analysis of docs/hardware.md is a table a reviewer checks row by row; these tests check what a
parser can: every input has its four axes (V value, T trend, O timing/order/age, C consistency), each as a row
or as "n/a" with a reason; every row that is not "n/a" names the class or function that implements its defence,
and each named one exists; every test a row names exists in the file it names; and the servo health levels shown
are the ones `hardware/xm430.py` states (`servo_diagnostics.levels_table()`)."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

from lerobot_blindgrasp.hardware import servo_diagnostics

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "lerobot_blindgrasp"
DOC = (ROOT / "docs" / "hardware.md").read_text(encoding="utf-8")
# Test files are named by file name alone: the names are unique across tests/'s folders (pytest needs them so).
TEST_FILES = {p.name: p for p in (ROOT / "tests").rglob("test_*.py")}
ANALYSIS = DOC[DOC.index("### Hazard analysis") : DOC.index("### Code map")]
AXES = set("VTOC")


def _rows() -> list[tuple[str, str, str, str]]:
    """(input, axis cell, implemented-by cell, test cell) of every row of the tables with an "axis: failure mode"
    column, and (pair, "", implemented-by cell, test cell) of the consistency table's."""
    out, axis_col, impl_col, current = [], None, None, ""
    for line in ANALYSIS.splitlines():
        if not line.startswith("|"):
            axis_col = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if "implemented by" in cells:
            axis_col = cells.index("axis: failure mode") if "axis: failure mode" in cells else -1
            impl_col = cells.index("implemented by")
        elif axis_col is not None and not all(c and set(c) <= set("-") for c in cells):
            current = cells[0] or current
            out.append((current, cells[axis_col] if axis_col >= 0 else "", cells[impl_col], cells[-1]))
    return out


def _tests(cell: str) -> list[tuple[str, str]]:
    """(file, test) of every test a test cell names: `file.py::test`, or a bare name, in the file named last."""
    found, file = [], None
    for name in re.findall(r"`([\w.:]+)`", cell):
        if "::" in name:
            file, name = name.split("::")
        assert file is not None, f"{name} in {cell!r} has no test file"
        found.append((file, name))
    return found


def _resolve(dotted: str) -> object:
    """`module.Name[.attr]`, the module by its file name (unique in the package, `test_layout.py` sees to it)."""
    stem, *names = dotted.split(".")
    paths = sorted(PACKAGE.rglob(f"{stem}.py"))
    assert len(paths) == 1 and names, f"{dotted}: {len(paths)} modules named {stem}.py"
    obj = importlib.import_module(".".join(paths[0].relative_to(ROOT).with_suffix("").parts))
    for name in names:
        obj = getattr(obj, name)
    return obj


def test_every_input_has_its_four_axes():
    covered: dict[str, set[str]] = {}
    for name, axis, _, _ in _rows():
        if not axis:
            continue
        letters = axis.split(":", 1)[0]
        assert set(re.findall(r"[A-Z]", letters)) <= AXES and ":" in axis, (name, axis)
        covered.setdefault(name, set()).update(re.findall(r"[VTOC]", letters))
    missing = {name: sorted(AXES - axes) for name, axes in covered.items() if axes != AXES}
    assert len(covered) >= 60 and not missing, missing


def test_every_cited_test_exists():
    defined: dict[str, set[str]] = {}
    missing = []
    for name, _, _, cell in _rows():
        assert not re.search(r"\b[A-Z][A-Z0-9]* `test_", cell), f"{name}: a test named by a letter code: {cell}"
        for file, test in _tests(cell):
            if file not in defined:
                assert file in TEST_FILES, f"{name}: no test file {file} under tests/"
                tree = ast.parse(TEST_FILES[file].read_text(encoding="utf-8"))
                defined[file] = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
            if test not in defined[file]:
                missing.append(f"{name}: {file}::{test}")
    assert len(defined) >= 15 and not missing, missing


def test_every_defence_names_the_class_or_function_that_implements_it():
    unnamed, missing, resolved = [], [], 0
    for name, axis, cell, _ in _rows():
        named = re.findall(r"`([\w.]+)`", cell)
        if axis.split(":", 2)[1:2] and axis.split(":", 2)[1].strip().startswith("n/a"):
            assert cell == "-", f"{name} {axis}: an n/a row names {cell}"
            continue
        if not named:
            unnamed.append(f"{name} {axis[:40]}")
        for dotted in named:
            try:
                _resolve(dotted)
                resolved += 1
            except (AssertionError, AttributeError, ImportError) as e:
                missing.append(f"{name}: {dotted} ({e})")
    assert resolved >= 140 and not unnamed and not missing, (unnamed, missing)


def test_the_levels_shown_are_the_ones_xm430_states():
    shown = DOC[DOC.index("<!-- levels: servo_diagnostics.levels_table() -->") : DOC.index("<!-- levels: end -->")]
    assert shown.split("\n", 1)[1].strip() == servo_diagnostics.levels_table()
    assert not re.search(r"\d+ degC|\d+\.\d V|\d+ %", servo_diagnostics.__doc__ or "")  # stated once, in xm430.py
