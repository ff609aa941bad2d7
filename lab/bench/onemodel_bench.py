"""One MuJoCo Warp model for every object against the product's object groups, stepped back to back.

    python -m lab.bench --bench.type=onemodel --bench.num_envs=[36,360] --bench.json=true

The Warp backend builds one model per object geometry type (`sim/backends/warp.py`): MuJoCo Warp batches
`geom_size`, `geom_pos`, `body_mass`, ... per world, but not `geom_type`, `geom_contype` or `geom_conaffinity`
(`mujoco_warp/_src/types.py`, `Model`: those specs have no "*" world axis), so a box and a sphere cannot share one
model's object geom. Every world can still hold one object geom of each type. In this bench's "one model" the
object body carries a box, a capsule, a cylinder and a sphere (that order, the box named `object_geom`); in each
world the object's own geom has its size and mass and the other three are 0.1 mm, massless, at the body origin,
i.e. deep inside the object. MuJoCo Warp's broadphase bounding-sphere test (`_sphere_filter`) then never passes
them on to the narrowphase, so they make no contact. Every world still pays for their pairs in the broadphase,
for the narrowphase kernels of every type pair (one kernel per convex pair type present in the model, each over
all contact slots), and for the fingertip distance sensors, now taken to the object body (the nearest of its four
geoms: the tiny ones sit inside the object, so the nearest is the object's own geom).

Both paths run the same envs, objects and Table II draw (`BatchedGraspEnv`'s), each as one `WarpBackend`: the
groups one is the env's own; the one-model one gets the four-geom object models, one per object, which differ
only in batchable fields, so the backend makes them one group. Table II's friction lands on `object_geom` there and
is copied to the other three. The check (`check`): from the same state, fingers 2 cm beside each object, both
replay the same side grasp's joint targets for --bench.check_steps control steps; the object poses must agree
within the tolerance derived there, and every sensor is compared too. The timing (`time_paths`): the same grasp
from the same state, in alternating blocks; env control steps per second (worlds x control steps / s) of each
path's `raw_step` (its captured graph(s), physics only) and `step` (plus the state the env reads and the failure
check).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np
import torch
import warp as wp

from lab.bench import BenchConfig
from lerobot_blindgrasp import spec
from lerobot_blindgrasp.sim import gripper, objects, observations, scripted
from lerobot_blindgrasp.sim.batched_config import GraspEnvConfig
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv
from lerobot_blindgrasp.sim.sensors import SensorIndex

SLOTS = ("box", "capsule", "cylinder", "sphere")  # the object body's geoms, one per MuJoCo type, in this order
SLOT_NAMES = ("object_geom", "object_capsule", "object_cylinder", "object_sphere")
OFF_SIZE = 1e-4  # m: a world's other geoms, at its object's centre (2 cm or more from any object's surface)


def object_mjcf(obj: objects.ObjectSpec) -> str:
    """`objects.object_mjcf` with a geom of each type: `obj`'s own at its size and mass, the others tiny and
    massless (the same attributes otherwise, so that only batchable fields differ between objects)."""
    geoms = []
    for slot, name in zip(SLOTS, SLOT_NAMES, strict=True):
        own = slot == obj.mjcf_type
        size = " ".join(f"{v:.6f}" for v in obj.size) if own else " ".join([f"{OFF_SIZE:g}"] * 3)
        geoms.append(
            f'<geom name="{name}" type="{slot}" size="{size}" mass="{obj.mass if own else 0.0:.6f}" condim="4" '
            f'friction="1 0.005 0.0001" contype="{gripper.OBJECT_CONTYPE}" '
            f'conaffinity="{gripper.OBJECT_CONAFFINITY}" rgba="0.2 0.6 0.3 {1 if own else 0}"/>'
        )
    euler = " ".join(f"{v:.9f}" for v in obj.euler)
    return f"""
    <body name="object" pos="0 0 {obj.rest_height:.6f}" euler="{euler}">
      <freejoint name="object_free"/>
      {"".join(geoms)}
    </body>"""


def one_model_template(obj: objects.ObjectSpec, options: gripper.PhysicsOptions) -> mujoco.MjModel:
    """The gripper with `obj` as four geoms; the sensors that name `object_geom` name the object body instead."""
    s = mujoco.MjSpec.from_string(gripper.gripper_mjcf(object_mjcf(obj), options))
    for sensor in s.sensors:
        if sensor.refname == "object_geom":
            sensor.reftype, sensor.refname = mujoco.mjtObj.mjOBJ_BODY, "object"
    return s.compile()


def build_pair(num_envs: int, seed: int = 0, device: str | None = None):
    """(the env with the product's groups backend, the one-model backend over the same envs and draw)."""
    from lerobot_blindgrasp.sim.backends.warp import WarpBackend

    env = BatchedGraspEnv(GraspEnvConfig(num_envs=num_envs, seed=seed, backend="warp", device=device))
    cfg = env.cfg
    specs = [objects.scaled(objects.get_object(n), cfg.dr.object_size_scale) for n in cfg.objects]
    templates = [one_model_template(o, cfg.physics) for o in specs]
    one = WarpBackend(
        templates, env.object_index, env.physics_draw, cfg.dr.torque_limit_scale, device=env.physics.wp_device
    )
    if len(one.groups) != 1:
        raise RuntimeError(f"the four-geom models made {len(one.groups)} Warp models, not one")
    # Table II's object friction went to `object_geom` (the box slot); every world's own geom gets it too.
    wp.synchronize_device(one.wp_device)  # the build's work on Warp's stream done before torch touches its arrays
    friction = wp.to_torch(one.groups[0].model.geom_friction)  # (worlds, ngeom, 3), the model's own memory
    slots = [templates[0].geom(n).id for n in SLOT_NAMES]
    friction[:, slots[1:], 0] = friction[:, slots[:1], 0]
    if one.device.type == "cuda":  # torch's write done before Warp's stream reads the model
        torch.cuda.current_stream(one.device).synchronize()
    return env, one


def _copy_state(src, dst) -> None:
    """dst's worlds to src's state (the env's reset), solver warm start cleared as at a reset."""
    every = torch.arange(dst.num_envs, device=dst.device)
    dst.reset(every)
    for k in ("qpos", "qvel", "ctrl", "xfrc_applied"):
        getattr(dst, k).copy_(getattr(src, k))
    dst.forward(every)


def grasp_targets(env: BatchedGraspEnv, steps: int) -> list[torch.Tensor]:
    """Reset the env with every finger 2 cm beside its object at grasp height (the side grasp's own pose), and
    return the servo targets of the rest of that grasp: squeeze over 8 control steps, then lift and hold.
    Fingertips are on the objects within a few steps, so both paths are compared (and timed) with grasp
    contacts."""
    env.reset()
    specs = [objects.scaled(objects.get_object(n), env.cfg.dr.object_size_scale) for n in env.object_names]
    pos = env.physics.qpos[:, observations.OBJECT_POS].double().cpu().numpy()
    script = scripted.SideGraspScript(env.joint_positions(), pos, specs)
    script.segments = ((8, 2, 3), (max(steps - 8, 1), 3, 4))
    lower, upper = np.asarray(spec.JOINT_LOWER), np.asarray(spec.JOINT_UPPER)
    beside = torch.as_tensor(np.clip(script.waypoints[2], lower, upper))
    p = env.physics
    p.qpos[:, observations.JOINTS] = beside.to(p.qpos.device, p.qpos.dtype)
    p.ctrl[:] = beside.to(p.ctrl.device, p.ctrl.dtype)
    p.forward(torch.arange(env.num_envs, device=p.device))
    return [torch.as_tensor(np.clip(script.target(t), lower, upper)) for t in range(steps)]


def replay(backend, targets: list[torch.Tensor], substeps: int) -> list[torch.Tensor]:
    """(worlds, 7 + nsensordata) after each control step of the targets replayed: the object pose and every
    sensor, float64 copies on the host."""
    out = []
    for target in targets:
        backend.ctrl[:] = target.to(backend.ctrl.device)
        backend.step(substeps)
        pose = backend.qpos[:, observations.OBJECT_POS.start : observations.OBJECT_QUAT.stop]
        out.append(torch.cat([pose, backend.sensordata], 1).to("cpu", torch.float64, copy=True))  # a copy
    return out


def max_diff(a: list[torch.Tensor], b: list[torch.Tensor], cols: slice) -> float:
    return max(float((x[:, cols] - y[:, cols]).abs().max()) for x, y in zip(a, b, strict=True))


def check(env: BatchedGraspEnv, one, steps: int) -> dict:
    """Both paths through the same grasp from the same state: the one model's object poses and sensors against
    the groups', and the groups' against themselves (a second replay).

    The tolerance, derived: per world both paths run the same float32 operations (the same model rows, the same
    contacts in the same order: the extra geoms never pass the broadphase), so where Warp runs a kernel's threads
    in a fixed order (its CPU device) they must agree to the bit. Where the order of contacts within a world comes
    from atomics (a GPU), two replays of the groups' own path already differ, and chaotically more with each step;
    there the one model may differ from the groups by at most twice what the groups differ from themselves."""
    substeps = env.cfg.physics.substeps
    targets = grasp_targets(env, steps)
    start = env.physics.snapshot()
    _copy_state(env.physics, one)
    groups = replay(env.physics, targets, substeps)
    mine = replay(one, targets, substeps)
    env.physics.restore(start)
    again = replay(env.physics, targets, substeps)
    pose, sensors = slice(0, 7), slice(7, None)
    diff, spread = max_diff(mine, groups, pose), max_diff(again, groups, pose)
    index = SensorIndex.from_model(one_model_template(objects.get_object(env.object_names[0]), env.cfg.physics))
    touch = torch.stack([index.read(x[:, 7:], "objcontact").norm(dim=2).amax(1) for x in groups]).amax(0)
    return {
        "control_steps": steps,
        "worlds": env.num_envs,
        "worlds_with_a_tip_on_the_object": int((touch > 0).sum()),
        "max_pose_diff": diff,  # m and unit-quaternion components, over every world and control step
        "groups_rerun_max_pose_diff": spread,
        "tolerance": 2.0 * spread,
        "agree": diff <= 2.0 * spread,
        "max_sensor_diff": max_diff(mine, groups, sensors),  # forces in N, distances in m, ...
        "groups_rerun_max_sensor_diff": max_diff(again, groups, sensors),
    }


def _block(backend, start, targets: list[torch.Tensor], substeps: int, raw: bool) -> float:
    """Seconds for the targets replayed from `start`: `raw_step` (physics only) or `step` (with the state the env
    reads gathered and the failure check)."""
    backend.restore(start)
    rows = [t.to(backend.ctrl.device, backend.ctrl.dtype) for t in targets]
    t0 = time.perf_counter()
    for target in rows:
        backend.ctrl.copy_(target)
        backend.raw_step(substeps) if raw else backend.step(substeps)
    if backend.device.type == "cuda":
        torch.cuda.synchronize(backend.device)
    return time.perf_counter() - t0


def time_paths(env: BatchedGraspEnv, one, steps: int, blocks: int, deadline: float) -> dict:
    """Env control steps per second of each path, `raw_step` and `step`, in alternating blocks from the same
    state with the same targets (`grasp_targets`: grasp contacts in every world); no block starts after
    `deadline`."""
    substeps = env.cfg.physics.substeps
    targets = grasp_targets(env, steps)
    paths = {"groups": env.physics, "one": one}
    _copy_state(env.physics, one)
    starts = {k: b.snapshot() for k, b in paths.items()}
    for k, b in paths.items():  # untimed: the captured graphs' first launches, and a first pass over the memory
        for raw in (True, False):
            _block(b, starts[k], targets, substeps, raw)
    seconds = {(k, raw): 0.0 for k in paths for raw in (True, False)}
    done, order = 0, list(seconds)
    while done < blocks and (done == 0 or time.perf_counter() < deadline):
        for k, raw in order if done % 2 == 0 else order[::-1]:  # every other block in reverse: no path first
            seconds[k, raw] += _block(paths[k], starts[k], targets, substeps, raw)
        done += 1
    n = done * steps * env.num_envs
    out = {
        k: {"raw_control_steps_per_s": n / seconds[k, True], "step_control_steps_per_s": n / seconds[k, False]}
        for k in paths
    }
    out["one_over_groups"] = {
        m: out["one"][m] / out["groups"][m] for m in ("raw_control_steps_per_s", "step_control_steps_per_s")
    }
    out["blocks"], out["control_steps_per_block"] = done, steps
    return out


def _pairs(backend) -> list[int]:
    """Geom pairs each model's broadphase tests per world (after contype/conaffinity and parent filtering)."""
    return [int(g.model.nxn_geom_pair_filtered.shape[0]) for g in backend.groups]


def measure(num_envs: int, check_steps: int, steps: int, blocks: int, budget_s: float, device=None) -> dict:
    """Build both paths at `num_envs`, check they agree, time them; timing blocks stop at `budget_s` overall."""
    t0 = time.perf_counter()
    env, one = build_pair(num_envs, device=device)
    built = time.perf_counter() - t0
    try:
        out = {"num_envs": num_envs, "device": str(one.device), "build_both_s": built}
        out["models"] = {"groups": len(env.physics.groups), "one": len(one.groups)}
        out["broadphase_pairs_per_world"] = {"groups": _pairs(env.physics), "one": _pairs(one)}
        out["check"] = check(env, one, check_steps)
        out.update(time_paths(env, one, steps, blocks, t0 + budget_s))
    finally:
        env.close()
        one.close()
    out["stage_s"] = time.perf_counter() - t0
    return out


@BenchConfig.register_subclass("onemodel")
@dataclass
class BenchOneModelConfig(BenchConfig):
    """One Warp model with per-world geometry against the object groups' graphs back to back."""

    num_envs: list[int] = field(default_factory=lambda: [36, 360])  # env counts (18 objects, allocated evenly)
    check_steps: int = 20  # control steps of the equivalence check
    steps: int = 12  # control steps per timed block
    blocks: int = 4  # alternating blocks per path (even: each order of the paths as often)
    budget_s: float = 600.0  # per env count: no timing block starts after this
    device: str | None = None  # Warp device (default: the GPU if there is one, else "cpu")


def run(cfg: BenchOneModelConfig) -> dict:
    rows = []
    for n in cfg.num_envs:
        load = os.getloadavg()
        rows.append({**measure(n, cfg.check_steps, cfg.steps, cfg.blocks, cfg.budget_s, cfg.device), "load": load})
    if not cfg.json:
        print("blindgrasp-bench onemodel: env control steps/s, object groups back to back vs one model")
        print("| envs | device | groups raw | one raw | one / groups | groups step | one step | check | load |")
        print("|---:|---|---:|---:|---:|---:|---:|---|---|")
        for r in rows:
            g, o, c = r["groups"], r["one"], r["check"]
            verdict = f"{'agree' if c['agree'] else 'DIFFER'} ({c['max_pose_diff']:.1e})"
            print(
                f"| {r['num_envs']} | {r['device']} | {g['raw_control_steps_per_s']:,.0f} | "
                f"{o['raw_control_steps_per_s']:,.0f} | {r['one_over_groups']['raw_control_steps_per_s']:.2f} | "
                f"{g['step_control_steps_per_s']:,.0f} | {o['step_control_steps_per_s']:,.0f} | {verdict} | "
                f"{'/'.join(f'{x:.1f}' for x in r['load'])} |"
            )
    return {"rows": rows}
