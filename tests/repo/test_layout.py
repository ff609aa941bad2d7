"""The package's layout holds as the README's Layout section draws it: imports run down the floors, modules and
functions stay small, no two public classes or functions share a name, and no two modules are named alike. The lab (`lab/`, outside the wheel)
is the floor above everything: it may import the package, the package never imports it.

Read from the code itself (every `import` and `from ... import`, lazy ones inside functions included), so a new arrow
up the floors fails here with the file that draws it."""

from __future__ import annotations

import ast
import tomllib
from collections import defaultdict
from pathlib import Path

from lab.structure import imported

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "lerobot_blindgrasp"
PLUGIN_FACE = ROOT / "lerobot_policy_blindgrasp"  # the module LeRobot's plugin discovery imports
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
    "teleoperators/manus_glove/manus_bridge.py": (
        620,
        "the glove bridge is one file a lab copies to the MANUS machine: names, datagram, ROS 2 and SDK sources, CLI",
    ),
}
# Modules that share a name on purpose: the same role in parallel folders.
SAME_NAME_OK = {"__init__.py", "__main__.py"}
# The one public name many modules define: `main`, a program's entry, which `[project.scripts]` names as
# `module:main` and `python -m` runs under `if __name__ == "__main__"` (LeRobot's `lerobot_train.main` and every CLI
# do the same). Nothing imports it by its bare name, so it never stands for two concepts in one reader's head.
ENTRY_POINT = "main"


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "lerobot_blindgrasp" and len(parts) > 1 else None


def _sources(*roots: Path):
    for path in sorted(p for root in roots or (PACKAGE,) for p in root.rglob("*.py")):
        yield path, ast.parse(path.read_text(), str(path))


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
        for module in imported(tree):
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
        for module in imported(tree)
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


def _public_defs(path: Path, tree: ast.Module):
    for node in tree.body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and not node.name.startswith(
            "_"
        ):
            yield node.name


def test_no_two_public_classes_or_functions_share_a_name():
    """A name says one concept: two public top-level classes or functions named alike in two modules (two
    `Schedule`s, four `collect`s) make every reader, and every `from ... import`, ask which one."""
    homes = defaultdict(list)
    for path, tree in _sources(PACKAGE, PLUGIN_FACE):
        for name in _public_defs(path, tree):
            homes[name].append(str(path.relative_to(ROOT)))
    twice = {name: where for name, where in homes.items() if len(where) > 1 and name != ENTRY_POINT}
    assert not twice, f"public classes or functions named alike: {twice}"


def test_every_main_is_a_programs_entry():
    """`main` may repeat only as a program's entry point: a console script, or a module run with `python -m`."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"].values()
    entries = {s.removesuffix(":main") for s in scripts if s.endswith(":main")}
    stray = []
    for path, tree in _sources(PACKAGE, PLUGIN_FACE):
        if ENTRY_POINT in _public_defs(path, tree):
            module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            if module not in entries and '__name__ == "__main__"' not in path.read_text():
                stray.append(module)
    assert not stray, f"`main` defined where no program starts: {stray}"


def test_no_two_modules_are_named_alike():
    """Alike up to a plural `s` too (`checkpoint.py` and `checkpoints.py` are one name to a reader)."""
    files = [p for root in (PACKAGE, LAB) for p in root.rglob("*.py") if p.name not in SAME_NAME_OK]
    homes = defaultdict(list)
    for p in files:
        homes[p.stem.removesuffix("s")].append(str(p.relative_to(ROOT)))
    twice = {stem: sorted(where) for stem, where in homes.items() if len(where) > 1}
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
