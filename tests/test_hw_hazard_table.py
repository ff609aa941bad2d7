"""The hazard analysis of docs/hardware.md is a table a reviewer checks row by row; these tests check what a
parser can: every input has its four axes (V value, T trend, O timing/order/age, C consistency), each as a row
or as "n/a" with a reason; every test a row names exists in the file its letter stands for; and the servo health
levels shown are the ones `hardware/xm430.py` states (`health.levels_table()`)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from lerobot_blindgrasp.hardware import servo_diagnostics as health

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "hardware.md").read_text(encoding="utf-8")
ANALYSIS = DOC[DOC.index("### Hazard analysis") : DOC.index("### Code map")]
AXES = set("VTOC")


def _legend() -> dict[str, str]:
    block = ANALYSIS[ANALYSIS.index("Test files") : ANALYSIS.index("others as")]
    return dict(re.findall(r"\*\*(\w+)\*\* `(test_\w+\.py)`", block))


def _rows() -> list[tuple[str, str, str]]:
    """(input, axis cell, test cell) of every row of the tables with an "axis: failure mode" column."""
    out, axis_col, current = [], None, ""
    for line in ANALYSIS.splitlines():
        if not line.startswith("|"):
            axis_col = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if "axis: failure mode" in cells:
            axis_col = cells.index("axis: failure mode")
        elif axis_col is not None and not all(c and set(c) <= set("-") for c in cells):
            current = cells[0] or current
            out.append((current, cells[axis_col], cells[-1]))
    return out


def _tests(cell: str, legend: dict[str, str]) -> list[tuple[str, str]]:
    """(file, test) of every test a test cell names: `file.py::test`, or names after a file letter; a bare name
    is in the file named last."""
    found, file = [], None
    for letter, name in re.findall(r"(?:\b([A-Z][A-Z0-9]*) )?`([\w.:]+)`", cell):
        if "::" in name:
            file, name = name.split("::")
        elif letter:
            assert letter in legend, f"{letter} in {cell!r} is not a test-file letter"
            file = legend[letter]
        assert file is not None, f"{name} in {cell!r} has no test file"
        found.append((file, name))
    return found


def test_every_input_has_its_four_axes():
    covered: dict[str, set[str]] = {}
    for name, axis, _ in _rows():
        letters = axis.split(":", 1)[0]
        assert set(re.findall(r"[A-Z]", letters)) <= AXES and ":" in axis, (name, axis)
        covered.setdefault(name, set()).update(re.findall(r"[VTOC]", letters))
    missing = {name: sorted(AXES - axes) for name, axes in covered.items() if axes != AXES}
    assert len(covered) >= 60 and not missing, missing


def test_every_cited_test_exists():
    legend = _legend()
    defined: dict[str, set[str]] = {}
    missing = []
    for name, _, cell in _rows():
        for file, test in _tests(cell, legend):
            if file not in defined:
                tree = ast.parse((ROOT / "tests" / file).read_text(encoding="utf-8"))
                defined[file] = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
            if test not in defined[file]:
                missing.append(f"{name}: {file}::{test}")
    assert len(defined) >= 15 and not missing, missing


def test_the_levels_shown_are_the_ones_xm430_states():
    shown = DOC[DOC.index("<!-- levels: health.levels_table() -->") : DOC.index("<!-- levels: end -->")]
    assert shown.split("\n", 1)[1].strip() == health.levels_table()
    assert not re.search(r"\d+ degC|\d+\.\d V|\d+ %", health.__doc__ or "")  # stated once, in xm430.py
