"""The host of the twin fault tests: lerobot-eval's own `eval_main` running the shipped student through
`--env.type=blindgrasp_real` on the twin, one trial per run, several runs in one process (LeRobot and the policy are
imported once; each run makes its env, robot and policy afresh, as lerobot-eval does).

    python tests/twin_grasp_host.py '<json: dynamixel_port, force_port, operator_socket, calibration_dir,
                                      scale_n_per_count, object, seed, output_dir, runs>'

Before each run it prints `RUN k`; after it, `ENDED` or `STOPPED <error>` when the robot's safety latch stopped it
(tests/twin/test_twin_faults.py injects the faults, or kills this process), then waits for a line on stdin.
"""

from __future__ import annotations

import gc
import json
import sys
from pathlib import Path

# Reply timeout = 2 x this + 2 ms: the twin shares a loaded CI machine's CPU with the host (tests only).
LATENCY_TIMER_MS = 150


def eval_args(a: dict, out: Path) -> list[str]:
    scale = ",".join(str(s) for s in a["scale_n_per_count"])
    return ["--policy.path=models/student_cpu", "--policy.device=cpu", "--env.type=blindgrasp_real",
            f"--env.task={a['object']}", "--env.robot.type=blindgrasp_gripper", "--env.robot.id=twin",
            f"--env.robot.calibration_dir={a['calibration_dir']}", f"--env.robot.port={a['dynamixel_port']}",
            f"--env.robot.force_sensor.port={a['force_port']}", f"--env.robot.force_sensor.scale_n_per_count=[{scale}]",
            f"--env.robot.latency_timer_ms={LATENCY_TIMER_MS}",
            "--env.robot.max_overrun_s=0",  # a loaded CI machine runs the loop slow: counted, not a stop
            f"--env.operator_socket={a['operator_socket']}", "--eval.n_episodes=1", "--eval.batch_size=1",
            "--eval.use_async_envs=false", f"--seed={a['seed']}", f"--output_dir={out}"]  # fmt: skip


def main(a: dict) -> None:
    from lerobot.scripts import lerobot_eval
    from lerobot.utils.utils import init_logging

    init_logging()
    lerobot_eval.register_third_party_plugins()
    for k in range(int(a["runs"])):
        sys.argv = ["lerobot-eval", *eval_args(a, Path(a["output_dir"]) / f"run{k}")]
        print(f"\nRUN {k}", flush=True)
        try:
            lerobot_eval.eval_main()
            print("\nENDED", flush=True)
        except Exception as e:  # the robot's safety latch: the torque is already off and both ports are closed
            print("\nSTOPPED " + f"{type(e).__name__}: {e}".replace("\n", " "), flush=True)
        gc.collect()  # the stopped run's env and its operator socket go now, not at exit
        sys.stdin.readline()


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
