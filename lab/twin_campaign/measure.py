"""The shipped student through the whole real stack on the physics twin, beside the sim env on the same start states.

    python -m lab.twin_campaign.measure --output_dir=outputs/twin_measure

One command, resumable (re-run it with the same `--output_dir` and it goes on where it stopped):
1. `sim/`: `lerobot-eval --env.type=blindgrasp` on the objects and seeds below (skipped once its eval_info.json
   exists, or with `--sim=false`).
2. `blindgrasp-twin` in its own process (`twin.log`), `blindgrasp-twin-calibrate` (the servos through
   lerobot-calibrate, the fingertips through blindgrasp-calibrate-force with the twin's weights).
3. Per object, `lerobot-eval --env.type=blindgrasp_real` on the twin's ports with the robot's shipped defaults
   (`--overload_n`, `--current_limit_a`, `--latency_timer_ms`, `--max_overrun_s` override them when given). A trial
   the real stack's safety latch stops is a failure (`stops.jsonl`, with its error), and lerobot-eval starts again
   at the next seed.
4. The record: `report.md` (`report.py`: per-object rates, the judge, stops by cause, peak forces, the real
   loop's step timing, the twin's own cost, the machine's load) and `compare.md` (`results/compare.py`: paired
   with the sim, McNemar p).

The twin and the evaluations run at `--nice` (default -10, which needs root; otherwise they run at the normal
priority and `runs.log` says so), standing in for a lab PC that runs nothing else, and the twin's emulator and
physics threads run real-time (`--twin_realtime_priority`), standing in for the gripper's own processors, which
answer whatever the PC does. `load.jsonl` samples the machine's load and CPU use every `--load_every_s` throughout.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from lab.twin_campaign import report
from lerobot_blindgrasp import durable, shipped
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.envs.real_env import resolve_real_objects
from lerobot_blindgrasp.twin.calibration_operator import TwinCalibrateConfig
from lerobot_blindgrasp.twin.calibration_operator import calibrate_twin as calibrate

logger = logging.getLogger(__name__)
BIN = Path(sys.executable).parent


@dataclass
class TwinMeasureConfig:
    output_dir: Path
    policy_path: str | None = None  # None: the shipped student (models/student_cpu)
    objects: str = "all"  # "all" (18), "medium" (6) or a comma list
    episodes: int = 10  # per object
    seed: int = 1000  # episode k of an object is evaluation index seed + k, in both envs
    sim: bool = True  # also run --env.type=blindgrasp on the same start states
    nice: int = -10  # the twin's and the evaluations' niceness (negative needs root)
    # The twin's emulators and physics as SCHED_FIFO threads at this priority (blindgrasp-twin --realtime_priority;
    # root): they stand in for the gripper's own processors. 0: normal threads.
    twin_realtime_priority: int = 10
    load_every_s: float = 10.0
    # Robot settings; None keeps the robot's shipped default.
    overload_n: float | None = None
    current_limit_a: float | None = None
    latency_timer_ms: int | None = None
    max_overrun_s: float | None = None
    restarts_per_object: int = 12  # lerobot-eval starts per object before giving up (each stop costs one)
    eval_timeout_s: float = 1800.0

    def __post_init__(self):
        self.object_names = resolve_real_objects(self.objects)
        if self.episodes < 1:
            raise ValueError("episodes must be >= 1")

    def policy(self) -> str:
        return self.policy_path or str(shipped.path("student_cpu"))

    def robot_flags(self) -> list[str]:
        fields = {"force_sensor.overload_n": self.overload_n, "current_limit_a": self.current_limit_a,
                  "latency_timer_ms": self.latency_timer_ms, "max_overrun_s": self.max_overrun_s}  # fmt: skip
        return [f"--env.robot.{k}={v}" for k, v in fields.items() if v is not None]


def _renice(n: int):
    def apply() -> None:
        try:
            os.nice(n)
        except OSError:
            pass  # not root: normal priority (the record's priority line says which it got)

    return apply


def _loadavg() -> dict:
    load = Path("/proc/loadavg").read_text().split()
    fields = [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle + iowait
    return {"t": round(time.time(), 1), "load1": float(load[0]), "running": int(load[3].split("/")[0]),
            "cpu_total": sum(fields), "cpu_idle": idle}  # fmt: skip


class LoadSampler(threading.Thread):
    """Appends the machine's 1-minute load and CPU busy share to `path` every `every_s`."""

    def __init__(self, path: Path, every_s: float):
        super().__init__(name="load-sampler", daemon=True)
        self.path, self.every_s, self.stop = path, every_s, threading.Event()

    def run(self) -> None:
        last = _loadavg()
        while not self.stop.wait(self.every_s):
            now = _loadavg()
            busy = 1.0 - (now["cpu_idle"] - last["cpu_idle"]) / max(1, now["cpu_total"] - last["cpu_total"])
            row = {"t": now["t"], "load1": now["load1"], "running": now["running"], "cpu_busy": round(busy, 3)}
            durable.atomic_append_text(self.path, json.dumps(row) + "\n")
            last = now


def run_logged(cmd: list[str], log: Path, nice: int = 0, timeout_s: float | None = None) -> int:
    """Run `cmd` with its output into `log`; returns its exit status (124 after `timeout_s`)."""
    with log.open("a") as out:
        out.write(f"$ {' '.join(cmd)}\n")
        out.flush()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, preexec_fn=_renice(nice))
        try:
            return proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.terminate()
            proc.wait(timeout=30)
            return 124


def sim_eval(cfg: TwinMeasureConfig) -> None:
    out = cfg.output_dir / "sim"
    if (out / "eval_info.json").is_file():
        return
    cmd = [str(BIN / "lerobot-eval"), f"--policy.path={cfg.policy()}", "--policy.device=cpu",
           "--env.type=blindgrasp", f"--env.task={','.join(cfg.object_names)}", f"--eval.n_episodes={cfg.episodes}",
           f"--eval.batch_size={min(cfg.episodes, 10)}", "--eval.use_async_envs=false", f"--seed={cfg.seed}",
           "--env.render_stride=20", "--env.render_episodes=0", f"--output_dir={out}"]  # fmt: skip
    logger.info("sim env: %d objects x %d episodes", len(cfg.object_names), cfg.episodes)
    if run_logged(cmd, cfg.output_dir / "sim.log", timeout_s=cfg.eval_timeout_s * 4) != 0:
        raise RuntimeError(f"the sim evaluation failed: see {cfg.output_dir / 'sim.log'}")


def done_seeds(out: Path, obj: str) -> set[int]:
    """Evaluation indices of `obj` that ended (the real env's trial log) or that the real stack stopped."""
    rows = report.read_jsonl(out / "real_trials.jsonl") + report.read_jsonl(out / "stops.jsonl")
    return {int(r["seed"]) for r in rows if r["object"] == obj}


def last_error(log: Path) -> str:
    lines = [x for x in log.read_text(errors="replace").splitlines() if "Error: " in x] if log.is_file() else []
    return lines[-1].split("Error: ", 1)[-1][:400] if lines else "no error line"


def real_eval(cfg: TwinMeasureConfig, obj: str, ports: dict) -> None:
    out = cfg.output_dir
    for _ in range(cfg.restarts_per_object):
        done = len(done_seeds(out, obj))
        if done >= cfg.episodes:
            return
        seed = cfg.seed + done
        run = out / "real" / obj / f"from_{seed}"
        run.parent.mkdir(parents=True, exist_ok=True)
        cmd = [str(BIN / "lerobot-eval"), f"--policy.path={cfg.policy()}", "--policy.device=cpu",
               "--env.type=blindgrasp_real", f"--env.task={obj}", "--env.robot.type=blindgrasp_gripper",
               "--env.robot.id=twin", f"--env.robot.calibration_dir={out / 'calibration'}",
               f"--env.robot.port={ports['dynamixel_port']}", f"--env.robot.force_sensor.port={ports['force_port']}",
               *cfg.robot_flags(), f"--env.operator_socket={ports['operator_socket']}", "--env.start_pose=sim",
               f"--env.trial_log={out / 'real_trials.jsonl'}", f"--eval.n_episodes={cfg.episodes - done}",
               "--eval.batch_size=1", "--eval.use_async_envs=false", f"--seed={seed}", f"--output_dir={run}"]  # fmt: skip
        rc = run_logged(cmd, run.with_suffix(".log"), cfg.nice, cfg.eval_timeout_s)
        durable.atomic_append_text(out / "runs.log", f"{time.strftime('%H:%M:%S')} {obj} from {seed} exit {rc}\n")
        if not (run / "eval_info.json").is_file():
            stopped = cfg.seed + len(done_seeds(out, obj))
            row = {"object": obj, "seed": stopped, "error": last_error(run.with_suffix(".log")), "t": time.time()}
            durable.atomic_append_text(out / "stops.jsonl", json.dumps(row) + "\n")
    raise RuntimeError(f"{obj}: still not {cfg.episodes} trials after {cfg.restarts_per_object} starts")


def start_twin(cfg: TwinMeasureConfig) -> tuple[subprocess.Popen, dict]:
    out = cfg.output_dir
    (out / "ports.json").unlink(missing_ok=True)
    cmd = [sys.executable, "-m", "lerobot_blindgrasp.twin.command", f"--ports_json={out / 'ports.json'}",
           f"--socket={out / 'twin.sock'}", f"--trial_log={out / 'twin_trials.jsonl'}", "--status_every_s=60",
           f"--realtime_priority={cfg.twin_realtime_priority}"]  # fmt: skip
    log = (out / "twin.log").open("a")
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, preexec_fn=_renice(cfg.nice))
    deadline = time.monotonic() + 120
    while not (out / "ports.json").is_file():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"blindgrasp-twin did not start: see {out / 'twin.log'}")
        time.sleep(0.5)
    durable.atomic_append_text(
        out / "runs.log", f"blindgrasp-twin pid {proc.pid}, niceness {niceness(proc.pid)}\n"
    )
    return proc, json.loads((out / "ports.json").read_text())


def niceness(pid: int) -> int:
    """A process's niceness (field 19 of /proc/PID/stat)."""
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16])


def commit() -> str:
    """The source's git commit (and "+changes" when its tree differs), or "unknown" outside a checkout."""
    here = Path(__file__).parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, check=True)  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head.stdout.strip() + ("+changes" if dirty.stdout.strip() else "")


def cpu_model() -> str:
    """The CPU's model name, for the record (/proc/cpuinfo; the machine type where it says none)."""
    import platform

    info = Path("/proc/cpuinfo")
    lines = info.read_text(errors="replace").splitlines() if info.exists() else []
    names = [line.partition(":")[2].strip() for line in lines if line.partition(":")[0].strip() == "model name"]
    return names[0] if names else platform.machine()


def facts(cfg: TwinMeasureConfig) -> dict:
    return {"commit": commit(), "command": " ".join([Path(sys.executable).name, "-m", __spec__.name, *sys.argv[1:]]),
            "started_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()), "cpus": os.cpu_count(),
            "platform": cpu_model(), "root": os.geteuid() == 0,
            "config": {k: str(v) for k, v in asdict(cfg).items()}}  # fmt: skip


def measure(cfg: TwinMeasureConfig) -> None:
    out = cfg.output_dir
    out.mkdir(parents=True, exist_ok=True)
    durable.atomic_append_text(out / "runs.log", json.dumps(facts(cfg)) + "\n")
    sampler = LoadSampler(out / "load.jsonl", cfg.load_every_s)
    sampler.start()
    try:
        if cfg.sim:
            sim_eval(cfg)
        twin, ports = start_twin(cfg)
        try:
            if not (out / "calibration" / "twin.force.json").is_file():
                cal = TwinCalibrateConfig(ports_json=out / "ports.json", calibration_dir=out / "calibration")
                if calibrate(cal) != 0:
                    raise RuntimeError("blindgrasp-twin-calibrate failed")
            for obj in cfg.object_names:
                logger.info("real stack on the twin: %s", obj)
                real_eval(cfg, obj, ports)
        finally:
            twin.send_signal(signal.SIGTERM)
            twin.wait(timeout=30)
    finally:
        sampler.stop.set()
    text = report.render(out, sim=out / "sim" if cfg.sim else None)
    durable.atomic_write_text(out / "report.md", text)
    print(text)


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    measure(parse_config(TwinMeasureConfig, argv))


if __name__ == "__main__":
    main()
