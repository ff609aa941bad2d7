"""How often the side-grasp script lifts each object from training start states: what scripted-grasp cloning
(`teacher.aux_bc`, the shipped teacher's recipe) has to clone on each object.

    python -m lab.diagnosis.script_success [--objects=all] [--episodes_per_object=30] [--pushes=true]

It rolls the script out as cloning collects its demonstrations (`teacher.scripted_demos.collect_scripted_demos`,
the training seeds of `presets.teacher_configs.ScriptedDemos`) and prints one row per object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.presets.teacher_configs import ScriptedDemos
from lerobot_blindgrasp.sim import objects
from lerobot_blindgrasp.teacher.scripted_demos import collect_scripted_demos


@dataclass
class ScriptSuccessConfig:
    """How often the side-grasp script lifts each object from training start states (what cloning can use)."""

    objects: str = "all"  # "all", "medium", or a comma-separated list of catalogue names
    episodes_per_object: int = 30
    pushes: bool = True  # Table II's random pushes (the paper's training randomization)


def main(argv=None) -> None:
    cfg = parse_config(ScriptSuccessConfig, argv)
    demos = ScriptedDemos(
        objects=objects.resolve_objects(cfg.objects),
        episodes_per_object=cfg.episodes_per_object,
        steps_per_episode=1,
        pushes=cfg.pushes,
    )
    rates = collect_scripted_demos(demos)["success"]
    print(
        f"side-grasp script, {cfg.episodes_per_object} episodes per object from seed {demos.seed}, "
        f"pushes={cfg.pushes}\n\n| object | success |\n|---|---:|"
    )
    for name, rate in rates.items():
        print(f"| {name} | {rate:.0%} ({round(rate * cfg.episodes_per_object)}/{cfg.episodes_per_object}) |")
    print(f"| **all** | **{np.mean(list(rates.values())):.1%}** |")


if __name__ == "__main__":
    main()
