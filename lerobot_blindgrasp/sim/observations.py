"""What the sim observes each control step, over the env axis: `raw` noise-free quantities (rewards, success,
curation); "policy", the student's o_t in R^12; "privileged", the teacher's 92-d vector, assembled by name
(`spec.privileged_parts`). Noise is one N(0, 1) draw per env and step split in `NOISE_LAYOUT` order: changing that
order changes every observation the shipped teacher was evaluated on."""

from __future__ import annotations

import mujoco
import torch

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import force
from lerobot_blindgrasp.sim import randomization, rewards, sensors

# Where the state lives in qpos/qvel: the nine gripper hinges first (spec.JOINT_NAMES order), then the object's
# free joint (position, wxyz quaternion; linear velocity in the world frame, angular velocity in the object frame).
JOINTS = slice(0, spec.NUM_JOINTS)
OBJECT_POS = slice(spec.NUM_JOINTS, spec.NUM_JOINTS + 3)  # qpos
OBJECT_QUAT = slice(spec.NUM_JOINTS + 3, spec.NUM_JOINTS + 7)  # qpos
OBJECT_LINVEL = slice(spec.NUM_JOINTS, spec.NUM_JOINTS + 3)  # qvel
OBJECT_ANGVEL = slice(spec.NUM_JOINTS + 3, spec.NUM_JOINTS + 6)  # qvel

# (reading, size) of the per-step noise draw, in draw order; joints get joint_noise_rad, the rest force_noise_n.
NOISE_LAYOUT: tuple[tuple[str, int], ...] = (
    ("joint_pos", spec.NUM_JOINTS),
    ("uniaxial_force", spec.NUM_FORCES),
    ("fingertip_contact_force", 3 * spec.NUM_FORCES),
    ("fingertip_wrench", 6 * spec.NUM_FORCES),
)
NOISE_DIM = sum(n for _, n in NOISE_LAYOUT)


def check_state_layout(m: mujoco.MjModel) -> None:
    hinges = [m.joint(j) for j in spec.JOINT_NAMES]
    free = m.joint("object_free")
    ok = [int(j.qposadr[0]) for j in hinges] == list(range(spec.NUM_JOINTS))
    ok &= [int(j.dofadr[0]) for j in hinges] == list(range(spec.NUM_JOINTS))
    ok &= int(free.qposadr[0]) == OBJECT_POS.start and int(free.dofadr[0]) == OBJECT_LINVEL.start
    if not ok or m.nq != OBJECT_QUAT.stop or m.nv != OBJECT_ANGVEL.stop:
        raise ValueError(
            "the scene's qpos/qvel order is not the nine spec joints followed by the object's free joint"
        )


def _scaled_noise(noise: torch.Tensor, dr: randomization.DomainRandomization) -> dict[str, torch.Tensor]:
    out, i = {}, 0
    for name, n in NOISE_LAYOUT:
        std = dr.joint_noise_rad if name == "joint_pos" else dr.force_noise_n
        out[name] = noise[:, i : i + n] * std
        i += n
    return out


def _uniaxial_reading(uni_true, noise, dr, sensor_draw) -> torch.Tensor:
    """The load cells' readings: gain, bias, noise and range (force.load_cell), a dead cell, then the deadband."""
    bias = sensor_draw.force_bias if sensor_draw is not None and dr.force_bias_n else 0.0
    signal = force.load_cell(uni_true, noise, gain=dr.force_gain, bias=bias, range_n=dr.force_range_n)
    if dr.dead_force_sensor >= 0:
        signal = signal.clone()
        signal[:, dr.dead_force_sensor] = 0.0
    return force.reading(signal)


def observe(
    qpos: torch.Tensor,
    qvel: torch.Tensor,
    sensordata: torch.Tensor,
    si: sensors.SensorIndex,
    rest_height: torch.Tensor,
    prev_action: torch.Tensor,
    noise: torch.Tensor,
    dr: randomization.DomainRandomization,
    sensor_draw: randomization.SensorDraw | None = None,
) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """(raw, obs) for the given rows of state. Sensor errors beyond Table II (`sensor_draw`, or None) act on what a
    real gripper measures (`joint_pos`, `uniaxial_force`); the teacher's sim-only readings get Table II's noise."""
    contact = si.read(sensordata, "contact")
    tip_quat = si.read(sensordata, "quat")
    uni_true = sensors.uniaxial_force(contact, si.read(sensordata, "zaxis"))
    obj_pos = qpos[:, OBJECT_POS]
    tip_obj = si.read(sensordata, "objcontact")  # world frame, the force each tip exerts on the object
    tip_obj_norm = sensors.sum_short(tip_obj.square(), -1).sqrt()
    raw = {
        "q": qpos[:, JOINTS],
        "uniaxial_clean": force.reading(uni_true),  # noise-free reading (rewards, curation)
        "d_xy": rewards.planar_distance(obj_pos[:, :2]),
        "lift": obj_pos[:, 2] - rest_height,
        "tip_object_distance": si.read(sensordata, "objdist")[:, :, 0].clone(),  # kept: `read` is a live view
        "tip_object_force": tip_obj_norm,
        # -F_z / |F|: 1 when a tip presses the object straight down, 0 sideways (0 without contact)
        "tip_object_downward": -tip_obj[..., 2] / tip_obj_norm.clamp_min(1e-9),
    }
    nz = _scaled_noise(noise, dr)
    n = qpos.shape[0]
    wrench = torch.cat([si.read(sensordata, "force"), si.read(sensordata, "torque")], dim=2)
    joint_pos = raw["q"] + nz["joint_pos"]
    if sensor_draw is not None and dr.joint_calibration_rad:
        joint_pos = joint_pos + sensor_draw.joint_offset
    parts = {
        "joint_pos": joint_pos,
        "joint_vel": qvel[:, JOINTS],
        "fingertip_pos": si.read(sensordata, "pos").reshape(n, -1),
        "fingertip_quat": tip_quat.reshape(n, -1),
        "object_pos": obj_pos,
        "object_quat": qpos[:, OBJECT_QUAT],
        "object_linvel": qvel[:, OBJECT_LINVEL],
        "object_angvel": qvel[:, OBJECT_ANGVEL],
        "fingertip_contact_force": sensors.contact_force_tip_frame(contact, tip_quat).reshape(n, -1)
        + nz["fingertip_contact_force"],
        "object_planar_distance": raw["d_xy"][:, None],
        "uniaxial_force": _uniaxial_reading(uni_true, nz["uniaxial_force"], dr, sensor_draw),
        "fingertip_wrench": wrench.reshape(n, -1) + nz["fingertip_wrench"],
        "previous_action": prev_action,
    }
    obs = {
        "policy": torch.cat([parts["joint_pos"], parts["uniaxial_force"]], dim=1).to(torch.float32),
        "privileged": torch.cat(spec.privileged_parts(parts), dim=1).to(torch.float32),
    }
    return raw, obs
