"""The repository's structure in figures: lines of Python per folder of the package, tracked files per top-level
folder, and the import arrows between the package's rooms (its folders and top-level modules).

    python -m lab.structure                                  # markdown on stdout
    python -m lab.structure --output=docs/results/structure.md

An arrow is a module of one room importing a module of another (lazy imports inside functions count, as in
tests/test_layout.py). Rooms are counted as pairs (room A imports room B, however many modules draw it) and as
module arrows (module a imports room B). A cycle is a set of rooms that reach each other through their arrows.
Lines are every line of the tracked `.py` files, as `find DIR -name '*.py' | xargs cat | wc -l` counts them.
"""

from __future__ import annotations

import ast
import subprocess
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

from lerobot_blindgrasp import durable
from lerobot_blindgrasp.cli import parse_config

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "lerobot_blindgrasp"
WHEEL = (PACKAGE, "lerobot_policy_blindgrasp")  # setup.py's packages


def tracked(root: Path = ROOT) -> list[str]:
    return subprocess.run(["git", "ls-files"], cwd=root, capture_output=True, text=True, check=True).stdout.split()


def lines(path: Path) -> int:
    return len(path.read_bytes().splitlines())


def room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == PACKAGE and len(parts) > 1 else None


def module_name(path: str) -> str:
    name = path.removesuffix(".py").replace("/", ".")
    return name.removesuffix(".__init__")


def imported(tree: ast.AST) -> set[str]:
    """Every absolute module a source imports, `from X import Y` counted as X.Y too for the package (Y may be a
    module). The layout test reads imports through this function too."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            if node.module == PACKAGE:
                found |= {f"{PACKAGE}.{a.name}" for a in node.names}
    return found


def arrows(files: list[str], root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the other rooms it imports, for every module of the package."""
    out = {}
    rooms = {room(module_name(f)) for f in files if f.startswith(f"{PACKAGE}/") and f.endswith(".py")}
    for f in files:
        if f.startswith(f"{PACKAGE}/") and f.endswith(".py"):
            mod = module_name(f)
            if room(mod) is None:  # the package's __init__: its imports register the plugin, no room draws them
                continue
            targets = {room(m) for m in imported(ast.parse((root / f).read_text(), f))} - {None}
            out[mod] = {t for t in targets if t in rooms and t != room(mod)}  # not a name like __version__
    return out


def cycles(pairs: set[tuple[str, str]]) -> list[set[str]]:
    """The rooms that reach each other (strongly connected sets of more than one room)."""
    reach = defaultdict(set)
    for a, b in pairs:
        reach[a].add(b)
    changed = True
    while changed:  # transitive closure: a few dozen rooms
        changed = False
        for a in list(reach):
            more = set().union(*(reach[b] for b in reach[a] if b in reach)) - reach[a]
            if more:
                reach[a] |= more
                changed = True
    found = {frozenset({a} | {b for b in reach[a] if a in reach.get(b, ())}) for a in reach}
    return [set(c) for c in found if len(c) > 1]


def render(root: Path = ROOT) -> str:
    files = tracked(root)
    py = [f for f in files if f.endswith(".py")]
    per_room = Counter()
    for f in py:
        if f.startswith(f"{PACKAGE}/"):
            per_room[f.split("/")[1].removesuffix(".py") if f.count("/") > 1 else "(top-level modules)"] += lines(
                root / f
            )
    wheel = sum(lines(root / f) for f in py if f.split("/")[0] in WHEEL)
    top = Counter(f.split("/")[0] if "/" in f else "(root files)" for f in files)
    top_lines = Counter()
    for f in py:
        top_lines[f.split("/")[0] if "/" in f else "(root files)"] += lines(root / f)
    mods = arrows(files, root)
    pairs = {(room(m), t) for m, ts in mods.items() for t in ts}
    out = [
        "# Structure",
        "",
        "Made by `python -m lab.structure` (see its docstring for what each figure counts).",
        "",
    ]
    out += [f"- The wheel's package (`{'/`, `'.join(WHEEL)}/`): **{wheel:,}** lines of Python"]
    out += [f"- Tracked files (`git ls-files | wc -l`): **{len(files)}**"]
    out += [f"- Import arrows between the package's rooms: **{len(pairs)}** room pairs, drawn by"]
    out += [
        f"  **{sum(len(t) for t in mods.values())}** module arrows; cycles between rooms: **{len(cycles(pairs))}**"
    ]
    out += ["", "## Lines of Python per folder of the package", "", "| folder | lines |", "|---|---:|"]
    out += [f"| `{r}` | {n:,} |" for r, n in sorted(per_room.items(), key=lambda x: -x[1])]
    out += [
        "",
        "## Tracked files per top-level folder",
        "",
        "| folder | files | lines of Python |",
        "|---|---:|---:|",
    ]
    out += [f"| `{d}` | {n} | {top_lines[d]:,} |" for d, n in sorted(top.items(), key=lambda x: (-x[1], x[0]))]
    out += ["", "## Import arrows between rooms", "", "| room | imports from |", "|---|---|"]
    for r in sorted({a for a, _ in pairs}):
        out.append(f"| `{r}` | {', '.join(f'`{b}`' for b in sorted(b for a, b in pairs if a == r))} |")
    return "\n".join(out) + "\n"


@dataclass
class StructureConfig:
    output: Path | None = None  # a markdown file to write; none: print it


def main(argv: list[str] | None = None) -> None:
    """Print (or write) the structure figures of the checkout this module sits in."""
    cfg = parse_config(StructureConfig, argv)
    text = render()
    if cfg.output:
        durable.atomic_write_text(cfg.output, text)
    else:
        print(text, end="")


if __name__ == "__main__":
    main()
