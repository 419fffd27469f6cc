"""Shading: sky radiance, Lambertian lighting, water reflections, fog; and ``cast``, the one ray caster.

All colours are linear light. Lighting terms come only from what the Scene holds: an ambient sky term
(always), the sun / moon (outdoors), point lights (``effects.lights``), shadow rays (``effects.shadows``)
and exponential fog (``effects.fog > 0``).
"""

from __future__ import annotations

import math

import torch

from holoflow.scene import textures
from holoflow.scene.intersect import Packed, cull, nearest, occluded, pack
from holoflow.scene.model import Scene, Sky

LAMP_SOFT = 0.5  # metres: point-light falloff 1 / (d^2 + LAMP_SOFT^2), no blow-up next to a lamp
CHUNK = 1 << 13  # rays per batch on CPU: memory ~ CHUNK * primitives * 100 bytes; small enough to cull well
CHUNK_CUDA = 1 << 17


def _vec(v, device) -> torch.Tensor:
    return torch.tensor(v, dtype=torch.float32, device=device)


def sky_radiance(sky: Sky, d: torch.Tensor, seed: int = 0) -> torch.Tensor:
    """Radiance [N, 3] of the sky seen along unit directions d [N, 3] (+y is down)."""
    dev = d.device
    el = -d[:, 1]  # sine of elevation
    zen, hor = _vec(sky.zenith, dev), _vec(sky.horizon, dev)
    up = el.clamp(0.0, 1.0)
    col = hor + (zen - hor) * up.sqrt()[:, None]
    col = torch.where((el < 0)[:, None], hor * 0.8, col)
    if sky.clouds > 0:
        plane = d[:, [0, 2]] / (up + 0.08)[:, None] * 1.2  # clouds on a high flat layer
        p = torch.cat([plane, torch.zeros_like(plane[:, :1])], 1)
        f = textures.fbm(p, seed + 911, 5)
        cover = textures.smoothstep(1.0 - sky.clouds, 1.25 - sky.clouds, f) * textures.smoothstep(0.0, 0.08, el)
        cloud = hor * 1.05 + _vec(sky.sun_color, dev) * 0.05
        col = col + (cloud - col) * (0.9 * cover)[:, None]
    if sky.stars:
        cells = torch.floor(d * 350.0)
        h = textures.cell_hash(cells, seed + 7)
        star = (h > 0.996).float() * (h - 0.996) * 150.0 * (el > 0.02).float()
        col = col + star[:, None] * 0.6
    sun = _vec(sky.sun_dir, dev)
    cosang = (d * sun).sum(1)
    disk = textures.smoothstep(math.cos(sky.sun_size * 1.3), math.cos(sky.sun_size), cosang)
    halo = cosang.clamp_min(0.0) ** 48
    col = col + _vec(sky.sun_color, dev) * (disk * 8.0 + halo * 0.15)[:, None]
    return col


def _albedo(
    scene: Scene, material: torch.Tensor, pos: torch.Tensor, uv: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Albedo [M, 3] and emitted radiance [M, 3] of hits with material indices [M]."""
    alb = torch.zeros_like(pos)
    emit = torch.zeros_like(pos)
    for m, mat in enumerate(scene.materials):
        sel = (material == m).nonzero().squeeze(1)
        if len(sel) == 0:
            continue
        c, c2 = _vec(mat.color, pos.device), _vec(mat.color2, pos.device)
        a, w = textures.albedo(mat.kind, c, c2, mat.scale, mat.seed, pos[sel], uv[sel])
        alb[sel] = a
        if mat.emission > 0:
            emit[sel] = a * (mat.emission * w)[:, None]
    return alb, emit


def _shade(
    scene: Scene, pk: Packed, full: Packed, o: torch.Tensor, d: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Colour [N, 3] and hit distance [N] of one batch of rays; ``pk`` holds the primitives these rays
    can hit, ``full`` all of them (for shadow rays)."""
    dev = o.device
    hit = nearest(scene, pk, o, d)
    rgb = sky_radiance(scene.sky, d, scene.seed)
    idx = (hit.material >= 0).nonzero().squeeze(1)
    if len(idx):
        dh = d[idx]
        t = hit.t[idx]
        p = o[idx] + t[:, None] * dh  # [M, 3] world hit points
        n = hit.normal[idx]
        n = torch.where(((n * dh).sum(1) > 0)[:, None], -n, n)  # face the viewer
        mat = hit.material[idx]
        alb, emit = _albedo(scene, mat, hit.pos[idx], hit.uv[idx])
        light = _vec(scene.ambient, dev) * (0.85 - 0.15 * n[:, 1])[:, None]  # a little brighter from above
        key = _vec(scene.key_light, dev)
        light = light + _vec(scene.ambient, dev) * (0.8 * (n * key).sum(1).clamp_min(0.0))[:, None]
        sun_rad = _vec(scene.sun_light, dev)
        if bool((sun_rad > 0).any()):
            sdir = _vec(scene.sky.sun_dir, dev)
            ndl = (n * sdir).sum(1).clamp_min(0.0)
            if scene.effects.shadows:
                lit = (ndl > 0).nonzero().squeeze(1)
                so, sd = p[lit] + n[lit] * 2e-3, sdir.expand(len(lit), 3)
                blocked = occluded(cull(full, so, sd), so, sd) if len(lit) else lit.bool()
                ndl[lit[blocked]] = 0.0
            light = light + sun_rad * ndl[:, None]
        if scene.effects.lights:
            for lamp in scene.lights:
                to = _vec(lamp.position, dev) - p
                dist2 = (to * to).sum(1)
                ndl = (n * to).sum(1).clamp_min(0.0) / dist2.clamp_min(1e-8).sqrt()
                light = light + _vec(lamp.intensity, dev) * (ndl / (dist2 + LAMP_SOFT**2))[:, None]
        col = alb * light + emit
        water = torch.tensor(
            [scene.materials[int(m)].kind == "water" for m in range(len(scene.materials))], device=dev
        )[mat]
        if bool(water.any()):
            col[water] = _water(scene, p[water], dh[water], col[water])
        rgb[idx] = col
    if scene.effects.fog > 0:
        fog = _vec(scene.effects.fog_color, dev)
        trans = torch.exp(-scene.effects.fog * hit.t.clamp_max(1e6))  # 0 for sky
        sky_w = torch.exp(-(-d[:, 1]).clamp_min(0.0) / 0.3)  # sky fades to fog at the horizon
        trans = torch.where(torch.isfinite(hit.t), trans, 1.0 - sky_w)
        rgb = rgb * trans[:, None] + fog * (1.0 - trans)[:, None]
    return rgb, hit.t


def _water(scene: Scene, p: torch.Tensor, d: torch.Tensor, col: torch.Tensor) -> torch.Tensor:
    """Water hits p, d, col [M, 3]: Fresnel blend of the lit water colour with the sky reflected about
    a rippled normal."""
    q = p * torch.tensor([1.3, 0.0, 0.5], device=p.device)
    nx = textures.fbm(q, scene.seed + 31, 3) - 0.5
    nz = textures.fbm(q + 5.3, scene.seed + 37, 3) - 0.5
    n = torch.nn.functional.normalize(torch.stack([0.12 * nx, -torch.ones_like(nx), 0.12 * nz], 1), dim=1)
    cos = (-(d * n).sum(1)).clamp(0.0, 1.0)
    fresnel = 0.02 + 0.98 * (1.0 - cos) ** 5
    r = d - 2.0 * (d * n).sum(1, keepdim=True) * n
    r = torch.cat([r[:, :1], r[:, 1:2].clamp_max(-0.01), r[:, 2:]], 1)  # reflect above the horizon
    refl = sky_radiance(scene.sky, torch.nn.functional.normalize(r, dim=1), scene.seed)
    return col * (1.0 - fresnel)[:, None] + refl * fresnel[:, None]


def coherent_order(dirs: torch.Tensor, chunk: int) -> torch.Tensor:
    """Permutation [N] grouping rays by direction (latitude-major bins of about chunk/2 rays), so that
    each chunk of the permuted rays spans a narrow cone and culling removes most primitives."""
    n = len(dirs)
    bins = max(1, n // max(1, chunk // 2))
    n_lat = max(1, int(math.sqrt(bins / 2)))
    n_lon = 2 * n_lat
    lat = torch.arcsin((-dirs[:, 1]).clamp(-1.0, 1.0))
    lon = torch.atan2(dirs[:, 0], dirs[:, 2])
    i = ((lat / math.pi + 0.5) * n_lat).long().clamp(0, n_lat - 1)
    j = ((lon / (2 * math.pi) + 0.5) * n_lon).long().clamp(0, n_lon - 1)
    return torch.sort(i * n_lon + j, stable=True).indices


def _batches(scene: Scene, origins: torch.Tensor, dirs: torch.Tensor, chunk: int):
    """Yield (ray indices, culled primitives, all primitives) per direction-coherent chunk of rays."""
    pk = pack(scene, origins.device)
    order = coherent_order(dirs, chunk)
    for s in range(0, len(order), chunk):
        idx = order[s : s + chunk]
        yield idx, cull(pk, origins[idx], dirs[idx]), pk


def cast(
    scene: Scene, origins: torch.Tensor, dirs: torch.Tensor, chunk: int | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Trace rays through the scene: origins [N, 3] (m), unit directions [N, 3], world frame.

    Returns linear RGB [N, 3] float32 and hit distance t [N] along the ray in metres (+inf = sky or
    nothing). Rays are traced in direction-coherent chunks (``chunk`` rays; default by device) with
    per-chunk culling; element-wise arithmetic only, so results are deterministic and independent of
    the chunking. Runs on the rays' device.
    """
    chunk = chunk or (CHUNK_CUDA if origins.is_cuda else CHUNK)
    origins = origins.to(torch.float32)
    dirs = torch.nn.functional.normalize(dirs.to(torch.float32), dim=-1)
    rgb = torch.empty_like(origins)
    t = torch.empty_like(origins[:, 0])
    with torch.no_grad():
        for idx, pk, full in _batches(scene, origins, dirs, chunk):
            rgb[idx], t[idx] = _shade(scene, pk, full, origins[idx], dirs[idx])
    return rgb, t
