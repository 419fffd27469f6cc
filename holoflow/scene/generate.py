"""Prompt words -> procedural Scene (rooms, furniture, terrain, trees, water, buildings, sky, effects).

``scene_from_prompt(prompt, seed)`` reads the prompt's words through the tables in
holoflow.scene.vocab; every random choice comes from one numpy Generator seeded by (seed, CRC32 of the
prompt), so the same prompt and seed always give the same Scene. Coordinates: +x right, +y down,
+z forward, metres; the camera is at the origin, the floor / ground at ``y = eye_height``.
"""

from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass, field

import numpy as np

from holoflow.scene import vocab
from holoflow.scene.model import Box, Cylinder, Effects, Ellipsoid, Ground, Material, PointLight, Room, Scene, Sky, Vec3

EYE_HEIGHT = 1.6  # metres above the floor / ground
CAMERA_CLEARANCE = 0.5  # metres: nothing is placed closer to the camera than this


def tokens(prompt: str) -> list[str]:
    """Lower-case words of a prompt; 'L-shaped' becomes 'lshaped'."""
    text = re.sub(r"\bl[\s-]+shaped\b", "lshaped", prompt.lower())
    return re.findall(r"[a-z]+", text)


@dataclass
class Words:
    """What the prompt says, by role."""

    words: list[str]
    attrs: dict[str, dict] = field(default_factory=dict)  # target -> {"color": rgb, "material": word}
    loose_color: Vec3 | None = None
    loose_material: str | None = None

    def has(self, *ws: str) -> bool:
        return any(w in self.words for w in ws)


def parse(prompt: str) -> Words:
    """Bind colour / material words to the noun that follows them (within three words)."""
    ws = tokens(prompt)
    out = Words(ws)
    used = set()
    for i, w in enumerate(ws):
        target = "wall" if w in vocab.ROOMS else vocab.TARGETS.get(w)
        if target is None:
            continue
        slot = out.attrs.setdefault(target, {})
        for j in range(i - 1, max(i - 4, -1), -1):
            prev = ws[j]
            if prev in vocab.COLORS and "color" not in slot:
                rgb = np.array(vocab.COLORS[prev])
                if j > 0 and ws[j - 1] in vocab.SHADES:
                    rgb = np.clip(rgb * vocab.SHADES[ws[j - 1]], 0.0, 0.9)
                slot["color"] = tuple(float(x) for x in rgb)
                used.add(j)
            elif prev in vocab.MATERIALS and "material" not in slot:
                slot["material"] = prev
                used.add(j)
            elif prev in vocab.TARGETS or prev in vocab.ROOMS or prev in ("and", "with", "of", "in", "on"):
                break
    for j, w in enumerate(ws):
        if j in used:
            continue
        if w in vocab.COLORS and out.loose_color is None:
            out.loose_color = vocab.COLORS[w]
        elif w in vocab.MATERIALS and out.loose_material is None:
            out.loose_material = w
    return out


class _Builder:
    """Accumulates materials and primitives; rounds numbers so scene.json stays readable."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.materials: list[Material] = []
        self.boxes: list[Box] = []
        self.ellipsoids: list[Ellipsoid] = []
        self.cylinders: list[Cylinder] = []
        self.lights: list[PointLight] = []
        self.objects: list[str] = []
        self.footprints: list[tuple[float, float, float]] = []  # (x, z, radius) on the floor
        self.footprints_mounted: list[tuple[float, float, float]] = []  # wall-mounted: (x, z, half width)

    def material(self, kind: str, color, color2, scale: float = 1.0, emission: float = 0.0) -> int:
        self.materials.append(
            Material(kind, _v(color), _v(color2), _r(scale), _r(emission), int(self.rng.integers(0, 1 << 16)))
        )
        return len(self.materials) - 1

    def box(self, center, half, yaw: float, mat: int) -> None:
        self.boxes.append(Box(_v(center), _v(half), _r(yaw), mat))

    def ellipsoid(self, center, radii, mat: int) -> None:
        self.ellipsoids.append(Ellipsoid(_v(center), _v(radii), mat))

    def cylinder(self, center, radius: float, half_height: float, mat: int) -> None:
        self.cylinders.append(Cylinder(_v(center), _r(radius), _r(half_height), mat))

    def free(
        self, x: float, z: float, radius: float, half: tuple[float, float] | None = None, yaw: float = 0.0
    ) -> bool:
        """Is the floor disk (x, z, radius) clear of placed objects, and the object (its rectangle of
        half sizes ``half`` turned by ``yaw``, else the disk) clear of the camera?"""
        if half is None:
            cam = math.hypot(x, z) - radius
        else:  # distance from the camera to the rotated rectangle
            c, s = math.cos(yaw), math.sin(yaw)
            lx, lz = -(c * x - s * z), -(s * x + c * z)
            cam = math.hypot(max(abs(lx) - half[0], 0.0), max(abs(lz) - half[1], 0.0))
        if cam < CAMERA_CLEARANCE:
            return False
        return all(math.hypot(x - fx, z - fz) >= radius + fr for fx, fz, fr in self.footprints)


def _r(x: float) -> float:
    return round(float(x), 4)


def _v(v) -> Vec3:
    return tuple(_r(x) for x in v)


def _jitter(rng: np.random.Generator, rgb, amount: float = 0.12) -> Vec3:
    return tuple(float(np.clip(c * (1.0 + amount * (rng.random() * 2 - 1)), 0.0, 0.95)) for c in rgb)


def _surface(
    b: _Builder, w: Words, target: str, default_word: str, emission: float = 0.0, color=None, loose: bool = False
) -> int:
    """Material for a scene part: the prompt's material / colour words for ``target`` win over defaults."""
    slot = w.attrs.get(target, {})
    word = slot.get("material") or (w.loose_material if loose else None) or default_word
    kind, c, c2, scale = vocab.MATERIALS.get(word) or vocab.OUTDOOR_GROUNDS[word]
    rgb = slot.get("color") or (w.loose_color if loose else None) or color
    if rgb is not None:
        keep_c2 = kind in ("brick", "tiles", "carpet", "facade", "grass", "sand", "snow", "asphalt")
        c, c2 = rgb, (c2 if keep_c2 else tuple(0.5 * x for x in rgb))
    else:
        c = _jitter(b.rng, c)
    return b.material(kind, c, c2, scale, emission)


def _color(b: _Builder, w: Words, target: str, default) -> Vec3:
    """The prompt's colour for ``target``, else the default with a little seeded variation."""
    rgb = w.attrs.get(target, {}).get("color")
    return rgb if rgb is not None else _jitter(b.rng, default)


# ----------------------------------------------------------------------------------------- sky, effects
def _sky(w: Words, rng: np.random.Generator, indoor: bool) -> tuple[Sky, str, Vec3, Vec3]:
    """Sky, time of day, ambient radiance and sun radiance from the time / cloud words."""
    times = [vocab.TIME_WORDS[x] for x in w.words if x in vocab.TIME_WORDS]
    time = times[0] if times else "noon"
    el_deg, sun_rad, zenith, horizon, ambient = vocab.TIMES[time]
    clouds = max([vocab.CLOUD_WORDS[x] for x in w.words if x in vocab.CLOUD_WORDS], default=0.0)
    sky_col = w.attrs.get("sky", {}).get("color")
    if sky_col is not None:
        zenith = tuple(0.7 * z + 0.3 * c for z, c in zip(zenith, sky_col))
        horizon = tuple(0.4 * h + 0.6 * c for h, c in zip(horizon, sky_col))
    if clouds >= 0.85:  # overcast: the sun goes soft, the sky grey
        sun_rad = tuple(0.25 * s for s in sun_rad)
        ambient = tuple(1.5 * a for a in ambient)
        grey = float(np.mean(horizon))
        zenith, horizon = (grey * 0.8,) * 3, (grey,) * 3
    az = rng.uniform(-math.pi, math.pi)
    el = math.radians(el_deg)
    sun_dir = (math.cos(el) * math.sin(az), -math.sin(el), math.cos(el) * math.cos(az))
    night = time == "night"
    sun_color = (0.7, 0.75, 0.85) if night else tuple(s / max(sun_rad) for s in sun_rad)
    sky = Sky(time, _v(zenith), _v(horizon), _v(sun_dir), _v(sun_color), 0.02 if night else 0.012, _r(clouds), night)
    return sky, time, _v(ambient), _v((0.0, 0.0, 0.0) if indoor else sun_rad)


def _effects(w: Words, sky: Sky, indoor: bool) -> Effects:
    fog_words = [x for x in w.words if x in vocab.FOG_WORDS]
    on = []
    fog = 0.0
    if fog_words:
        amount = math.prod(vocab.FOG_AMOUNT[x] for x in w.words if x in vocab.FOG_AMOUNT)
        fog = vocab.FOG_WORDS[fog_words[0]] * amount * (0.12 if indoor else 0.025)
        on += fog_words
    shadows = [x for x in w.words if x in vocab.SHADOW_WORDS]
    lights = [x for x in w.words if x in vocab.LIGHT_WORDS]
    night = sky.time == "night"
    fog_color = tuple(0.5 * h + 0.5 * z for h, z in zip(sky.horizon, sky.zenith))
    fog_color = tuple(0.6 * f + 0.4 * float(np.mean(fog_color)) for f in fog_color)
    return Effects(
        _r(fog), _v(fog_color), bool(shadows), bool(lights), night, on + shadows + lights + (["night"] if night else [])
    )


# ----------------------------------------------------------------------------------------- indoor
@dataclass
class _Wall:
    """A straight wall segment on the floor: from p0 to p1, inward unit normal n (x, z)."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    n: tuple[float, float]

    @property
    def length(self) -> float:
        return math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1])


@dataclass
class _Frame:
    """Object frame on the floor: origin (x, z), yaw; local x along, z away from the wall, y = height."""

    x: float
    z: float
    yaw: float
    floor: float

    def at(self, lx: float, height: float, lz: float) -> tuple[float, float, float]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return (self.x + c * lx + s * lz, self.floor - height, self.z - s * lx + c * lz)


def _room(b: _Builder, w: Words, kind: str) -> tuple[Room, list[_Wall], tuple[float, float, float, float]]:
    """Room shell: shape and size words, camera off-centre; returns the walls free for furniture and
    the floor area [xmin, xmax, zmin, zmax] for free-standing objects."""
    rng = b.rng
    size = math.prod(vocab.SIZES[x] for x in w.words if x in vocab.SIZES)
    if kind in ("hall", "church"):
        size *= 1.6
    width = float(np.clip(5.0 * size * rng.uniform(0.85, 1.15), 2.6, 30.0))
    depth = float(np.clip(6.0 * size * rng.uniform(0.85, 1.15), 2.8, 40.0))
    height = float(np.clip(2.7 * min(max(size, 1.0), 2.0) * rng.uniform(0.95, 1.1), 2.4, 12.0))
    floor_y, ceiling_y = EYE_HEIGHT, EYE_HEIGHT - height
    floor_word, wall_word, _ = vocab.ROOM_KINDS[kind]
    floor_m = _surface(b, w, "floor", floor_word)
    wall_m = _surface(b, w, "wall", wall_word, loose=True, color=_wall_color(rng, wall_word))
    ceil_m = _surface(b, w, "ceiling", "plaster", color=(0.78, 0.77, 0.74))
    if w.has(*vocab.ROUND):
        radius = 0.5 * max(width, depth)
        room = Room("round", [], _r(radius), _r(floor_y), _r(ceiling_y), floor_m, wall_m, ceil_m)
        n = 10
        walls = []
        for k in range(n):  # chords just inside the circle
            a0, a1 = 2 * math.pi * k / n, 2 * math.pi * (k + 1) / n
            rr = radius * math.cos(math.pi / n) - 0.02
            p0 = (rr * math.sin(a0), rr * math.cos(a0))
            p1 = (rr * math.sin(a1), rr * math.cos(a1))
            am = 0.5 * (a0 + a1)
            walls.append(_Wall(p0, p1, (-math.sin(am), -math.cos(am))))
        half = radius * 0.7
        return room, walls, (-half, half, -half, half)
    # camera off-centre: at least 1.2 m from every wall
    cx = rng.uniform(-0.5, 0.5) * max(width - 2.4, 0.0)
    cz = rng.uniform(-0.5, 0.5) * max(depth - 2.4, 0.0)
    x0, x1, z0, z1 = -width / 2 - cx, width / 2 - cx, -depth / 2 - cz, depth / 2 - cz
    boxes = [[x0, x1, z0, z1]]
    walls = [
        _Wall((x0, z0), (x1, z0), (0, 1)),
        _Wall((x1, z0), (x1, z1), (-1, 0)),
        _Wall((x1, z1), (x0, z1), (0, -1)),
        _Wall((x0, z1), (x0, z0), (1, 0)),
    ]
    shape = "box"
    if w.has(*vocab.LSHAPE):
        shape = "L"
        ext, wing = width * rng.uniform(0.6, 1.0), depth * rng.uniform(0.4, 0.6)
        if rng.random() < 0.5:  # wing on the +x side, at the far (+z) end
            boxes.append([x1 - 0.01, x1 + ext, z1 - wing, z1])
            walls = [wl for k, wl in enumerate(walls) if k != 1]
        else:  # wing on the -x side
            boxes.append([x0 - ext, x0 + 0.01, z1 - wing, z1])
            walls = [wl for k, wl in enumerate(walls) if k != 3]
    room = Room(shape, [[_r(v) for v in bx] for bx in boxes], 0.0, _r(floor_y), _r(ceiling_y), floor_m, wall_m, ceil_m)
    return room, walls, (x0 + 0.3, x1 - 0.3, z0 + 0.3, z1 - 0.3)


def _wall_color(rng: np.random.Generator, wall_word: str):
    if wall_word != "plaster":
        return None
    palette = [
        (0.72, 0.68, 0.58),
        (0.62, 0.66, 0.62),
        (0.70, 0.60, 0.50),
        (0.58, 0.62, 0.70),
        (0.75, 0.73, 0.70),
        (0.65, 0.52, 0.42),
    ]
    return palette[int(rng.integers(len(palette)))]


# furniture: name -> (width, depth, against a wall?, wall-mounted?)
_FURNITURE = {
    "sofa": (2.0, 0.9, True, False),
    "armchair": (0.9, 0.85, True, False),
    "bed": (1.6, 2.1, True, False),
    "nightstand": (0.5, 0.45, True, False),
    "wardrobe": (1.2, 0.6, True, False),
    "shelves": (1.0, 0.35, True, False),
    "cabinet": (1.4, 0.5, True, False),
    "counter": (2.4, 0.62, True, False),
    "desk": (1.4, 0.7, True, False),
    "bathtub": (1.7, 0.75, True, False),
    "plant": (0.6, 0.6, True, False),
    "lamp": (0.45, 0.45, True, False),
    "painting": (1.0, 0.05, True, True),
    "window": (1.4, 0.04, True, True),
    "table": (1.4, 0.9, False, False),
    "coffee_table": (1.0, 0.6, False, False),
    "chair": (0.5, 0.5, False, False),
    "bench": (1.8, 0.45, False, False),
    "rug": (2.2, 1.5, False, False),
}


def _indoor(b: _Builder, w: Words, sky: Sky, effects: Effects) -> tuple[Room, list[str]]:
    """The room, then its materials, then each item placed in turn, then a ceiling light (each draws
    from ``b.rng`` in turn). Returns the room and the names of what was placed."""
    kinds = [vocab.ROOMS[x] for x in w.words if x in vocab.ROOMS]
    kind = next((k for k in kinds if k != "living"), kinds[0] if kinds else "living")
    room, walls, area = _room(b, w, kind)
    mats = _indoor_materials(b, w, sky, effects)
    names = []
    table_frame = None
    for item in _indoor_items(w, kind, walls, effects):
        frame = _place(b, item, walls, room, area, table_frame)
        if frame is None:
            continue
        _BUILD[item](b, frame, mats, room)
        names.append(item)
        if item == "table":
            table_frame = frame
    if effects.lights:
        _ceiling_light(b, room, area, mats)
        names.append("ceiling_light")
    return room, names


def _indoor_items(w: Words, kind: str, walls: list[_Wall], effects: Effects) -> list[str]:
    """What the room holds: its kind's furniture, what the prompt names, a lamp when lit."""
    items = list(vocab.ROOM_KINDS[kind][2])
    if kind == "library":  # shelves along the walls, as many as fit
        items += ["shelves"] * int(sum(wl.length for wl in walls) / 2.5)
    for x in w.words:
        f = vocab.FURNITURE.get(x)
        if f and f not in items:
            items.append(f)
    if effects.lights and "lamp" not in items:
        items.append("lamp")
    return items


def _indoor_materials(b: _Builder, w: Words, sky: Sky, effects: Effects) -> dict[str, int]:
    """The room's materials by role (furniture builders look them up by these names)."""
    rng = b.rng
    return {
        "wood": _surface(b, w, "table", "wood"),
        "fabric": _surface(
            b,
            w,
            "sofa",
            "fabric",
            color=_pick(rng, [(0.25, 0.28, 0.32), (0.45, 0.12, 0.08), (0.12, 0.2, 0.3), (0.35, 0.3, 0.22)]),
        ),
        "bed": _surface(b, w, "bed", "linen"),
        "cabinet": _surface(b, w, "cabinet", "oak"),
        "shelves": _surface(b, w, "shelves", "walnut"),
        "metal": b.material("metal", (0.12, 0.12, 0.13), (0.08, 0.08, 0.08)),
        "white": b.material("plain", (0.78, 0.78, 0.76), (0.7, 0.7, 0.7)),
        "rug": _surface(
            b,
            w,
            "rug",
            "carpet",
            color=_pick(rng, [(0.35, 0.08, 0.06), (0.1, 0.15, 0.3), (0.45, 0.35, 0.2), (0.2, 0.25, 0.15)]),
        ),
        "leaves": b.material("leaves", (0.05, 0.2, 0.04), (0.12, 0.3, 0.06), 0.4),
        "pot": b.material("plain", (0.45, 0.18, 0.08), (0.3, 0.1, 0.05)),
        "painting": b.material("painting", (0.5, 0.4, 0.3), (0.1, 0.08, 0.05), 0.6),
        "marble": b.material("marble", (0.8, 0.78, 0.74), (0.25, 0.25, 0.27), 0.4),
        "shade": b.material(
            "glow" if effects.lights else "fabric",
            (0.95, 0.85, 0.6),
            (0.8, 0.7, 0.5),
            1.0,
            3.0 if effects.lights else 0.0,
        ),
        "window": b.material("window", tuple(min(1.0, 1.6 * c) for c in sky.horizon), (0.85, 0.85, 0.82), 0.45, 1.0),
        "books": b.material("books", (0.3, 0.16, 0.07), (0.3, 0.16, 0.07), 0.4),
    }


def _place(b: _Builder, item: str, walls: list[_Wall], room: Room, area, table_frame) -> _Frame | None:
    """Where ``item`` goes: against a wall, at the table (a chair), or free in ``area``, its footprint
    taken; None after 40 tries."""
    rng = b.rng
    wdt, dep, on_wall, mounted = _FURNITURE[item]
    for _ in range(40):
        if on_wall:
            wall = walls[int(rng.integers(len(walls)))]
            if wall.length < wdt + 0.4:
                continue
            t = rng.uniform(wdt / 2 + 0.2, wall.length - wdt / 2 - 0.2)
            ux, uz = (wall.p1[0] - wall.p0[0]) / wall.length, (wall.p1[1] - wall.p0[1]) / wall.length
            ax, az = wall.p0[0] + ux * t, wall.p0[1] + uz * t
            yaw = math.atan2(wall.n[0], wall.n[1])
            fx, fz = ax + wall.n[0] * dep / 2, az + wall.n[1] * dep / 2
        elif item == "chair" and table_frame is not None:
            side = int(rng.integers(4))
            tw, td = _FURNITURE["table"][0], _FURNITURE["table"][1]
            lx, lz = [(0, td / 2 + 0.4), (0, -td / 2 - 0.4), (tw / 2 + 0.4, 0), (-tw / 2 - 0.4, 0)][side]
            lx += rng.uniform(-0.3, 0.3) * (side < 2)
            ax, _, az = table_frame.at(lx, 0, lz)
            yaw = table_frame.yaw + [math.pi, 0, -math.pi / 2, math.pi / 2][side]
            fx, fz = ax, az
        else:
            ax, az = rng.uniform(area[0], area[1]), rng.uniform(area[2], area[3])
            yaw = rng.choice([0.0, math.pi / 2]) + rng.uniform(-0.15, 0.15)
            fx, fz = ax, az
        radius = 0.5 * math.hypot(wdt, dep) * 0.8
        if mounted:
            if any(math.hypot(ax - mx, az - mz) < wdt / 2 + mr for mx, mz, mr in b.footprints_mounted):
                continue
            b.footprints_mounted.append((ax, az, wdt / 2))
            return _Frame(ax, az, yaw, room.floor_y)
        if item == "rug" and math.hypot(fx, fz) < 2.5:
            return _Frame(ax, az, yaw, room.floor_y)
        if item != "rug" and b.free(fx, fz, radius, (wdt / 2, dep / 2), yaw):
            b.footprints.append((fx, fz, radius))
            return _Frame(ax, az, yaw, room.floor_y)
    return None


def _ceiling_light(b: _Builder, room: Room, area, mats: dict[str, int]) -> None:
    """A ceiling light above the middle of the free area (not right above the camera), so the whole
    room is lit."""
    cx, cz = 0.5 * (area[0] + area[1]), 0.5 * (area[2] + area[3])
    r = math.hypot(cx, cz)
    if r < 1.2:  # not right above the camera
        ux, uz = (cx / r, cz / r) if r > 1e-6 else (0.0, 1.0)
        cx, cz = 1.2 * ux, 1.2 * uz
    y = room.ceiling_y + 0.35
    b.cylinder((cx, room.ceiling_y + 0.12, cz), 0.01, 0.12, mats["metal"])
    b.ellipsoid((cx, y, cz), (0.12, 0.12, 0.12), mats["shade"])
    b.lights.append(PointLight(_v((cx, y + 0.2, cz)), _v((1.2, 1.05, 0.8))))


def _pick(rng: np.random.Generator, options: list):
    return options[int(rng.integers(len(options)))]


def _box_local(
    b: _Builder, f: _Frame, lx: float, bottom: float, lz: float, hx: float, hy: float, hz: float, mat: int
) -> None:
    """Box in the object frame: centre (lx, lz) on the floor plane, from ``bottom`` up by 2*hy."""
    b.box(f.at(lx, bottom + hy, lz), (hx, hy, hz), f.yaw, mat)


def _legs(b: _Builder, f: _Frame, hx: float, hz: float, height: float, mat: int, r: float = 0.025) -> None:
    for sx in (-1, 1):
        for sz in (-1, 1):
            b.cylinder(f.at(sx * (hx - 0.05), height / 2, sz * (hz - 0.05) + 0.0), r, height / 2, mat)


def _sofa(b, f, m, room, width=2.0, depth=0.9):
    _box_local(b, f, 0, 0.08, depth / 2, width / 2, 0.17, depth / 2, m["fabric"])
    _box_local(b, f, 0, 0.08, 0.12, width / 2, 0.4, 0.12, m["fabric"])
    for s in (-1, 1):
        _box_local(b, f, s * (width / 2 - 0.1), 0.08, depth / 2, 0.1, 0.26, depth / 2, m["fabric"])
    _box_local(b, f, 0, 0.0, depth / 2, width / 2 - 0.05, 0.04, depth / 2 - 0.05, m["metal"])


def _armchair(b, f, m, room):
    _sofa(b, f, m, room, width=0.9, depth=0.85)


def _bed(b, f, m, room):
    _box_local(b, f, 0, 0.0, 1.05, 0.8, 0.2, 1.05, m["wood"])
    _box_local(b, f, 0, 0.4, 1.06, 0.77, 0.1, 1.0, m["bed"])
    _box_local(b, f, 0, 0.45, 1.4, 0.79, 0.08, 0.66, m["fabric"])
    _box_local(b, f, 0, 0.0, 0.04, 0.8, 0.55, 0.04, m["wood"])
    for s in (-1, 1):
        _box_local(b, f, s * 0.38, 0.6, 0.3, 0.3, 0.07, 0.18, m["white"])


def _nightstand(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0.225, 0.25, 0.25, 0.225, m["cabinet"])
    _table_lamp(b, f, m, 0.5, 0.2)


def _table_lamp(b, f, m, bottom, lz):
    b.cylinder(f.at(0, bottom + 0.15, lz), 0.02, 0.15, m["metal"])
    b.cylinder(f.at(0, bottom + 0.38, lz), 0.14, 0.1, m["shade"])
    if b.materials[m["shade"]].emission > 0:
        x, y, z = f.at(0, bottom + 0.38, lz)
        b.lights.append(PointLight(_v((x, y, z)), _v((0.45, 0.38, 0.25))))


def _wardrobe(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0.3, 0.6, 1.05, 0.3, m["cabinet"])


def _shelves(b, f, m, room):
    h = min(2.1, (room.floor_y - room.ceiling_y) - 0.2)
    _box_local(b, f, 0, 0.0, 0.17, 0.5, h / 2, 0.17, m["shelves"])
    _box_local(b, f, 0, 0.05, 0.345, 0.47, h / 2 - 0.05, 0.01, m["books"])


def _cabinet(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0.25, 0.7, 0.45, 0.25, m["cabinet"])
    _box_local(b, f, 0, 0.9, 0.26, 0.72, 0.02, 0.26, m["marble"])


def _counter(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0.3, 1.2, 0.45, 0.3, m["cabinet"])
    _box_local(b, f, 0, 0.9, 0.31, 1.22, 0.02, 0.31, m["marble"])
    _box_local(b, f, 0, 1.5, 0.18, 1.2, 0.35, 0.18, m["cabinet"])


def _desk(b, f, m, room):
    _box_local(b, f, 0, 0.72, 0.35, 0.7, 0.02, 0.35, m["wood"])
    for s in (-1, 1):
        _box_local(b, f, s * 0.67, 0.0, 0.35, 0.02, 0.36, 0.33, m["wood"])
    _table_lamp(b, f, m, 0.74, 0.15)


def _bathtub(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0.375, 0.85, 0.28, 0.375, m["white"])


def _plant(b, f, m, room):
    b.cylinder(f.at(0, 0.2, 0.3), 0.18, 0.2, m["pot"])
    b.ellipsoid(f.at(0, 0.85, 0.3), (0.33, 0.5, 0.33), m["leaves"])


def _lamp(b, f, m, room):
    b.cylinder(f.at(0, 0.02, 0.22), 0.16, 0.02, m["metal"])
    b.cylinder(f.at(0, 0.78, 0.22), 0.015, 0.76, m["metal"])
    b.cylinder(f.at(0, 1.6, 0.22), 0.2, 0.15, m["shade"])
    if b.materials[m["shade"]].emission > 0:
        x, y, z = f.at(0, 1.6, 0.22)
        b.lights.append(PointLight(_v((x, y, z)), _v((0.8, 0.65, 0.42))))


def _painting(b, f, m, room):
    _box_local(b, f, 0, 1.2, 0.02, 0.5, 0.35, 0.02, m["painting"])
    _box_local(b, f, 0, 1.17, 0.015, 0.53, 0.38, 0.015, m["shelves"])


def _window(b, f, m, room):
    top = min(2.3, room.floor_y - room.ceiling_y - 0.3)
    _box_local(b, f, 0, top - 1.4, 0.015, 0.7, 0.7, 0.015, m["window"])


def _table(b, f, m, room, hx=0.7, hz=0.45, height=0.75):
    _box_local(b, f, 0, height - 0.04, 0, hx, 0.02, hz, m["wood"])
    _legs(b, f, hx, hz, height - 0.04, m["wood"])


def _coffee_table(b, f, m, room):
    _table(b, f, m, room, 0.5, 0.3, 0.42)


def _chair(b, f, m, room):
    _box_local(b, f, 0, 0.43, 0, 0.22, 0.02, 0.22, m["wood"])
    _box_local(b, f, 0, 0.45, -0.2, 0.22, 0.25, 0.02, m["wood"])
    _legs(b, f, 0.22, 0.22, 0.43, m["wood"], 0.018)


def _bench(b, f, m, room):
    _box_local(b, f, 0, 0.42, 0, 0.9, 0.03, 0.22, m["wood"])
    for s in (-1, 1):
        _box_local(b, f, s * 0.8, 0.0, 0, 0.03, 0.21, 0.2, m["wood"])


def _rug(b, f, m, room):
    _box_local(b, f, 0, 0.0, 0, 1.1, 0.006, 0.75, m["rug"])


_BUILD = {
    "sofa": _sofa,
    "armchair": _armchair,
    "bed": _bed,
    "nightstand": _nightstand,
    "wardrobe": _wardrobe,
    "shelves": _shelves,
    "cabinet": _cabinet,
    "counter": _counter,
    "desk": _desk,
    "bathtub": _bathtub,
    "plant": _plant,
    "lamp": _lamp,
    "painting": _painting,
    "window": _window,
    "table": _table,
    "coffee_table": _coffee_table,
    "chair": _chair,
    "bench": _bench,
    "rug": _rug,
}


# ----------------------------------------------------------------------------------------- outdoor
_TREES = {
    "forest": 40,
    "park": 12,
    "lake": 10,
    "village": 8,
    "mountain": 8,
    "snow": 8,
    "beach": 4,
    "city": 6,
    "desert": 0,
}
_ROCKS = {
    "desert": 12,
    "mountain": 14,
    "beach": 6,
    "park": 3,
    "forest": 5,
    "snow": 5,
    "lake": 6,
    "village": 2,
    "city": 0,
}
_HILLS = {"park": 5, "forest": 4, "lake": 4, "village": 4, "mountain": 3, "snow": 4, "desert": 6, "beach": 1, "city": 0}


def _outdoor(b: _Builder, w: Words, sky: Sky, effects: Effects) -> tuple[Ground, list[str]]:
    """Ground and water, then hills, mountains, trees, rocks, buildings and lamps, in that order (each
    draws from ``b.rng`` in turn). Returns the ground and the names of what was placed."""
    biomes = [vocab.BIOMES[x] for x in w.words if x in vocab.BIOMES]
    biome = biomes[0] if biomes else "park"
    ground, water = _ground(b, w, biome)
    spot = _spotter(b, ground)
    placed = [
        biome,
        water,
        _hills(b, w, biome, spot),
        _mountains(b, w, biome),
        _trees(b, w, biome, spot),
        _rocks(b, w, biome, spot),
        _buildings(b, w, biome, effects, spot),
        _lamps(b, effects, spot),
    ]
    return ground, [name for name in placed if name]


def _ground(b: _Builder, w: Words, biome: str) -> tuple[Ground, str | None]:
    """The ground plane and its water (a sea far off, or a lake): (ground, "sea" | "lake" | None)."""
    rng = b.rng
    ground_m = _surface(b, w, "ground", biome)
    sea = w.has("sea", "ocean", "beach", "coast", "island")
    lake = sea or w.has("lake", "pond", "river") or biome == "lake"
    water_c = _color(b, w, "water", (0.02, 0.06, 0.08))
    water_m = b.material("water", water_c, tuple(0.6 * c for c in water_c), 1.0)
    ground = Ground(_r(EYE_HEIGHT), 1500.0 if sea else 400.0, ground_m, water_m)
    if sea:
        az = rng.uniform(-math.pi, math.pi)
        big = 4000.0
        dist = big + rng.uniform(12.0, 25.0)
        ground.water.append([_r(dist * math.sin(az)), _r(dist * math.cos(az)), big])
        return ground, "sea"
    if lake:
        az = rng.uniform(-math.pi, math.pi)
        r = rng.uniform(12.0, 30.0)
        dist = r + rng.uniform(5.0, 12.0)
        ground.water.append([_r(dist * math.sin(az)), _r(dist * math.cos(az)), _r(r)])
        return ground, "lake"
    return ground, None


def _spotter(b: _Builder, ground: Ground):
    """``spot(rmin, rmax, radius)``: a random dry, free place (x, z) at rmin..rmax metres from the eye
    (uniform over the annulus), its footprint of ``radius`` metres taken; None after 30 tries."""
    rng = b.rng

    def dry(x, z, pad):
        return all(math.hypot(x - cx, z - cz) > r + pad for cx, cz, r in ground.water)

    def spot(rmin, rmax, radius):
        for _ in range(30):
            az, d = rng.uniform(-math.pi, math.pi), math.sqrt(rng.uniform(rmin**2, rmax**2))
            x, z = d * math.sin(az), d * math.cos(az)
            if dry(x, z, radius) and b.free(x, z, radius):
                b.footprints.append((x, z, radius))
                return x, z
        return None

    return spot


def _hills(b: _Builder, w: Words, biome: str, spot) -> None:
    rng, gy = b.rng, EYE_HEIGHT
    hill_m = _surface(b, w, "hill", biome)
    for _ in range(_HILLS.get(biome, 3) + 4 * w.has("hill", "hills", "hilly")):
        r = rng.uniform(25.0, 70.0)
        at = spot(90.0, 300.0, r * 0.8)
        if at:
            top = rng.uniform(4.0, 18.0)
            b.ellipsoid((at[0], gy + r * 0.6 - top, at[1]), (r, r * 0.6, r * rng.uniform(0.7, 1.3)), hill_m)


def _mountains(b: _Builder, w: Words, biome: str) -> str | None:
    if not (biome == "mountain" or w.has("mountain", "mountains", "alpine")):
        return None
    rng, gy = b.rng, EYE_HEIGHT
    rock_m = _surface(b, w, "mountain", "mountain")
    snow_m = b.material("snow", (0.62, 0.64, 0.68), (0.5, 0.54, 0.62), 4.0)
    for k in range(7):  # a ring of peaks: tall ellipsoids with snow caps
        az = 2 * math.pi * k / 7 + rng.uniform(-0.3, 0.3)
        d, r = rng.uniform(450.0, 700.0), rng.uniform(110.0, 200.0)
        hgt = rng.uniform(1.4, 2.2) * r
        c = (d * math.sin(az), gy + hgt * 0.3, d * math.cos(az))
        b.ellipsoid(c, (r, hgt, r * 0.8), rock_m)
        b.ellipsoid((c[0], c[1] - hgt * 0.33, c[2]), (r * 0.62, hgt * 0.69, r * 0.5), snow_m)
    return "mountains"


def _trees(b: _Builder, w: Words, biome: str, spot) -> str | None:
    n_trees = _TREES.get(biome, 8) + 10 * w.has("tree", "trees", "forest")
    if not n_trees:
        return None
    rng, gy = b.rng, EYE_HEIGHT
    autumn = w.has("autumn", "fall")
    colors = (
        [(0.6, 0.2, 0.03), (0.7, 0.45, 0.05), (0.45, 0.08, 0.03)]
        if autumn
        else [_color(b, w, "tree", (0.04, 0.18, 0.03))]
    )
    palette = [b.material("leaves", c, tuple(0.6 * x for x in c), 1.0) for c in colors]
    bark = b.material("bark", (0.16, 0.1, 0.06), (0.08, 0.05, 0.03), 1.0)
    conifer = biome in ("snow", "mountain") or w.has("pine", "pines", "conifer", "spruce")
    for _ in range(n_trees):
        at = spot(4.0, 50.0 if biome == "forest" else 70.0, 2.0)
        if at is None:
            continue
        x, z = at
        leaf = palette[int(rng.integers(len(palette)))]
        h = rng.uniform(2.0, 4.0)
        b.cylinder((x, gy - h / 2, z), rng.uniform(0.15, 0.3), h / 2, bark)
        if conifer:
            for k, s in enumerate((1.0, 0.72, 0.45)):
                b.ellipsoid((x, gy - h - 0.4 - 1.6 * k, z), (1.6 * s, 1.4, 1.6 * s), leaf)
        else:
            r = rng.uniform(1.5, 3.0)
            b.ellipsoid((x, gy - h - r * 0.6, z), (r, r * 0.9, r), leaf)
    return "trees"


def _rocks(b: _Builder, w: Words, biome: str, spot) -> str | None:
    n_rocks = _ROCKS.get(biome, 3) + 8 * w.has("rock", "rocks", "boulder", "boulders", "rocky")
    if not n_rocks:
        return None
    rng, gy = b.rng, EYE_HEIGHT
    rock_m = _surface(b, w, "rock", "mountain")
    for _ in range(n_rocks):
        r = rng.uniform(0.3, 2.0)
        at = spot(3.0, 60.0, r)
        if at:
            b.ellipsoid(
                (at[0], gy - r * 0.25, at[1]), (r, r * rng.uniform(0.4, 0.8), r * rng.uniform(0.7, 1.2)), rock_m
            )
    return "rocks"


def _buildings(b: _Builder, w: Words, biome: str, effects: Effects, spot) -> str | None:
    houses = biome == "village" or w.has("house", "houses", "cottage", "cabin", "farm", "farmhouse", "village", "town")
    city = biome == "city" or w.has("building", "buildings", "skyscraper", "skyscrapers", "tower", "towers")
    if not (houses or city):
        return None
    rng, gy = b.rng, EYE_HEIGHT
    lit = effects.night and effects.lights
    glass = (0.9, 0.7, 0.35) if lit else (0.1, 0.13, 0.17)
    default = "concrete" if city else _pick(rng, ["plaster", "brick", "wood", "stone"])
    facades = []
    for _ in range(3):
        base = _surface(b, w, "building", default, loose=True)
        mat = b.materials[base]
        facades.append(b.material("facade", mat.color, glass, 3.2, 1.2 if lit else 0.0))
    roof = b.material("tiles", (0.35, 0.1, 0.05), (0.18, 0.05, 0.03), 0.25)
    for _ in range(22 if city else 8):
        if city:
            hx, hz, hy = rng.uniform(5, 12), rng.uniform(5, 12), rng.uniform(8, 45)
        else:
            hx, hz, hy = rng.uniform(3, 5), rng.uniform(3, 5), rng.uniform(2.5, 4.0)
        at = spot(12.0, 120.0, math.hypot(hx, hz))
        if at is None:
            continue
        yaw = math.atan2(at[0], at[1]) + rng.uniform(-0.2, 0.2)
        b.box((at[0], gy - hy, at[1]), (hx, hy, hz), yaw, facades[int(rng.integers(3))])
        if not city:
            b.box((at[0], gy - 2 * hy - 0.3, at[1]), (hx + 0.4, 0.3, hz + 0.4), yaw, roof)
    return "buildings" if city else "houses"


def _lamps(b: _Builder, effects: Effects, spot) -> str | None:
    if not effects.lights:
        return None
    gy = EYE_HEIGHT
    glow = b.material("glow", (1.0, 0.8, 0.45), (1.0, 0.8, 0.45), 1.0, 4.0)
    pole = b.material("metal", (0.08, 0.08, 0.09), (0.05, 0.05, 0.05))
    for _ in range(6):
        at = spot(5.0, 25.0, 0.3)
        if at:
            b.cylinder((at[0], gy - 1.7, at[1]), 0.05, 1.7, pole)
            b.ellipsoid((at[0], gy - 3.6, at[1]), (0.2, 0.2, 0.2), glow)
            b.lights.append(PointLight(_v((at[0], gy - 3.6, at[1])), _v((9.0, 7.2, 4.0))))
    return "lamps"


# ----------------------------------------------------------------------------------------- entry point
def is_indoor(w: Words) -> bool:
    """Indoor when any room word appears (a room with a view of mountains is still a room)."""
    return any(x in vocab.ROOMS for x in w.words)


def scene_from_prompt(prompt: str, seed: int) -> Scene:
    """Build the procedural Scene for ``prompt``; deterministic in (prompt, seed)."""
    w = parse(prompt)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(" ".join(w.words).encode())])
    b = _Builder(rng)
    indoor = is_indoor(w)
    sky, time, ambient, sun_light = _sky(w, rng, indoor)
    effects = _effects(w, sky, indoor)
    room = ground = None
    if indoor:
        room, names = _indoor(b, w, sky, effects)
        ambient = (0.05, 0.05, 0.06) if effects.night else (0.55, 0.53, 0.5)
        if effects.lights:
            ambient = tuple(0.5 * a for a in ambient)
    else:
        ground, names = _outdoor(b, w, sky, effects)
    key = (0.4, -0.7, 0.6)
    kn = math.sqrt(sum(k * k for k in key))
    return Scene(
        prompt=prompt,
        seed=int(seed),
        kind="indoor" if indoor else "outdoor",
        eye_height=EYE_HEIGHT,
        materials=b.materials,
        sky=sky,
        effects=effects,
        ambient=_v(ambient),
        key_light=_v(tuple(k / kn for k in key)) if indoor else (0.0, 0.0, 0.0),
        sun_light=sun_light,
        room=room,
        ground=ground,
        boxes=b.boxes,
        ellipsoids=b.ellipsoids,
        cylinders=b.cylinders,
        lights=b.lights if effects.lights else [],
        objects=names,
    )
