"""Analytic ray intersection with a Scene's geometry, batched over rays and over primitives.

Rays: origins [N, 3] and unit directions [N, 3] in the world frame (+x right, +y down, +z forward).
Each ``hit_*`` returns a ``Hit`` for the nearest surface of its kind; ``nearest`` merges them. Distances
``t`` are metres along the (unit) ray; a miss is ``t = +inf`` and material ``-1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from holoflow.scene.model import Scene

EPS = 1e-4  # metres: self-intersection guard for secondary rays
_TINY = 1e-12
INF = float("inf")


@dataclass
class Hit:
    """Nearest hits of N rays. ``pos``/``uv`` are texture coordinates in the object's frame (metres)."""

    t: torch.Tensor  # [N] distance along the ray, +inf = miss
    normal: torch.Tensor  # [N, 3] unit world normal (orientation not yet faced to the ray)
    material: torch.Tensor  # [N] int64 index into Scene.materials, -1 = miss
    pos: torch.Tensor  # [N, 3] solid-texture coordinates
    uv: torch.Tensor  # [N, 2] in-surface texture coordinates

    @classmethod
    def miss(cls, n: int, device: torch.device) -> "Hit":
        return cls(
            torch.full((n,), INF, device=device),
            torch.zeros(n, 3, device=device),
            torch.full((n,), -1, dtype=torch.int64, device=device),
            torch.zeros(n, 3, device=device),
            torch.zeros(n, 2, device=device),
        )

    def merge(self, other: "Hit") -> "Hit":
        """Per ray, keep the nearer of two hits."""
        m = other.t < self.t
        return Hit(
            torch.where(m, other.t, self.t),
            torch.where(m[:, None], other.normal, self.normal),
            torch.where(m, other.material, self.material),
            torch.where(m[:, None], other.pos, self.pos),
            torch.where(m[:, None], other.uv, self.uv),
        )


@dataclass
class Packed:
    """A Scene's primitives as tensors (one row per primitive)."""

    box_c: torch.Tensor  # [B, 3]
    box_h: torch.Tensor  # [B, 3] half extents
    box_cs: torch.Tensor  # [B, 2] cos, sin of yaw
    box_m: torch.Tensor  # [B]
    ell_c: torch.Tensor  # [E, 3]
    ell_r: torch.Tensor  # [E, 3]
    ell_m: torch.Tensor  # [E]
    cyl_c: torch.Tensor  # [C, 3]
    cyl_rh: torch.Tensor  # [C, 2] radius, half height
    cyl_m: torch.Tensor  # [C]

    def bounds(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Bounding spheres (centre xyz, radius) [P, 4] of the boxes, ellipsoids and cylinders."""
        return (
            torch.cat([self.box_c, self.box_h.norm(dim=1, keepdim=True)], 1),
            torch.cat([self.ell_c, self.ell_r.amax(1, keepdim=True)], 1),
            torch.cat([self.cyl_c, self.cyl_rh.norm(dim=1, keepdim=True)], 1),
        )

    def subset(self, boxes: torch.Tensor, ells: torch.Tensor, cyls: torch.Tensor) -> "Packed":
        """The primitives selected by three boolean masks."""
        return Packed(
            self.box_c[boxes],
            self.box_h[boxes],
            self.box_cs[boxes],
            self.box_m[boxes],
            self.ell_c[ells],
            self.ell_r[ells],
            self.ell_m[ells],
            self.cyl_c[cyls],
            self.cyl_rh[cyls],
            self.cyl_m[cyls],
        )


def cull(pk: Packed, o: torch.Tensor, d: torch.Tensor) -> Packed:
    """Primitives that rays o, d [N, 3] can possibly hit (conservative bounding-cone test).

    The rays' origins lie in a ball (centre, r_o) and their directions in a cone (axis a, half-angle
    alpha); a primitive's bounding sphere grown by r_o must come within alpha of the axis.
    """
    oc = o.mean(0)
    r_o = (o - oc).norm(dim=1).amax()
    a = d.mean(0)
    if float(a.norm()) < 0.5:  # directions too spread
        return pk
    a = a / a.norm()
    alpha = torch.arccos((d * a).sum(1).amin().clamp(-1.0, 1.0))
    if float(alpha) > 1.2:
        return pk

    def keep(bs: torch.Tensor) -> torch.Tensor:
        v = bs[:, :3] - oc
        dist = v.norm(dim=1)
        rr = bs[:, 3] + r_o + 1e-3
        theta = torch.arccos(((v * a).sum(1) / dist.clamp_min(_TINY)).clamp(-1.0, 1.0))
        beta = torch.arcsin((rr / dist.clamp_min(_TINY)).clamp(max=1.0))
        return (dist <= rr) | (theta <= alpha + beta + 1e-4)

    return pk.subset(*(keep(bs) for bs in pk.bounds()))


def pack(scene: Scene, device: torch.device | str = "cpu") -> Packed:
    """Convert the scene's primitive lists to tensors on ``device``."""

    def f(rows, width):
        return torch.tensor(rows, dtype=torch.float32, device=device).reshape(-1, width)

    def m(rows):
        return torch.tensor(rows, dtype=torch.int64, device=device).reshape(-1)

    b, e, c = scene.boxes, scene.ellipsoids, scene.cylinders
    return Packed(
        f([x.center for x in b], 3),
        f([x.half for x in b], 3),
        f([(math.cos(x.yaw), math.sin(x.yaw)) for x in b], 2),
        m([x.material for x in b]),
        f([x.center for x in e], 3),
        f([x.radii for x in e], 3),
        m([x.material for x in e]),
        f([x.center for x in c], 3),
        f([(x.radius, x.half_height) for x in c], 2),
        m([x.material for x in c]),
    )


def _nonzero(x: torch.Tensor) -> torch.Tensor:
    """Replace |x| < tiny by +-tiny (keeps the sign) so that 1/x stays finite."""
    return torch.where(x.abs() < _TINY, torch.where(x < 0, -_TINY, _TINY), x)


def _dominant_uv(q: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
    """In-plane coordinates [N, 2] of points q [N, 3] on a face whose normal is along ``axis`` [N]."""
    return torch.where(
        (axis == 0)[:, None], q[:, [2, 1]], torch.where((axis == 1)[:, None], q[:, [0, 2]], q[:, [0, 1]])
    )


def hit_boxes(pk: Packed, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Nearest hit with the oriented boxes (slab test in each box's frame)."""
    n = len(o)
    if len(pk.box_c) == 0:
        return Hit.miss(n, o.device)
    cs, sn = pk.box_cs[None, :, 0], pk.box_cs[None, :, 1]  # [1, B]
    oc = o[:, None, :] - pk.box_c[None]  # [N, B, 3]
    lo = torch.stack([cs * oc[..., 0] - sn * oc[..., 2], oc[..., 1], sn * oc[..., 0] + cs * oc[..., 2]], -1)
    dx, dy, dz = d[:, None, 0], d[:, None, 1], d[:, None, 2]  # [N, 1]
    ld = torch.stack([cs * dx - sn * dz, dy.expand_as(cs * dx), sn * dx + cs * dz], -1)  # [N, B, 3]
    inv = 1.0 / _nonzero(ld)
    t1 = (-pk.box_h[None] - lo) * inv
    t2 = (pk.box_h[None] - lo) * inv
    tn = torch.minimum(t1, t2).amax(-1)  # [N, B]
    tf = torch.maximum(t1, t2).amin(-1)
    t = torch.where(tn > EPS, tn, tf)
    t = torch.where((tf >= tn) & (t > EPS), t, INF)
    tbest, idx = t.min(1)  # [N]
    rows = torch.arange(n, device=o.device)
    q = lo[rows, idx] + tbest[:, None] * ld[rows, idx]  # [N, 3] local hit
    h = pk.box_h[idx]
    axis = (q.abs() / h).argmax(1)  # [N]
    nl = torch.zeros_like(q)
    nl[rows, axis] = torch.sign(q[rows, axis])
    c, s = pk.box_cs[idx, 0], pk.box_cs[idx, 1]
    normal = torch.stack([c * nl[:, 0] + s * nl[:, 2], nl[:, 1], -s * nl[:, 0] + c * nl[:, 2]], 1)
    qw = q + pk.box_c[idx]
    hit = torch.isfinite(tbest)
    return Hit(tbest, normal, torch.where(hit, pk.box_m[idx], -1), qw, _dominant_uv(qw, axis))


def hit_ellipsoids(pk: Packed, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Nearest hit with the axis-aligned ellipsoids (unit-sphere test after scaling)."""
    n = len(o)
    if len(pk.ell_c) == 0:
        return Hit.miss(n, o.device)
    lo = (o[:, None, :] - pk.ell_c[None]) / pk.ell_r[None]  # [N, E, 3]
    ld = d[:, None, :] / pk.ell_r[None]
    a = (ld * ld).sum(-1)
    b = (lo * ld).sum(-1)
    c = (lo * lo).sum(-1) - 1.0
    disc = b * b - a * c
    sq = disc.clamp_min(0.0).sqrt()
    t0, t1 = (-b - sq) / a, (-b + sq) / a
    t = torch.where(t0 > EPS, t0, t1)
    t = torch.where((disc >= 0) & (t > EPS), t, INF)
    tbest, idx = t.min(1)
    rows = torch.arange(n, device=o.device)
    q = lo[rows, idx] + tbest[:, None] * ld[rows, idx]  # on the unit sphere
    r = pk.ell_r[idx]
    normal = torch.nn.functional.normalize(q / r, dim=1)
    pos = q * r + pk.ell_c[idx]
    hit = torch.isfinite(tbest)
    return Hit(tbest, normal, torch.where(hit, pk.ell_m[idx], -1), pos, pos[:, [0, 2]])


def hit_cylinders(pk: Packed, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Nearest hit with the vertical capped cylinders (side quadric + two cap disks)."""
    n = len(o)
    if len(pk.cyl_c) == 0:
        return Hit.miss(n, o.device)
    lo = o[:, None, :] - pk.cyl_c[None]  # [N, C, 3]
    rad, hh = pk.cyl_rh[None, :, 0], pk.cyl_rh[None, :, 1]  # [1, C]
    dx, dy, dz = d[:, None, 0], d[:, None, 1], d[:, None, 2]
    a = (dx * dx + dz * dz).expand_as(lo[..., 0])
    b = lo[..., 0] * dx + lo[..., 2] * dz
    c = lo[..., 0] ** 2 + lo[..., 2] ** 2 - rad * rad
    disc = b * b - a * c
    sq = disc.clamp_min(0.0).sqrt()
    a_safe = a.clamp_min(_TINY)
    cands = []
    for ts in ((-b - sq) / a_safe, (-b + sq) / a_safe):
        y = lo[..., 1] + ts * dy
        ok = (disc >= 0) & (a > _TINY) & (y.abs() <= hh) & (ts > EPS)
        cands.append(torch.where(ok, ts, INF))
    dy_safe = _nonzero(dy)
    for cap in (-1.0, 1.0):
        tc = (cap * hh - lo[..., 1]) / dy_safe
        x, z = lo[..., 0] + tc * dx, lo[..., 2] + tc * dz
        ok = (x * x + z * z <= rad * rad) & (tc > EPS)
        cands.append(torch.where(ok, tc, INF))
    t_all = torch.stack(cands, -1)  # [N, C, 4]
    t, which = t_all.min(-1)
    tbest, idx = t.min(1)
    rows = torch.arange(n, device=o.device)
    kind = which[rows, idx]  # 0, 1 side; 2, 3 caps
    q = lo[rows, idx] + tbest[:, None] * d
    r = pk.cyl_rh[idx, 0]
    side = kind < 2
    radial = torch.stack([q[:, 0], torch.zeros_like(q[:, 0]), q[:, 2]], 1) / r[:, None]
    cap_n = torch.stack([torch.zeros_like(r), torch.where(kind == 2, -1.0, 1.0), torch.zeros_like(r)], 1)
    normal = torch.where(side[:, None], radial, cap_n)
    uv = torch.where(side[:, None], torch.stack([torch.atan2(q[:, 0], q[:, 2]) * r, q[:, 1]], 1), q[:, [0, 2]])
    hit = torch.isfinite(tbest)
    return Hit(tbest, normal, torch.where(hit, pk.cyl_m[idx], -1), q + pk.cyl_c[idx], uv)


def hit_room(scene: Scene, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Exit point of rays starting inside the room (walls, floor, ceiling); rays from outside miss."""
    room = scene.room
    n = len(o)
    hit = Hit.miss(n, o.device)
    if room is None:
        return hit
    dy = _nonzero(d[:, 1])
    down = dy > 0
    ty = torch.where(down, (room.floor_y - o[:, 1]) / dy, (room.ceiling_y - o[:, 1]) / dy)  # [N]
    ty_in = torch.where(down, (room.ceiling_y - o[:, 1]) / dy, (room.floor_y - o[:, 1]) / dy)
    if room.shape == "round":
        a = (d[:, 0] ** 2 + d[:, 2] ** 2).clamp_min(_TINY)
        b = o[:, 0] * d[:, 0] + o[:, 2] * d[:, 2]
        c = o[:, 0] ** 2 + o[:, 2] ** 2 - room.radius**2
        disc = b * b - a * c
        tw = torch.where((disc >= 0) & (c <= 0), (-b + disc.clamp_min(0).sqrt()) / a, -INF)
        inside = (c <= 0) & (ty_in <= 0)
        t_exit = torch.minimum(tw, ty)
        face = torch.where(ty < tw, 1, 3)  # 1 = floor/ceiling, 3 = round wall
    else:
        t_exit, face, inside = _box_union_exit(room.boxes, o, d, ty, ty_in)
    t_exit = torch.where(inside & (t_exit > 0), t_exit, INF)
    p = o + t_exit[:, None].clamp_max(1e6) * d
    zeros = torch.zeros_like(t_exit)
    ones = torch.ones_like(t_exit)
    if room.shape == "round":
        wall_n = -torch.stack([p[:, 0], zeros, p[:, 2]], 1) / room.radius
        wall_uv = torch.stack([torch.atan2(p[:, 0], p[:, 2]) * room.radius, p[:, 1]], 1)
    else:
        sx, sz = -torch.sign(_nonzero(d[:, 0])), -torch.sign(_nonzero(d[:, 2]))
        wall_n = torch.where(
            (face == 0)[:, None], torch.stack([sx, zeros, zeros], 1), torch.stack([zeros, zeros, sz], 1)
        )
        wall_uv = torch.where((face == 0)[:, None], p[:, [2, 1]], p[:, [0, 1]])
    floor = down
    flat_n = torch.stack([zeros, torch.where(floor, -ones, ones), zeros], 1)
    is_flat = face == 1
    normal = torch.where(is_flat[:, None], flat_n, wall_n)
    uv = torch.where(is_flat[:, None], p[:, [0, 2]], wall_uv)
    mat = torch.where(is_flat, torch.where(floor, room.floor_material, room.ceiling_material), room.wall_material)
    mat = torch.where(torch.isfinite(t_exit), mat, -1)
    return Hit(t_exit, normal, mat, p, uv)


def _box_union_exit(
    boxes: list[list[float]], o: torch.Tensor, d: torch.Tensor, ty: torch.Tensor, ty_in: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Exit distance [N], exit face [N] (0 = x wall, 1 = floor/ceiling, 2 = z wall) and inside-mask [N]
    of rays through the union of vertical boxes ``[xmin, xmax, zmin, zmax]`` sharing floor and ceiling."""
    dx, dz = _nonzero(d[:, 0]), _nonzero(d[:, 2])
    spans = []
    for xmin, xmax, zmin, zmax in boxes:
        tx = torch.where(dx > 0, (xmax - o[:, 0]) / dx, (xmin - o[:, 0]) / dx)
        tz = torch.where(dz > 0, (zmax - o[:, 2]) / dz, (zmin - o[:, 2]) / dz)
        tx_in = torch.where(dx > 0, (xmin - o[:, 0]) / dx, (xmax - o[:, 0]) / dx)
        tz_in = torch.where(dz > 0, (zmin - o[:, 2]) / dz, (zmax - o[:, 2]) / dz)
        t_out = torch.minimum(torch.minimum(tx, tz), ty)
        face = torch.where(ty <= torch.minimum(tx, tz), 1, torch.where(tx < tz, 0, 2))
        t_in = torch.maximum(torch.maximum(tx_in, tz_in), ty_in)
        spans.append((t_in, t_out, face))
    exit_t = torch.full_like(ty, -INF)
    exit_f = torch.ones_like(ty, dtype=torch.int64)
    for t_in, t_out, face in spans:  # boxes holding the origin
        start = (t_in <= 0) & (t_out >= 0) & (t_out > exit_t)
        exit_t, exit_f = torch.where(start, t_out, exit_t), torch.where(start, face, exit_f)
    inside = torch.isfinite(exit_t)
    for _ in range(len(spans)):  # chain overlapping boxes
        for t_in, t_out, face in spans:
            go = inside & (t_in <= exit_t + 1e-6) & (t_out > exit_t) & (t_in <= t_out)
            exit_t, exit_f = torch.where(go, t_out, exit_t), torch.where(go, face, exit_f)
    return exit_t, exit_f, inside


def hit_ground(scene: Scene, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Ground plane y = height within its disk; water disks swap the material."""
    g = scene.ground
    n = len(o)
    if g is None:
        return Hit.miss(n, o.device)
    t = (g.height - o[:, 1]) / _nonzero(d[:, 1])
    p = o + t.clamp(0, 1e6)[:, None] * d
    r2 = p[:, 0] ** 2 + p[:, 2] ** 2
    ok = (t > EPS) & (r2 <= g.radius**2)
    t = torch.where(ok, t, INF)
    mat = torch.full((n,), g.material, dtype=torch.int64, device=o.device)
    for cx, cz, r in g.water:
        wet = (p[:, 0] - cx) ** 2 + (p[:, 2] - cz) ** 2 <= r * r
        mat = torch.where(wet, g.water_material, mat)
    normal = torch.zeros_like(p)
    normal[:, 1] = -1.0
    return Hit(t, normal, torch.where(ok, mat, -1), p, p[:, [0, 2]])


def nearest(scene: Scene, pk: Packed, o: torch.Tensor, d: torch.Tensor) -> Hit:
    """Nearest hit over every part of the scene."""
    hit = hit_room(scene, o, d).merge(hit_ground(scene, o, d))
    for fn in (hit_boxes, hit_ellipsoids, hit_cylinders):
        hit = hit.merge(fn(pk, o, d))
    return hit


def occluded(pk: Packed, o: torch.Tensor, d: torch.Tensor, max_t: torch.Tensor | float = INF) -> torch.Tensor:
    """[N] bool: does a primitive (not the room or ground) block the ray before ``max_t``?"""
    blocked = torch.zeros(len(o), dtype=torch.bool, device=o.device)
    for fn in (hit_boxes, hit_ellipsoids, hit_cylinders):
        blocked |= fn(pk, o, d).t < max_t
    return blocked
