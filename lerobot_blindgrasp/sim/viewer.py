"""`blindgrasp-sim-viewer`: a scripted pinch-and-lift through the lerobot-eval gym env, rendered to an mp4, with
lift, fingertip forces (N) and success printed. The script knows the object's shape and assumes it is centred.

    blindgrasp-sim-viewer --object=sphere_small --output=outputs/sim_demo/sphere_small.mp4"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_blindgrasp import durable, spec
from lerobot_blindgrasp.cli import parse_config
from lerobot_blindgrasp.sim import gym_env, objects, randomization
from lerobot_blindgrasp.sim.scripted import PinchLiftScript


@dataclass
class SimDemoConfig:
    """Watch the sim work: a scripted pinch-and-lift through the lerobot-eval gym env, rendered to an mp4."""

    object: str = "cylinder_a_medium"  # object to lift: a name from sim/objects.py's CATALOGUE (Table I)
    output: Path | None = None  # mp4 path (default: outputs/sim_demo/<object>.mp4)
    video: bool = True  # false: skip rendering, print the summary only
    seed: int = 0  # episode seed (randomization draw and noise)
    steps: int = spec.EPISODE_STEPS  # control steps at 20 Hz (default: one 10 s trial)
    width: int = 640  # video width (px)
    height: int = 480  # video height (px)
    shadows: bool = True  # false renders faster on a CPU
    # false: nominal physics, no sensor noise (default: the paper's randomization, pushes off)
    randomization: bool = True

    def __post_init__(self):
        objects.get_object(self.object)  # raises on unknown names, listing the known ones
        if not 1 <= self.steps <= spec.EPISODE_STEPS:
            raise ValueError(f"steps must be in [1, {spec.EPISODE_STEPS}] (one 10 s trial), got {self.steps}")

    @property
    def video_path(self) -> Path | None:
        return (self.output or Path("outputs/sim_demo") / f"{self.object}.mp4") if self.video else None


def _boundary_distance(o: objects.ObjectSpec, phi: float) -> float:
    """Distance from the object's vertical axis to its side, at centre height, along world direction phi."""
    c, s = abs(math.cos(phi)), abs(math.sin(phi))
    if o.mjcf_type in ("cylinder", "sphere"):
        return o.size[0]
    if o.mjcf_type == "box":
        a, b = o.size[0], o.size[1]
        return min(a / c if c > 1e-9 else math.inf, b / s if s > 1e-9 else math.inf)
    if o.mjcf_type == "capsule":  # lying along x: a stadium of half-length h and radius r in the plane
        r, h = o.size
        if s > 1e-9 and r * c / s <= h:
            return r / s
        return c * h + math.sqrt(max(0.0, r * r - (s * h) ** 2))
    raise ValueError(f"no grasp geometry for mjcf type {o.mjcf_type!r}")


def grasp_geometry(object_name: str) -> tuple[float, float]:
    """(radius, height) for `PinchLiftScript`: the object's side along the three finger directions, averaged."""
    o = objects.get_object(object_name)
    radius = float(np.mean([_boundary_distance(o, phi) for phi in spec.FINGER_BASE_ANGLES_RAD]))
    return radius, o.rest_height


def run_demo(cfg: SimDemoConfig) -> dict:
    """Run one scripted episode; write the video if `cfg.video_path` is set; return the summary."""
    output = cfg.video_path
    dr = randomization.CENTRED_EVAL_DR if cfg.randomization else randomization.NO_DR
    env = gym_env.BlindGraspGymEnv(
        cfg.object, dr=dr, render_mode="rgb_array" if output else None, render_width=cfg.width,
        render_height=cfg.height, render_shadows=cfg.shadows,
    )  # fmt: skip
    script = PinchLiftScript(*grasp_geometry(cfg.object))  # a 3 cm lift
    obs, _ = env.reset(seed=cfg.seed)
    frames = [env.render()] if output else []
    lifts, clean_forces, measured_forces = [], [], []
    first_success = None
    t0 = time.perf_counter()
    for t in range(cfg.steps):
        obs, _, terminated, truncated, info = env.step(script.target(t))
        lifts.append(info["lift_m"])
        clean_forces.append(info["uniaxial_force_n"])
        measured_forces.append(obs["agent_pos"][spec.STATE_FORCE_SLICE])
        if info["is_success"] and first_success is None:
            first_success = t + 1
        if output:
            frames.append(env.render())
        if terminated or truncated:
            break
    sim_s = time.perf_counter() - t0
    env.close()

    last_s = max(1, min(len(lifts), spec.CONTROL_HZ))  # the last second: the hold
    summary = {
        "object": cfg.object,
        "task": objects.get_object(cfg.object).task,
        "seed": cfg.seed,
        "steps": len(lifts),
        "success": first_success is not None,
        "success_at_s": None if first_success is None else first_success / spec.CONTROL_HZ,
        "max_lift_m": float(np.max(lifts)),
        "final_lift_m": float(lifts[-1]),
        "hold_force_n": np.mean(clean_forces[-last_s:], axis=0).round(2).tolist(),
        "hold_force_measured_n": np.mean(measured_forces[-last_s:], axis=0).round(2).tolist(),
        "wall_s": sim_s,
        "video": None,
    }
    if output:
        summary["video"] = str(_write_video(output, frames))
    return summary


def _write_video(output: Path, frames: list) -> Path:
    """The rendered frames as an mp4, with the writer lerobot-eval uses for its videos (PyAV, H.264)."""
    from lerobot.utils.io_utils import write_video

    output.parent.mkdir(parents=True, exist_ok=True)
    with durable.atomic_path(output) as tmp:
        write_video(str(tmp), frames, spec.CONTROL_HZ)
    return output


def format_summary(s: dict) -> str:
    fingers = ", ".join(f"{f}={v:.2f}" for f, v in zip(spec.FINGERS, s["hold_force_n"], strict=True))
    measured = ", ".join(f"{f}={v:.2f}" for f, v in zip(spec.FINGERS, s["hold_force_measured_n"], strict=True))
    success = f"yes (held from t={s['success_at_s']:.2f} s)" if s["success"] else "no"
    lines = [
        f"object        {s['object']} ({s['task']!r}), seed {s['seed']}",
        f"steps         {s['steps']} at {spec.CONTROL_HZ} Hz ({s['steps'] / spec.CONTROL_HZ:.1f} s sim, "
        f"{s['wall_s']:.1f} s wall incl. rendering)",
        f"lift          max {100 * s['max_lift_m']:.1f} cm, final {100 * s['final_lift_m']:.1f} cm "
        f"(success needs >= {100 * spec.SUCCESS_LIFT_M:.1f} cm for {spec.SUCCESS_HOLD_S:.0f} s)",
        f"tip forces    last second, noise-free: {fingers} N",
        f"              as the policy sees them (noise, sigma {spec.FORCE_NOISE_STD_N} N): {measured} N",
        f"success       {success}",
    ]
    if s["video"]:
        lines.append(f"video         {s['video']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    print(format_summary(run_demo(parse_config(SimDemoConfig, argv))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
