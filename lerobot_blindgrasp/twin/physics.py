"""The twin's MuJoCo side: one gripper and one object, stepped one 5 ms substep at a time. A placement from (seed,
object) draws the physics and start position `--env.type=blindgrasp` draws for the same `--seed`; success is the
sim's rule (`sim/termination.py`), judged every control period from the placement on.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

import mujoco
import numpy as np
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430
from lerobot_blindgrasp.sim import gripper, objects, observations, randomization, sensors, termination
from lerobot_blindgrasp.sim.gym_env import start_seed

logger = logging.getLogger(__name__)

PARK_XY = (0.30, 0.30)  # where an object waits off the workspace between sessions (the table is 0.35 m half-wide)


@dataclass
class ServoCommand:
    """What the servos' registers ask of the joints, per joint (spec.JOINT_NAMES order)."""

    enabled: np.ndarray = field(default_factory=lambda: np.zeros(spec.NUM_JOINTS, dtype=bool))
    goal_q: np.ndarray = field(default_factory=lambda: np.zeros(spec.NUM_JOINTS))
    kp_factor: np.ndarray = field(default_factory=lambda: np.ones(spec.NUM_JOINTS))
    torque_max_nm: np.ndarray = field(default_factory=lambda: np.full(spec.NUM_JOINTS, xm430.STALL_TORQUE_NM))


@dataclass
class TrialVerdict:
    trial: int
    success: bool
    reason: str


class TwinPhysics:
    def __init__(
        self,
        dr: randomization.DomainRandomization = randomization.EVAL_DR,
        options: gripper.PhysicsOptions | None = None,
        park_object: str = "cylinder_a_medium",
    ):
        self.dr = dr
        self.options = options or gripper.PhysicsOptions()
        self.lock = threading.Lock()
        self.command = ServoCommand()
        self.hand_q: np.ndarray | None = None  # joints held by the operator's hand (torque off), or None
        self.pad_load_n = np.zeros(spec.NUM_FORCES)  # a calibration weight resting on a pad, along its cell's axis
        self._templates: dict[str, mujoco.MjModel] = {}
        self.substeps = 0
        self.trial = 0  # placement counter; verdicts carry it
        self.judging = False
        self.on_verdict = None  # called with a TrialVerdict (from the physics thread, outside the lock)
        self.unstable_resets = 0
        self._load(park_object, None, np.zeros(spec.NUM_JOINTS), np.zeros(spec.NUM_JOINTS))

    # --- models and placements --------------------------------------------------------------------------------
    def _template(self, name: str) -> mujoco.MjModel:
        if name not in self._templates:
            obj = objects.scaled(objects.get_object(name), self.dr.object_size_scale)
            xml = objects.object_mjcf(obj, gripper.OBJECT_CONTYPE, gripper.OBJECT_CONAFFINITY)
            self._templates[name] = gripper.compile_model(xml, self.options)
        return self._templates[name]

    def _load(self, name: str, seed: int | None, q: np.ndarray, qd: np.ndarray) -> dict:
        """A fresh model and state: `name` placed from evaluation index `seed` (None: parked off the workspace)."""
        obj = objects.scaled(objects.get_object(name), self.dr.object_size_scale)
        env_seed = start_seed(seed, name) if seed is not None else spec.SEED_RANGES["eval"].start
        seeds = np.array([env_seed], dtype=np.uint64)
        draw = randomization.draw_physics(self.dr, seeds)
        model = randomization.apply_physics_draw(self._template(name), draw, 0, self.dr.torque_limit_scale)
        _, xy = randomization.draw_reset(self.dr, seeds, np.zeros(1, dtype=np.int64))
        xy = xy[0].numpy() if seed is not None else np.asarray(PARK_XY)
        data = mujoco.MjData(model)
        data.qpos[observations.JOINTS] = q
        data.qvel[observations.JOINTS] = qd
        quat = np.zeros(4)
        mujoco.mju_euler2Quat(quat, np.asarray(obj.euler, dtype=np.float64), "xyz")
        data.qpos[observations.OBJECT_POS] = [xy[0], xy[1], obj.rest_height]
        data.qpos[observations.OBJECT_QUAT] = quat
        data.ctrl[:] = q
        mujoco.mj_forward(model, data)
        self.model, self.data, self.rest_height = model, data, obj.rest_height
        self.base_kp = model.actuator_gainprm[:, 0].copy()
        self.base_kv = -model.actuator_biasprm[:, 2].copy()
        self.sensor_index = sensors.SensorIndex.from_model(model)
        self._applied = None  # the command whose gains and limits are written into `model`
        self._placed_qpos = data.qpos.copy()
        self._held = np.zeros(1, dtype=np.int64)
        self.peak_lift = 0.0
        self._publish()
        # The true squeeze since the placement (the trial record): its instantaneous peak, and the largest force
        # held for two control periods, which any host read in that window sees. The host's peak lies between them.
        self.peak_tip_force_n = np.zeros(spec.NUM_FORCES)
        self.held_tip_force_n = np.zeros(spec.NUM_FORCES)
        self.q_at_peak = q.copy()  # until a first squeeze: a trial that ends before any substep still has a record
        self._recent_force = np.zeros((2 * self.options.substeps, spec.NUM_FORCES))
        return {
            "object": name,
            "seed": seed,
            "env_seed": int(env_seed),
            "object_xy_m": [float(v) for v in xy],
            **{k: round(v, 4) for k, v in draw.row(0).items()},
        }

    def place(self, name: str, seed: int) -> dict:
        """Put `name` on the table where the sim env's start state for (seed, name) has it, and start judging."""
        self._template(name)  # compile outside the lock: the servos keep being simulated meanwhile
        with self.lock:
            placement = self._load(
                name,
                int(seed),
                self.data.qpos[observations.JOINTS].copy(),
                self.data.qvel[observations.JOINTS].copy(),
            )
            self.trial += 1
            self.judging = True
            placement["trial"] = self.trial
        logger.info("placed %s", placement)
        return placement

    def end_trial(self) -> None:
        """The trial is over: the operator takes the object out of the gripper (off the workspace), as between real
        trials, so that the gripper homes unobstructed and the next placement starts clean."""
        with self.lock:
            self.judging = False
            d = self.data
            d.qpos[observations.OBJECT_POS] = [PARK_XY[0], PARK_XY[1], self.rest_height]
            d.qvel[observations.OBJECT_LINVEL.start : observations.OBJECT_ANGVEL.stop] = 0.0
            mujoco.mj_forward(self.model, d)

    # --- stepping ---------------------------------------------------------------------------------------------
    def substep(self) -> None:
        verdict = None
        with self.lock:
            m, d, c = self.model, self.data, self.command
            key = (c.enabled.tobytes(), c.kp_factor.tobytes(), c.torque_max_nm.tobytes())
            if key != self._applied:  # gains and limits change rarely (torque on/off, configure): write them then
                kp = self.base_kp * c.kp_factor * c.enabled
                m.actuator_gainprm[:, 0] = kp
                m.actuator_biasprm[:, 1] = -kp
                m.actuator_biasprm[:, 2] = -self.base_kv * c.enabled
                m.actuator_forcerange[:, 0] = -c.torque_max_nm
                m.actuator_forcerange[:, 1] = c.torque_max_nm
                self._applied = key
            d.ctrl[:] = c.goal_q
            if self.hand_q is not None:
                d.qpos[observations.JOINTS] = self.hand_q
                d.qvel[observations.JOINTS] = 0.0
            mujoco.mj_step(m, d)
            if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
                self._recover()
            self.substeps += 1
            self._publish()
            force = self.tip_force_n
            if force.max() > self.peak_tip_force_n.max():
                self.q_at_peak = self.q.copy()  # the pose that made the trial's largest squeeze (the record)
            self.peak_tip_force_n = np.maximum(self.peak_tip_force_n, force)
            self._recent_force[self.substeps % len(self._recent_force)] = force
            self.held_tip_force_n = np.maximum(self.held_tip_force_n, self._recent_force.min(axis=0))
            if self.substeps % self.options.substeps == 0 and self.judging:
                verdict = self._judge()
        if verdict is not None and self.on_verdict is not None:
            self.on_verdict(verdict)

    def _recover(self) -> None:
        """Unstable physics (the sim env resets such an env too): back to the placement, joints at rest."""
        self.unstable_resets += 1
        logger.warning("twin physics went unstable; restoring the placement state")
        mujoco.mj_resetData(self.model, self.data)  # joints at rest (qvel 0)
        self.data.qpos[:] = self._placed_qpos
        mujoco.mj_forward(self.model, self.data)

    def _judge(self) -> TrialVerdict | None:
        lift = np.array([self.data.qpos[observations.OBJECT_POS][2] - self.rest_height])
        self.peak_lift = max(self.peak_lift, float(lift[0]))
        self._held = termination.held_steps(self._held, lift)
        if termination.is_success(self._held)[0]:
            self.judging = False
            rule = f"lifted >= {spec.SUCCESS_LIFT_M * 100:.1f} cm for {spec.SUCCESS_HOLD_S} s"
            return TrialVerdict(self.trial, True, rule)
        d_xy = np.linalg.norm(self.data.qpos[observations.OBJECT_POS][:2])
        if termination.out_of_workspace(np.array([d_xy]))[0]:
            self.judging = False
            return TrialVerdict(self.trial, False, "object left the workspace")
        return None

    def verdict_now(self) -> bool:
        """The sim's rule at this instant (what the twin answers when the host asks at the time limit)."""
        with self.lock:
            return bool(termination.is_success(self._held)[0])

    # --- what the sensors see ---------------------------------------------------------------------------------
    def _publish(self) -> None:
        """Copies the servos' and the load cells' threads read without taking the lock."""
        d = self.data
        self.q = d.qpos[observations.JOINTS].copy()
        self.qd = d.qvel[observations.JOINTS].copy()
        self.tau = d.actuator_force.copy()
        self._sensordata = d.sensordata.copy()

    @property
    def tip_force_n(self) -> np.ndarray:
        """The true compressive force on each fingertip's load cell (N), spec.FINGERS order."""
        sd, si = torch.from_numpy(self._sensordata[None]), self.sensor_index
        true = sensors.uniaxial_force(si.read(sd, "contact"), si.read(sd, "zaxis"))[0].numpy()
        # The pad sits on the cell: it can push on it, never pull (a side contact that tilts the tip reads 0).
        return np.maximum(true, 0.0) + self.pad_load_n

    def place_weight(self, tip: int | None, mass_kg: float = 0.0, g: float = 9.80665) -> None:
        """The operator rests a calibration weight on pad `tip` alone (the gripper held so that the pad faces up: the
        whole weight bears along the cell's axis); None takes it off."""
        load = np.zeros(spec.NUM_FORCES)
        if tip is not None:
            if not (0 <= int(tip) < spec.NUM_FORCES and mass_kg > 0):
                raise ValueError(f"a weight needs a pad 0..{spec.NUM_FORCES - 1} and a mass > 0 kg")
            load[int(tip)] = mass_kg * g
        self.pad_load_n = load

    def hold_by_hand(self, q) -> None:
        """The operator holds the joints at q (torque off, as during calibration); None lets go."""
        with self.lock:
            self.hand_q = None if q is None else np.asarray(q, dtype=np.float64).copy()
