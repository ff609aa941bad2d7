"""The package's layout holds as the README's Layout section draws it: imports run down the floors, modules and
functions stay small, and no two modules are named alike for different things.

Read from the code itself (every `import` and `from ... import`, lazy ones inside functions included), so a new arrow
up the floors fails here with the file that draws it."""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "lerobot_blindgrasp"

# Floors, bottom first: a folder (or top-level module) may import only from floors below its own.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("spec", "durable", "platform_id"),
    ("spaces", "cli", "project"),
    ("shipped", "hardware"),
    ("sim", "policies", "robots"),
    ("results", "presets", "teleoperators", "cards"),
    ("envs", "emulators"),
    ("rollout",),
    ("teacher",),
    ("demos",),
    ("analysis", "robustness", "bench", "twin"),
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


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "lerobot_blindgrasp" and len(parts) > 1 else None


def _sources():
    for path in sorted(PACKAGE.rglob("*.py")):
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


def test_modules_and_functions_are_small():
    big = []
    for path, tree in _sources():
        rel = path.relative_to(PACKAGE)
        lines = len(path.read_text().splitlines())
        if lines > LONG_MODULES.get(rel.as_posix(), (MAX_MODULE_LINES,))[0]:
            big.append(f"{rel}: {lines} lines")
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    big.append(f"{rel}:{node.lineno} {node.name}: {n} lines")
    assert not big, "over the size limits:\n" + "\n".join(big)


def test_no_two_modules_are_named_alike():
    names = Counter(p.name for p in PACKAGE.rglob("*.py") if p.name not in SAME_NAME_OK)
    twice = {n: sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob(n)) for n, c in names.items() if c > 1}
    assert not twice, f"modules named alike: {twice}"
