"""The procedural scene description: a tree of dataclasses, JSON round-trippable.

World frame = the panorama centre's OpenCV frame (docs/conventions.md): +x right, +y DOWN, +z forward,
metres. The camera sits at the origin; the floor / ground is the plane ``y = eye_height`` (positive, below
the eye). Colours are linear-light albedos in [0, 1]. Primitives name their material by index into
``Scene.materials`` so the renderer can shade every hit of one material in one vectorised pass.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]


@dataclass
class Material:
    """A procedural texture: ``kind`` names a pattern of holoflow.scene.textures; two albedos.

    ``scale`` is the pattern's size in metres (plank width, brick length, tile side, noise cell);
    ``emission`` adds ``emission * color`` radiance (lamp shades, lit windows, sky-lit glass).
    """

    kind: str
    color: Vec3
    color2: Vec3
    scale: float = 1.0
    emission: float = 0.0
    seed: int = 0


@dataclass
class Box:
    """Oriented box: centre, half extents (metres), rotation ``yaw`` about +y (radians)."""

    center: Vec3
    half: Vec3
    yaw: float
    material: int


@dataclass
class Ellipsoid:
    """Axis-aligned ellipsoid (sphere when radii are equal): centre and radii in metres."""

    center: Vec3
    radii: Vec3
    material: int


@dataclass
class Cylinder:
    """Vertical (y-axis) capped cylinder: centre of its axis, radius, half height, metres."""

    center: Vec3
    radius: float
    half_height: float
    material: int


@dataclass
class Room:
    """An enclosing interior seen from inside.

    ``shape``: ``box`` (``boxes[0]``), ``L`` (union of ``boxes[0]`` and ``boxes[1]``) or ``round``
    (vertical cylinder of ``radius`` about the y axis). Boxes are ``[xmin, xmax, zmin, zmax]``; the floor
    is at ``floor_y`` (> 0) and the ceiling at ``ceiling_y`` (< 0).
    """

    shape: str
    boxes: list[list[float]]
    radius: float
    floor_y: float
    ceiling_y: float
    floor_material: int
    wall_material: int
    ceiling_material: int


@dataclass
class Ground:
    """Outdoor ground plane ``y = height`` inside a disk of ``radius`` metres; water disks on it.

    ``water`` holds ``[cx, cz, r]`` disks (lakes, sea) that replace the ground material with water.
    """

    height: float
    radius: float
    material: int
    water_material: int
    water: list[list[float]] = field(default_factory=list)


@dataclass
class Sky:
    """Sky dome colours and the sun (or moon): ``sun_dir`` is the unit direction towards it."""

    time: str
    zenith: Vec3
    horizon: Vec3
    sun_dir: Vec3
    sun_color: Vec3
    sun_size: float
    clouds: float
    stars: bool


@dataclass
class PointLight:
    """Isotropic point light: position (m) and radiant intensity (linear RGB, inverse-square falloff)."""

    position: Vec3
    intensity: Vec3


@dataclass
class Effects:
    """What the prompt asked for; each is off unless a word turned it on (docs/panorama.md)."""

    fog: float = 0.0  # exponential fog density, 1/m (0 = off)
    fog_color: Vec3 = (0.0, 0.0, 0.0)
    shadows: bool = False  # sun / moon shadow rays
    lights: bool = False  # point lights (lamps)
    night: bool = False
    words: list[str] = field(default_factory=list)  # the prompt words that switched effects on


@dataclass
class Scene:
    """A whole procedural scene; ``kind`` is ``indoor`` (a room) or ``outdoor`` (ground + sky)."""

    prompt: str
    seed: int
    kind: str
    eye_height: float
    materials: list[Material]
    sky: Sky
    effects: Effects
    ambient: Vec3
    key_light: Vec3  # soft indoor fill direction (unit, towards the light), no shadows
    sun_light: Vec3  # directional sun / moon radiance (zero indoors)
    room: Room | None = None
    ground: Ground | None = None
    boxes: list[Box] = field(default_factory=list)
    ellipsoids: list[Ellipsoid] = field(default_factory=list)
    cylinders: list[Cylinder] = field(default_factory=list)
    lights: list[PointLight] = field(default_factory=list)
    objects: list[str] = field(default_factory=list)  # names of the placed objects, for people

    def to_json(self) -> str:
        """Canonical JSON (sorted keys, fixed separators): same scene -> same bytes."""
        return json.dumps(dataclasses.asdict(self), sort_keys=True, indent=1) + "\n"

    @classmethod
    def from_json(cls, text: str) -> "Scene":
        return _build(cls, json.loads(text))


def _build(tp, value):
    """Rebuild a value of (annotated) type ``tp`` from its ``dataclasses.asdict`` form."""
    if value is None:
        return None
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        return _build(inner[0], value)
    if dataclasses.is_dataclass(tp):
        hints = typing.get_type_hints(tp)
        return tp(**{f.name: _build(hints[f.name], value[f.name]) for f in dataclasses.fields(tp) if f.name in value})
    if origin is list:
        (arg,) = typing.get_args(tp)
        return [_build(arg, v) for v in value]
    if origin is tuple:
        return tuple(float(v) for v in value)
    if tp is float:
        return float(value)
    return value
