"""The paper's 18 training objects (Table I, cm there, metres here) and the catalogue that held-out objects join.
Cuboid X, Y, Z are full edges; the capsule's "Height" is its cylindrical part, and it lies on its side. Mass:
400 kg/m^3, i.e. PLA printed with two walls and ~20 % infill, as 3D-printed replicas usually are."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

OBJECT_DENSITY = 400.0  # kg/m^3


@dataclass(frozen=True)
class ObjectSpec:
    name: str  # e.g. "cylinder_a_medium"
    geometry: str  # "cuboid_a", ...
    size_label: str  # "large" | "medium" | "small"
    mjcf_type: str  # box | capsule | cylinder | sphere
    size: tuple[float, ...]  # MuJoCo geom size (half-extents / radius, half-length)
    euler: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mass_kg: float | None = None  # None: OBJECT_DENSITY x volume (the 3D-printed replicas)

    @property
    def rest_height(self) -> float:
        """Height of the centre above the table when the object rests in its spawn pose."""
        if self.mjcf_type == "box":
            return self.size[2]
        if self.mjcf_type == "cylinder":
            return self.size[1]
        return self.size[0]  # sphere; capsule lying on its side

    @property
    def rest_quat(self) -> tuple[float, float, float, float]:
        """The spawn orientation (wxyz), from `euler` (xyz, rad) as MJCF reads it."""
        import mujoco  # this module builds MJCF text without MuJoCo; only the env asks for quaternions

        q = np.zeros(4)
        mujoco.mju_euler2Quat(q, np.asarray(self.euler, dtype=np.float64), "xyz")
        return tuple(q)

    @property
    def volume(self) -> float:
        s = self.size
        if self.mjcf_type == "box":
            return 8.0 * s[0] * s[1] * s[2]
        if self.mjcf_type == "cylinder":
            return math.pi * s[0] ** 2 * 2.0 * s[1]
        if self.mjcf_type == "capsule":
            return math.pi * s[0] ** 2 * 2.0 * s[1] + 4.0 / 3.0 * math.pi * s[0] ** 3
        return 4.0 / 3.0 * math.pi * s[0] ** 3

    @property
    def mass(self) -> float:
        return self.mass_kg if self.mass_kg is not None else OBJECT_DENSITY * self.volume

    @property
    def task(self) -> str:
        """Natural-language task string (LeRobot `task`) naming the object."""
        return f"grasp and lift the {self.size_label} {self.geometry.replace('_', ' ')}"


# Table I, cm. One row per geometry: parameters for (large, medium, small).
TABLE_I_CM: dict[str, dict[str, tuple[float, float, float]]] = {
    "cuboid_a": {"x": (10.0, 8.0, 6.0), "y": (10.0, 8.0, 6.0), "z": (7.5, 6.0, 4.5)},
    "cuboid_b": {"x": (10.0, 8.0, 6.0), "y": (7.5, 6.0, 4.5), "z": (10.0, 8.0, 6.0)},
    "capsule": {"radius": (3.33, 2.67, 2.00), "height": (3.33, 2.67, 2.00)},
    "cylinder_a": {"radius": (3.75, 3.0, 2.25), "height": (10.0, 8.0, 6.0)},
    "cylinder_b": {"radius": (5.0, 4.0, 3.0), "height": (7.5, 6.0, 4.5)},
    "sphere": {"radius": (5.0, 4.0, 3.0)},
}
SIZES = ("large", "medium", "small")


def _from_table(geometry: str, k: int) -> ObjectSpec:
    p = {key: v[k] / 100.0 for key, v in TABLE_I_CM[geometry].items()}
    name = f"{geometry}_{SIZES[k]}"
    if geometry.startswith("cuboid"):
        return ObjectSpec(name, geometry, SIZES[k], "box", (p["x"] / 2, p["y"] / 2, p["z"] / 2))
    if geometry == "capsule":  # lying along x
        return ObjectSpec(
            name, geometry, SIZES[k], "capsule", (p["radius"], p["height"] / 2), (0.0, math.pi / 2, 0.0)
        )
    if geometry.startswith("cylinder"):
        return ObjectSpec(name, geometry, SIZES[k], "cylinder", (p["radius"], p["height"] / 2))
    return ObjectSpec(name, geometry, SIZES[k], "sphere", (p["radius"],))


CATALOGUE: dict[str, ObjectSpec] = {
    o.name: o for o in (_from_table(g, k) for g in TABLE_I_CM for k in range(len(SIZES)))
}
PAPER_OBJECTS: tuple[str, ...] = tuple(CATALOGUE)  # the 18 training objects, Table I order
MEDIUM_OBJECTS: tuple[str, ...] = tuple(n for n in PAPER_OBJECTS if n.endswith("_medium"))


# Everyday objects outside Table I, for held-out evaluation only: real dimensions and masses, one primitive each.
EVERYDAY: tuple[ObjectSpec, ...] = (
    ObjectSpec("everyday_tennis_ball", "tennis_ball", "everyday", "sphere", (0.0335,), mass_kg=0.058),
    ObjectSpec("everyday_apple", "apple", "everyday", "sphere", (0.038,), mass_kg=0.180),
    ObjectSpec("everyday_soda_can", "soda_can", "everyday", "cylinder", (0.033, 0.061), mass_kg=0.120),
    ObjectSpec("everyday_pill_bottle", "pill_bottle", "everyday", "cylinder", (0.022, 0.040), mass_kg=0.040),
    ObjectSpec("everyday_mug", "mug", "everyday", "cylinder", (0.041, 0.048), mass_kg=0.250),
    ObjectSpec("everyday_tea_box", "tea_box", "everyday", "box", (0.035, 0.0375, 0.0625), mass_kg=0.100),
    ObjectSpec("everyday_rubiks_cube", "rubiks_cube", "everyday", "box", (0.0285, 0.0285, 0.0285), mass_kg=0.090),
    ObjectSpec("everyday_orange", "orange", "everyday", "sphere", (0.042,), mass_kg=0.150),
)


def scaled(obj: ObjectSpec, scale: float) -> ObjectSpec:
    """`obj` with every dimension x `scale` (same density, so mass x scale^3)."""
    mass = None if obj.mass_kg is None else obj.mass_kg * scale**3
    return replace(obj, size=tuple(scale * v for v in obj.size), mass_kg=mass)


CATALOGUE.update((o.name, o) for o in EVERYDAY)
EVERYDAY_OBJECTS: tuple[str, ...] = tuple(o.name for o in EVERYDAY)


def get_object(name: str) -> ObjectSpec:
    try:
        return CATALOGUE[name]
    except KeyError:
        raise ValueError(f"unknown object {name!r}; known objects: {', '.join(CATALOGUE)}") from None


def resolve_objects(names: str | list[str] | tuple[str, ...] | None) -> tuple[str, ...]:
    """Expand "all" (Table I) / "medium" / "everyday" / a comma list into catalogue names, rejecting unknown ones."""
    if names is None or names == "all":
        return PAPER_OBJECTS
    if names == "medium":
        return MEDIUM_OBJECTS
    if names == "everyday":
        return EVERYDAY_OBJECTS
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    out = tuple(names)
    if not out:
        raise ValueError("empty object list")
    for n in out:
        get_object(n)
    return out


def task_id(object_name: str) -> int:
    """An object's catalogue index: its lerobot-eval task_id (`per_task`) and its evaluation seed block."""
    return list(CATALOGUE).index(get_object(object_name).name)


def object_for_task_id(tid: int) -> str:
    names = list(CATALOGUE)
    if not 0 <= tid < len(names):
        raise ValueError(f"task_id {tid} out of range: the catalogue has {len(names)} objects")
    return names[tid]


def object_mjcf(obj: ObjectSpec, contype: int, conaffinity: int) -> str:
    # The spawn rotation goes on the body, not the geom: every object then has the same sparsity layout, which
    # `mujoco.batch` needs to step models of different objects together.
    size = " ".join(f"{v:.6f}" for v in obj.size)
    euler = " ".join(f"{v:.9f}" for v in obj.euler)
    return f"""
    <body name="object" pos="0 0 {obj.rest_height:.6f}" euler="{euler}">
      <freejoint name="object_free"/>
      <geom name="object_geom" type="{obj.mjcf_type}" size="{size}" mass="{obj.mass:.6f}"
            condim="4" friction="1.0 0.005 0.0001" contype="{contype}" conaffinity="{conaffinity}"
            rgba="0.2 0.6 0.3 1"/>
    </body>"""
