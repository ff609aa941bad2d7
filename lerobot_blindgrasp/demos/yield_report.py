"""Per-object yield of a collection: counts, the printed table and `yield_report.json` in the dataset folder. Counts
are cumulative over `--resume` runs; `rollouts` includes those of objects that already had their quota.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from lerobot_blindgrasp import durable

REPORT_NAME = "yield_report.json"


@dataclass
class ObjectTally:
    rollouts: int = 0  # finished rollouts with sane physics
    passed: int = 0  # met both curation criteria
    kept: int = 0  # written to the dataset
    frames: int = 0  # frames written
    success: int = 0  # env success latch (lifted >= 1.5 cm, held >= 1 s within 5 s)
    left_workspace: int = 0
    physics_failed: int = 0  # never written, not counted in rollouts
    force_sum_n_total: float = 0.0  # over rollouts, for the mean

    @property
    def yield_rate(self) -> float:
        return self.passed / self.rollouts if self.rollouts else 0.0


@dataclass
class Tally:
    objects: dict[str, ObjectTally] = field(default_factory=dict)

    def of(self, name: str) -> ObjectTally:
        return self.objects.setdefault(name, ObjectTally())

    def total(self) -> ObjectTally:
        t = ObjectTally()
        for o in self.objects.values():
            for k, v in asdict(o).items():
                setattr(t, k, getattr(t, k) + v)
        return t

    def to_json(self) -> dict:
        rows = {
            name: {**asdict(o), "yield": o.yield_rate, "force_sum_n_mean": _mean(o.force_sum_n_total, o.rollouts)}
            for name, o in self.objects.items()
        }
        t = self.total()
        return {"objects": rows, "total": {**asdict(t), "yield": t.yield_rate}}

    @classmethod
    def from_json(cls, data: dict) -> Tally:
        names = set(ObjectTally.__dataclass_fields__)
        rows = data["objects"].items()
        return cls({name: ObjectTally(**{f: v for f, v in row.items() if f in names}) for name, row in rows})


def _mean(total: float, n: int) -> float:
    return total / n if n else 0.0


def format_table(tally: Tally, order: list[str] | None = None) -> str:
    names = order or list(tally.objects)
    head = (
        f"{'object':<20} {'rollouts':>8} {'passed':>7} {'yield':>7} {'kept':>6} {'frames':>8} {'success':>8} "
        f"{'F sum':>8}"
    )
    lines = [head, "-" * len(head)]

    def row(name: str, o: ObjectTally) -> str:
        succ = o.success / o.rollouts if o.rollouts else 0.0
        return (
            f"{name:<20} {o.rollouts:>8d} {o.passed:>7d} {o.yield_rate:>7.1%} {o.kept:>6d} {o.frames:>8d} "
            f"{succ:>8.1%} {_mean(o.force_sum_n_total, o.rollouts):>8.0f}"
        )

    lines += [row(name, tally.of(name)) for name in names]
    lines += ["-" * len(head), row("total", tally.total())]
    return "\n".join(lines)


def write_yield_report(root: Path, tally: Tally, extra: dict) -> Path:
    path = Path(root) / REPORT_NAME
    durable.atomic_write_json(path, {**extra, **tally.to_json()}, indent=2)
    return path


def load_tally(root: Path) -> Tally:
    path = Path(root) / REPORT_NAME
    return Tally.from_json(json.loads(path.read_text())) if path.is_file() else Tally()
