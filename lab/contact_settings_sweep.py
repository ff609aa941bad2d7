"""Which contact settings hold a grasp without creep, and what each costs.

    .venv/bin/python scripts/contact_settings_sweep.py [--envs=128]

A scripted pinch-and-lift (sim/scripted.py) grips the medium cylinder and lifts it 3 cm under the paper's servo-gain,
friction and mass randomization (no xy offset, no pushes). For each setting it reports success, the final lift after
a 1.5 s hold (creep shows as a lift below 3 cm), the maximum lift (an ejected object shows as > 4 cm) and the wall
time per control step relative to the first row, all measured in one run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.sim import gripper, randomization
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.scripted import PinchLiftScript

SETTINGS = [  # (label, timestep, impratio, noslip_iterations)
    ("elliptic, impratio 1, no noslip, 5 ms (cheapest)", 0.005, 1.0, 0),
    ("elliptic, impratio 1, noslip 3, 5 ms (chosen)", 0.005, 1.0, 3),
    ("elliptic, impratio 10, no noslip, 5 ms", 0.005, 10.0, 0),
    ("elliptic, impratio 10, noslip 3, 5 ms", 0.005, 10.0, 3),
    ("elliptic, impratio 1, no noslip, 2.5 ms", 0.0025, 1.0, 0),
    ("elliptic, impratio 10, no noslip, 2.5 ms", 0.0025, 10.0, 0),
    ("elliptic, impratio 1, noslip 3, 2.5 ms", 0.0025, 1.0, 3),
]


def run_setting(n: int, timestep: float, impratio: float, noslip: int) -> dict:
    phys = gripper.PhysicsOptions(
        timestep=timestep,
        substeps=int(round(0.05 / timestep)),
        impratio=impratio,
        noslip_iterations=noslip,
        contact_timeconst=2 * timestep,
        tip_timeconst=4 * timestep,
    )
    dr = replace(randomization.PAPER_DR, joint_offset_rad=0.0, object_xy_m=0.0, external_force=False)
    env = BatchedGraspEnv(
        GraspEnvConfig(num_envs=n, objects=("cylinder_a_medium",), dr=dr, physics=phys, autoreset=False, nthread=1)
    )
    env.reset()
    script = PinchLiftScript(object_radius=0.03, grasp_height=0.045)
    lifts = []
    t = time.perf_counter()
    for _ in range(95):
        _, _, _, _, info = env.step(script(env.joint_positions()))
        lifts.append(info["lift"].copy())
    dt = (time.perf_counter() - t) / 95
    lifts = np.array(lifts)
    return {
        "success": float(info["success"].mean()),
        "final_lift_cm": float(np.median(lifts[-1]) * 100),
        "max_lift_cm": float(lifts.max() * 100),
        "ms_per_step": dt * 1000,
    }


@dataclass
class SweepConfig:
    envs: int = 128  # parallel envs per setting


def main(argv: list[str] | None = None) -> None:
    args = parse_config(SweepConfig, argv)
    rows = [(label, run_setting(args.envs, *s)) for label, *s in SETTINGS]
    base = rows[0][1]["ms_per_step"]
    print(
        f"| setting ({args.envs} envs, 1 thread) | success | median final lift (cm) | max lift (cm) | step cost |"
    )
    print("|---|---:|---:|---:|---:|")
    for label, r in rows:
        print(
            f"| {label} | {r['success'] * 100:.0f} % | {r['final_lift_cm']:.2f} | {r['max_lift_cm']:.1f} | "
            f"{r['ms_per_step'] / base:.2f}x |"
        )


if __name__ == "__main__":
    main()
