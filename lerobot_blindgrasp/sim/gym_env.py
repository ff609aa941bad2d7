"""One grasping trial as a gymnasium env for `lerobot-eval`: one row of a `BatchedGraspEnv` (its own, or shared by
a batch of these envs, see `attach`), so eval sees the physics, noise and success rule of training.

Contract (spec.py): observation `{"agent_pos": o_t}` (9 joint positions in rad + 3 uniaxial forces in N, float32);
action: absolute joint targets (rad), the step to them clipped to +-0.3 rad and the joint limits as on the real
gripper; `info["is_success"]`: the shared, latched success rule (`end_on_success` ends the episode there).
`reset(seed=s)` takes s as an evaluation index: sim seed `start_seed(s, object)`, per object, in the eval range.

Outside LeRobot: `gym.make("lerobot_blindgrasp.sim.gym_env:lerobot_blindgrasp/BlindGrasp-v0", object_name=...)`
or `make_env(name)`."""

from __future__ import annotations

import os

# MuJoCo picks its OpenGL backend when it is first imported, and its Linux default (GLFW) needs a display. Eval
# runs headless (CI, servers, lerobot-eval's workers), so default to EGL; an explicit MUJOCO_GL wins.
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from lerobot_blindgrasp import spaces, spec  # noqa: E402
from lerobot_blindgrasp.sim import objects, randomization  # noqa: E402
from lerobot_blindgrasp.sim.batched_env import BatchedGraspEnv, GraspEnvConfig  # noqa: E402

GYM_ID = "lerobot_blindgrasp/BlindGrasp-v0"
# The scene's offscreen framebuffer (sim/gripper.py, <visual><global offwidth offheight>) bounds render sizes.
MAX_RENDER_WIDTH, MAX_RENDER_HEIGHT = 640, 480
_MAX_SEED = spec.EVAL_TASK_STRIDE  # reset seeds are per-object evaluation indices (spec.eval_env_seed)


def start_seed(seed: int, object_name: str) -> int:
    """The env seed of evaluation index `seed` on `object_name`: distinct per object, inside the eval range."""
    return spec.eval_env_seed(seed, objects.task_id(object_name))


class BlindGraspGymEnv(gym.Env):
    """Grasp and lift one object, blind: o_t in R^12 in, absolute joint targets out, 10 s per episode."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": spec.CONTROL_HZ}

    def __init__(
        self,
        object_name: str = "cylinder_a_medium",
        *,
        dr: randomization.DomainRandomization = randomization.EVAL_DR,
        render_mode: str | None = "rgb_array",
        render_width: int = 320,
        render_height: int = 240,
        render_shadows: bool = False,
        render_stride: int = 1,
        end_on_success: bool = False,
    ):
        self.object = objects.get_object(object_name)  # raises on unknown names, listing the known ones
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not (0 < render_width <= MAX_RENDER_WIDTH and 0 < render_height <= MAX_RENDER_HEIGHT):
            raise ValueError(
                f"render size must be within {MAX_RENDER_WIDTH}x{MAX_RENDER_HEIGHT} (the scene's offscreen "
                f"buffer), got {render_width}x{render_height}"
            )
        if not isinstance(dr, randomization.DomainRandomization):
            raise TypeError(f"dr must be a DomainRandomization, got {type(dr).__name__}")
        self.dr = dr
        self.render_mode = render_mode
        self.render_width, self.render_height = int(render_width), int(render_height)
        # Shadows make CPU rendering several times slower; eval videos are for a glance, the demo turns them on.
        self.render_shadows = bool(render_shadows)
        # A new frame every `render_stride` control steps, the last repeated between (why: envs/sim_env.py).
        if int(render_stride) < 1:
            raise ValueError(f"render_stride must be >= 1, got {render_stride}")
        self.render_stride = int(render_stride)
        self.end_on_success = bool(end_on_success)
        self._frame: np.ndarray | None = None
        self._frame_step = 0
        self.observation_space = spaces.observation_space()
        self.action_space = spaces.action_space()
        # Read by lerobot-eval (`env.call("task_description")`); the dataset's task string for this object.
        self.task = self.task_description = self.object.task
        self._max_episode_steps = spec.EPISODE_STEPS  # gym.make's TimeLimit sets the same; kept for direct use
        self.eval_seed: int | None = None  # evaluation index of the current episode
        self.env_seed: int | None = None  # the sim's seed for it, see start_seed
        self._sim: BatchedGraspEnv | None = None
        self._row = 0  # this env's row of `_sim`
        self._done = False
        self._renderer: mujoco.Renderer | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # `options` is accepted and ignored: lerobot-eval passes its own marker there.
        self.begin(seed)
        sim = make_sim(self.object.name, [self.env_seed], self.dr)
        return self.attach(sim, 0, sim.reset())

    def begin(self, seed: int | None) -> None:
        """The seeding half of `reset`: this episode's evaluation index and sim seed (`start_seed`)."""
        if seed is not None and not (isinstance(seed, int | np.integer) and 0 <= int(seed) < _MAX_SEED):
            raise ValueError(f"seed must be an integer in [0, 2**32), got {seed!r}")
        super().reset(seed=None if seed is None else int(seed))  # seeds self.np_random when a seed is given
        self.eval_seed = int(seed) if seed is not None else int(self.np_random.integers(_MAX_SEED))
        self.env_seed = start_seed(self.eval_seed, self.object.name)

    def attach(self, sim: BatchedGraspEnv, row: int, obs: dict[str, np.ndarray]):
        """Run this episode as row `row` of a reset `sim` built with `env_seed` there (`envs/sim_vector.py`)."""
        if self._sim is not None and self._sim is not sim:
            self._sim.close()
        self._sim, self._row = sim, row
        self._done = False
        self._frame = None
        info = {"is_success": False, "eval_seed": self.eval_seed, "env_seed": self.env_seed}
        return spaces.observation(obs["policy"][row]), info

    def step(self, action):
        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("the episode has ended (terminated or truncated); call reset() before step()")
        target = self.check_action(action)
        # Targets past the limits are commands, not bugs: the sim clips them as the real gripper does.
        delta = self._sim.delta_for_target(target[None, :])  # in the joints' measured (calibrated) frame
        return self.row_result(self._sim.step(delta))

    @staticmethod
    def check_action(action) -> np.ndarray:
        target = np.asarray(action, dtype=np.float64)
        if target.shape != (spec.NUM_JOINTS,):
            raise ValueError(
                f"action must be {spec.NUM_JOINTS} absolute joint targets in rad, order {spec.ACTION_NAMES}; "
                f"got shape {target.shape}"
            )
        if not np.isfinite(target).all():
            raise ValueError(f"action has NaN/inf entries: {target.tolist()}")
        return target

    def row_result(self, out: tuple):
        """This env's gymnasium step result from its row of the sim's step result `out`."""
        obs, reward, terminated, truncated, info = out
        i = self._row
        success = bool(info["success"][i])
        terminated = bool(terminated[i]) or (self.end_on_success and success)
        truncated = bool(truncated[i]) and not terminated
        self._done = terminated or truncated
        step_info = {
            "is_success": success,
            "lift_m": float(info["lift"][i]),
            "uniaxial_force_n": info["uniaxial_force"][i].astype(np.float32),  # noise-free, after the deadband
            "joint_target": info["joint_target"][i].astype(np.float32),  # what the servos were sent
        }
        return spaces.observation(obs["policy"][i]), float(reward[i]), terminated, truncated, step_info

    def render(self):
        if self.render_mode is None:
            raise RuntimeError("this env was created with render_mode=None; pass render_mode='rgb_array'")
        if self._sim is None:
            raise RuntimeError("call reset() before render()")
        step = int(self._sim.episode_length[self._row])
        if self._frame is not None and step - self._frame_step < self.render_stride:
            return self._frame
        model, data = self._sim.mj_model_data(self._row)
        if self._renderer is None:
            self._renderer = self._make_renderer(model)
        # A renderer built from an earlier episode's model draws this one: randomization never changes geometry.
        self._renderer.update_scene(data, camera="side")
        self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.render_shadows
        self._frame, self._frame_step = self._renderer.render().copy(), step
        return self._frame

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._sim is not None:
            self._sim.close()
            self._sim = None

    def _make_renderer(self, model: mujoco.MjModel) -> mujoco.Renderer:
        try:
            return mujoco.Renderer(model, height=self.render_height, width=self.render_width)
        except Exception as e:  # the GL backend is chosen at `import mujoco`; say how to fix it
            raise RuntimeError(
                f"MuJoCo offscreen rendering failed ({e}). On a headless machine set MUJOCO_GL=egl (or osmesa) "
                f"before anything imports mujoco (MUJOCO_GL is {os.environ.get('MUJOCO_GL')!r} here)."
            ) from e


def make_sim(object_name: str, env_seeds: list[int], dr: randomization.DomainRandomization) -> BatchedGraspEnv:
    """The sim that runs episodes of `object_name` from these sim seeds (`start_seed`), one row each."""
    return BatchedGraspEnv(
        GraspEnvConfig(
            num_envs=len(env_seeds),
            objects=(object_name,),
            seed=int(env_seeds[0]),  # what a one-env sim records as its seed
            env_seeds=tuple(int(s) for s in env_seeds),
            dr=dr,
            nthread=1,  # small batches: a thread pool would only add overhead
            autoreset=False,  # gymnasium's vector envs own resets
        )
    )


def make_env(object_name: str = "cylinder_a_medium", **kwargs) -> gym.Env:
    """`gym.make` of the registered id; module-level, so that async vector env workers can unpickle it by name."""
    return gym.make(GYM_ID, object_name=object_name, **kwargs)


if GYM_ID not in gym.registry:
    gym.register(
        GYM_ID, entry_point=BlindGraspGymEnv, max_episode_steps=spec.EPISODE_STEPS, disable_env_checker=True
    )
