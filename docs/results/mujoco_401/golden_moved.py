"""What moved in the golden simulation between two runs: per setting, whether the exact quantities (successes,
dones, lengths, shapes, physics failures) are equal, which quantities are not bit-identical, and which envs' floats
moved, from which step on. The runs are `tests/sim/test_sim_golden.py --dump` files, one per MuJoCo version:

    python tests/sim/test_sim_golden.py --dump A.npz      # under one version
    python tests/sim/test_sim_golden.py --dump B.npz      # under the other
    python docs/results/mujoco_401/golden_moved.py A.npz B.npz
"""

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "tests"))
import golden_sim as g  # noqa: E402  (the record's machinery lives beside the tests)


def load(path: str) -> dict:
    data = np.load(path)
    out: dict = {}
    for key in data.files:
        setting, name = key.split("/", 1)
        out.setdefault(setting, {})[name] = data[key]
    return out


def first_moved_step(a: dict, b: dict, names: list[str]) -> dict[int, int]:
    """Env -> the first step at which any of `names` differs between the two runs."""
    first: dict[int, int] = {}
    for name in names:
        diff = (a[name] != b[name]).reshape(a[name].shape[0], a[name].shape[1], -1).any(axis=2)
        for env in range(diff.shape[1]):
            steps = np.flatnonzero(diff[:, env])
            if steps.size:
                first[env] = min(first.get(env, steps[0]), int(steps[0]))
    return dict(sorted(first.items()))


def main(path_a: str, path_b: str) -> None:
    a, b = load(path_a), load(path_b)
    record = json.loads((ROOT / "tests/data/sim_golden.json").read_text())
    for s in g.SETTINGS:
        moved = sorted(k for k in a[s] if not np.array_equal(a[s][k], b[s][k]))
        print(f"{s}: exact quantities equal: {g.exact(a[s], s) == g.exact(b[s], s)}; ", end="")
        print(f"B's equal the record's: {g.exact(b[s], s) == record['settings'][s]['exact']}")
        print(f"  not bit-identical: {len(moved)} of {len(a[s])} quantities {moved}")
        print(f"  envs whose floats moved (env: first step): {first_moved_step(a[s], b[s], moved)}")
        print(f"  the record compares floats up to step {record['settings'][s]['horizon'] - 1}")
    for label, run in (("A", a), ("B", b)):
        print(f"{label} reproduces the digests of: {g.matching_platforms(record, run) or 'no recorded platform'}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
