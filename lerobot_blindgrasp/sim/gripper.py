"""The D'Claw-derived three-finger gripper, built in code from ROBEL's D'Claw (`chain3xh.xml`) and the XM430 facts.
Joint axes and signs follow `spec` (J*1/J*2 > 0 open the finger).

Actuation: `position` actuators (kp, kv randomized per env, Table II; forcerange = stall torque) plus joint damping
= stall torque / no-load speed (the back-EMF of a voltage-limited motor), so the speed limit emerges. Fingertips: a
`*_tip` body at the load cell carries a soft capsule (the elastic printed tips) and the wrench and contact sensors."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.hardware import xm430

# --- Facts (metres, kilograms) -----------------------------------------------------------------------------------
BASE_RADIUS = 0.060
PLATE_TO_J10 = 0.01725
LINK_J10_J11 = 0.0675
LINK_J11_J12 = 0.068
LINK_J12_TIPSITE = 0.076
TIP_CAPSULE_RADIUS = 0.011
TIP_CAPSULE_START = 0.033  # tip body (load cell) origin below J12; the capsule runs from here to 0.084
TIP_CAPSULE_END = 0.084 - TIP_CAPSULE_RADIUS
LINK_MASS = (0.105, 0.105, 0.014)  # knuckle (servo + brackets), proximal (servo + brackets), distal bracket
TIP_MASS = 0.018
PLATE_HEIGHT = 0.25  # plate underside above the table top; straight fingertip end at 1.3 cm
PLATE_RADIUS = 0.075

BACK_EMF_DAMPING = xm430.STALL_TORQUE_NM / xm430.NO_LOAD_SPEED_RAD_S
ARMATURE = 0.002

# Collision groups (bitmasks): fingers collide with each other, the table and the object; the object with
# everything. Links of one finger never collide with each other (adjacent bodies overlap by construction).
_TABLE_BIT, _OBJECT_BIT, _PLATE_BIT = 1, 2, 32
_FINGER_BITS = (4, 8, 16)


# Nominal servo loop gains; Table II scales kp by x[0.3, 3] and kv by x[0.75, 1.5] per env.
SERVO_KP = 15.0  # N m/rad: ~the XM430 default P gain (800) mapped to torque; saturates at 0.27 rad error
SERVO_KV = 0.2  # N m s/rad


@dataclass(frozen=True)
class PhysicsOptions:
    """Solver settings (`python -m lab.contact_settings_sweep`). Elliptic cones + noslip hold a grasp without creep
    under Table II's gains; impratio stays 1 because higher values eject squeezed objects at this 5 ms step."""

    timestep: float = 0.005
    substeps: int = 10  # 10 x 5 ms = one 20 Hz control step
    impratio: float = 1.0
    noslip_iterations: int = 3
    iterations: int = 20
    ls_iterations: int = 10
    torque_limit: float = xm430.STALL_TORQUE_NM  # N m; the robot's default current limit is the same stall point
    tip_friction: float = 1.0
    # Contact time constants (s, MuJoCo clamps them to >= 2 x timestep); the fingertips are the soft printed tips.
    contact_timeconst: float = 0.01
    tip_timeconst: float = 0.02

    def __post_init__(self):
        if abs(self.timestep * self.substeps - spec.CONTROL_DT) > 1e-9:
            raise ValueError(
                f"timestep x substeps must equal the control period {spec.CONTROL_DT} s, "
                f"got {self.timestep} x {self.substeps}"
            )


def _finger_xml(i: int, finger: str) -> str:
    """One finger, in a frame whose x is the radial direction and y the tangential one (seen from above: CCW)."""
    phi = spec.FINGER_BASE_ANGLES_RAD[i]
    bx, by = BASE_RADIUS * math.cos(phi), BASE_RADIUS * math.sin(phi)
    names = spec.JOINT_NAMES[3 * i : 3 * i + 3]
    lo, hi = spec.JOINT_LOWER[3 * i : 3 * i + 3], spec.JOINT_UPPER[3 * i : 3 * i + 3]
    m = spec.HARD_STOP_MARGIN_RAD
    bit = _FINGER_BITS[i]
    others = sum(_FINGER_BITS) - bit
    affinity = _TABLE_BIT | _OBJECT_BIT | others
    col = f'contype="{bit}" conaffinity="{affinity}"'
    link_r = 0.017  # servo-sized capsules for the knuckle and proximal links
    # Axes: J10 about +x (radial) moves the tip +y (CCW); J11/J12 about -y move the tip +x (outward) for q > 0.
    return f"""
    <body name="{finger}_base" pos="{bx:.6f} {by:.6f} {-PLATE_TO_J10:.6f}" euler="0 0 {phi:.9f}">
      <body name="{finger}_l10">
        <joint name="{names[0]}" axis="1 0 0" range="{lo[0] - m:.4f} {hi[0] + m:.4f}"/>
        <geom name="{finger}_g10" type="capsule" fromto="0 0 -0.012 0 0 {-LINK_J10_J11 + 0.012}" size="{link_r}"
              mass="{LINK_MASS[0]}" {col} rgba="0.2 0.2 0.22 1"/>
        <body name="{finger}_l11" pos="0 0 {-LINK_J10_J11}">
          <joint name="{names[1]}" axis="0 -1 0" range="{lo[1] - m:.4f} {hi[1] + m:.4f}"/>
          <geom name="{finger}_g11" type="capsule" fromto="0 0 -0.012 0 0 {-LINK_J11_J12 + 0.012}"
                size="{link_r}" mass="{LINK_MASS[1]}" {col} rgba="0.2 0.2 0.22 1"/>
          <body name="{finger}_l12" pos="0 0 {-LINK_J11_J12}">
            <joint name="{names[2]}" axis="0 -1 0" range="{lo[2] - m:.4f} {hi[2] + m:.4f}"/>
            <geom name="{finger}_g12" type="box" pos="0 0 -0.017" size="0.012 0.014 0.014"
                  mass="{LINK_MASS[2]}" {col} rgba="0.7 0.7 0.72 1"/>
            <body name="{finger}_tip" pos="0 0 {-TIP_CAPSULE_START}">
              <site name="{finger}_loadcell" euler="3.14159265 0 0" size="0.004" rgba="1 0 0 1"/>
              <site name="{finger}_tipsite" pos="0 0 {-(LINK_J12_TIPSITE - TIP_CAPSULE_START):.6f}"
                    euler="3.14159265 0 0" size="0.003"/>
              <geom name="{finger}_tipend" type="sphere" size="{TIP_CAPSULE_RADIUS}" contype="0" conaffinity="0"
                    pos="0 0 {-(TIP_CAPSULE_END - TIP_CAPSULE_START):.6f}" mass="0" rgba="0 0 0 0" group="3"/>
              <geom name="{finger}_tipgeom" class="fingertip" type="capsule"
                    fromto="0 0 {-TIP_CAPSULE_RADIUS} 0 0 {-(TIP_CAPSULE_END - TIP_CAPSULE_START):.6f}"
                    size="{TIP_CAPSULE_RADIUS}" mass="{TIP_MASS}" {col}/>
            </body>
          </body>
        </body>
      </body>
    </body>"""


def gripper_mjcf(object_xml: str, options: PhysicsOptions | None = None) -> str:
    """The whole scene (table, frame, gripper, sensors and one object body) as an MJCF string."""
    o = options or PhysicsOptions()
    fingers = "".join(_finger_xml(i, f) for i, f in enumerate(spec.FINGERS))
    actuators = "".join(
        f'<position name="{j}" joint="{j}" kp="{SERVO_KP}" kv="{SERVO_KV}" forcerange="{-o.torque_limit} '
        f'{o.torque_limit}" ctrlrange="{spec.JOINT_LOWER[k]:.4f} {spec.JOINT_UPPER[k]:.4f}"/>'
        for k, j in enumerate(spec.JOINT_NAMES)
    )
    sensors = "".join(_sensors_xml(f) for f in spec.FINGERS)
    table_aff = _OBJECT_BIT | sum(_FINGER_BITS)
    return f"""
<mujoco model="blindgrasp_dclaw">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{o.timestep}" integrator="implicitfast" cone="elliptic" impratio="{o.impratio}"
          solver="Newton" jacobian="dense" iterations="{o.iterations}" ls_iterations="{o.ls_iterations}"
          noslip_iterations="{o.noslip_iterations}"/>
  <visual><global offwidth="640" offheight="480"/><quality shadowsize="2048"/></visual>
  <default>
    <joint damping="{BACK_EMF_DAMPING:.4f}" armature="{ARMATURE}" frictionloss="0.01"/>
    <geom condim="3" friction="1 0.005 0.0001" solref="{o.contact_timeconst} 1"/>
    <default class="fingertip">
      <geom condim="4" friction="{o.tip_friction} 0.01 0.0001" solref="{o.tip_timeconst} 1"
            solimp="0.9 0.97 0.002" rgba="0.95 0.45 0.1 1"/>
    </default>
  </default>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.8 0.8 0.8" rgb2="0.7 0.7 0.7" width="256" height="256"/>
    <material name="table" texture="grid" texrepeat="8 8"/>
  </asset>
  <worldbody>
    <light pos="0.3 -0.3 0.8" dir="-0.3 0.3 -0.8" diffuse="0.8 0.8 0.8"/>
    <light pos="-0.3 0.3 0.8" dir="0.3 -0.3 -0.8" diffuse="0.4 0.4 0.4"/>
    <camera name="side" pos="0.30 -0.30 0.16" xyaxes="0.707 0.707 0 -0.1 0.1 0.99"/>
    <geom name="table" type="plane" pos="0 0 0" size="0.35 0.35 0.01" material="table" friction="0.5 0.005 0.0001"
          contype="{_TABLE_BIT}" conaffinity="{table_aff}"/>
    <geom name="frame_post" type="box" pos="0 0.2 0.14" size="0.015 0.015 0.14" rgba="0.3 0.3 0.3 1"
          contype="0" conaffinity="0"/>
    <body name="claw" pos="0 0 {PLATE_HEIGHT}">
      <geom name="plate" type="cylinder" pos="0 0 0.004" size="{PLATE_RADIUS} 0.004" rgba="0.5 0.6 0.9 0.6"
            contype="{_PLATE_BIT}" conaffinity="0"/>
      <site name="claw_centre" pos="0 0 0" size="0.003"/>
      {fingers}
    </body>
    {object_xml}
  </worldbody>
  <actuator>{actuators}</actuator>
  <sensor>{sensors}</sensor>
</mujoco>"""


def _sensors_xml(f: str) -> str:
    """Finger f's sensors: tip contact forces, the load cell's wrench, the tip's pose, its distance to the object."""
    return "".join(
        [
            f'<contact name="{f}_contact" geom1="{f}_tipgeom" data="force" reduce="netforce"/>',
            # the same, restricted to the object: lets shaping tell a touch on the object from a push on the table
            f'<contact name="{f}_objcontact" geom1="{f}_tipgeom" geom2="object_geom" data="force" reduce="netforce"/>',
            f'<force name="{f}_force" site="{f}_loadcell"/>',
            f'<torque name="{f}_torque" site="{f}_loadcell"/>',
            f'<framepos name="{f}_pos" objtype="site" objname="{f}_tipsite"/>',
            f'<framequat name="{f}_quat" objtype="site" objname="{f}_tipsite"/>',
            f'<framezaxis name="{f}_zaxis" objtype="site" objname="{f}_loadcell"/>',
            # distance from the tip END (where the axial load cell reads pushes) to the object, for the reach term
            f'<distance name="{f}_objdist" geom1="{f}_tipend" geom2="object_geom" cutoff="0.3"/>',
        ]
    )


OBJECT_CONTYPE = _OBJECT_BIT
OBJECT_CONAFFINITY = _TABLE_BIT | _PLATE_BIT | sum(_FINGER_BITS)


def compile_model(object_xml: str, options: PhysicsOptions | None = None) -> mujoco.MjModel:
    return mujoco.MjSpec.from_string(gripper_mjcf(object_xml, options)).compile()
