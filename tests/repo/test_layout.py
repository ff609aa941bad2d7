"""The package's layout holds as the README's Layout section draws it: imports run down the floors, modules and
functions stay small, and no two modules are named alike for different things. The lab (`lab/`, outside the wheel)
is the floor above everything: it may import the package, the package never imports it.

Read from the code itself (every `import` and `from ... import`, lazy ones inside functions included), so a new arrow
up the floors fails here with the file that draws it."""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "lerobot_blindgrasp"
LAB = ROOT / "lab"  # benchmarks, the twin's measurement campaign, research diagnosis: not in the wheel

# Floors, bottom first: a folder (or top-level module) may import only from floors below its own.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("spec", "durable"),
    ("spaces", "cli", "project", "compat"),
    ("shipped", "hardware", "policy_contract"),
    ("sim", "policies", "robots"),
    ("results", "presets", "teleoperators", "cards"),
    ("envs", "emulators"),
    ("rollout",),
    ("teacher",),
    ("demos",),
    ("twin",),
    ("pipeline", "hub", "deploy"),
)
FLOOR = {room: k for k, rooms in enumerate(FLOORS) for room in rooms}
# Arrows that may run up, each with its reason (the README's Layout section names them).
EXCEPTIONS: dict[tuple[str, str], str] = {}
MAX_MODULE_LINES, MAX_FUNCTION_LINES = 350, 60
# Modules allowed more lines, each with its cap and reason.
LONG_MODULES: dict[str, tuple[int, str]] = {
    "policy_contract.py": (
        380,
        "the policy-vs-robot contract is one module: what a checkpoint records, and the check every caller runs",
    ),
    "teleoperators/manus_glove/manus_bridge.py": (
        620,
        "the glove bridge is one file a lab copies to the MANUS machine: names, datagram, ROS 2 and SDK sources, CLI",
    ),
}
# Modules that share a name on purpose: the same role in parallel folders.
SAME_NAME_OK = {"__init__.py", "__main__.py"}


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "lerobot_blindgrasp" and len(parts) > 1 else None


def _sources(*roots: Path):
    for path in sorted(p for root in roots or (PACKAGE,) for p in root.rglob("*.py")):
        yield path, ast.parse(path.read_text(), str(path))


def _imported(tree: ast.AST) -> set[str]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            if node.module == "lerobot_blindgrasp":
                found |= {f"lerobot_blindgrasp.{a.name}" for a in node.names}
    return found


def test_every_room_has_a_floor():
    rooms = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir() if not p.name.startswith(("_", "."))}
    rooms = {r for r in rooms if (PACKAGE / r).is_dir() or (PACKAGE / f"{r}.py").is_file()}
    assert rooms <= set(FLOOR), f"folders or modules without a floor: {sorted(rooms - set(FLOOR))}"


def test_imports_run_down_the_floors():
    up = []
    for path, tree in _sources():
        rel = path.relative_to(PACKAGE)
        if rel.as_posix() == "__init__.py":  # the package's face registers the plugins
            continue
        src = rel.parts[0].removesuffix(".py")
        for module in _imported(tree):
            dst = _room(module)
            if dst is None or dst == src or dst == "__version__" or (src, dst) in EXCEPTIONS:
                continue
            if FLOOR.get(dst, 0) >= FLOOR[src]:
                up.append(f"{rel} imports {module} (floor {FLOOR.get(dst)} from floor {FLOOR[src]})")
    assert not up, "imports that do not run down the floors:\n" + "\n".join(up)


def test_the_package_never_imports_the_lab():
    """The wheel carries the package alone, so an import of `lab` from it would fail for every user."""
    up = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path, tree in _sources()
        for module in _imported(tree)
        if module == "lab" or module.startswith("lab.")
    ]
    assert LAB.is_dir() and not up, "the package imports the lab:\n" + "\n".join(up)


def test_modules_and_functions_are_small():
    big = []
    for path, tree in _sources(PACKAGE, LAB):
        rel = path.relative_to(ROOT)
        lines = len(path.read_text().splitlines())
        key = path.relative_to(PACKAGE).as_posix() if path.is_relative_to(PACKAGE) else rel.as_posix()
        if lines > LONG_MODULES.get(key, (MAX_MODULE_LINES,))[0]:
            big.append(f"{rel}: {lines} lines")
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    big.append(f"{rel}:{node.lineno} {node.name}: {n} lines")
    assert not big, "over the size limits:\n" + "\n".join(big)


def test_no_two_modules_are_named_alike():
    files = [p for root in (PACKAGE, LAB) for p in root.rglob("*.py") if p.name not in SAME_NAME_OK]
    names = Counter(p.name for p in files)
    twice = {n: sorted(str(p.relative_to(ROOT)) for p in files if p.name == n) for n, c in names.items() if c > 1}
    assert not twice, f"modules named alike: {twice}"


# Test folders besides the package's rooms: the lab's tools, and the repository's own checks (layout, docs, wheel).
TEST_FOLDERS_BESIDES_ROOMS = {"lab", "repo"}
TEST_SUPPORT = {"data", "emulators"}  # the emulated rig and recorded data, shared by every folder


def test_the_tests_mirror_the_package():
    """Every test file sits in the folder of the room it tests (tests/robots/ for lerobot_blindgrasp/robots/, ...),
    and no two share a file name (pytest imports them by name, and docs/hardware.md cites them by name)."""
    rooms = {p.name for p in PACKAGE.iterdir() if p.is_dir() and not p.name.startswith("__")}
    tests = ROOT / "tests"
    stray = sorted(p.name for p in tests.glob("test_*.py"))
    assert not stray, f"test files outside a folder: {stray}"
    folders = {p.name for p in tests.iterdir() if p.is_dir() and not p.name.startswith("__")} - TEST_SUPPORT
    assert folders <= rooms | TEST_FOLDERS_BESIDES_ROOMS, sorted(folders - rooms - TEST_FOLDERS_BESIDES_ROOMS)
    names = [p.name for p in tests.rglob("test_*.py")]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
