"""Procedural textures in torch: hash noise, fBm and one albedo pattern per material kind.

Every function is pure and deterministic (integer hashing, no global RNG). Patterns are evaluated at
surface points in the object's frame: ``pos`` [N, 3] (metres, solid noise) and ``uv`` [N, 2] (metres in
the surface plane, for planks, bricks, tiles, windows). Albedos are linear light in [0, 1].
"""

from __future__ import annotations

import functools

import torch

_M32 = 0xFFFFFFFF


def hash3(ix: torch.Tensor, iy: torch.Tensor, iz: torch.Tensor, seed: int) -> torch.Tensor:
    """Integer lattice hash -> float in [0, 1). Inputs int64 tensors of one shape."""
    h = (ix * 0x8DA6B343) ^ (iy * 0xD8163841) ^ (iz * 0xCB1AB31F) ^ ((seed * 0x165667B1 + 0x27D4EB2F) & _M32)
    h = h & _M32
    h = h ^ (h >> 15)
    h = (h * 0x2C1B3C6D) & _M32
    h = h ^ (h >> 12)
    h = (h * 0x297A2D39) & _M32
    h = h ^ (h >> 15)
    return (h & 0xFFFFFF).to(torch.float32) / 16777216.0


def cell_hash(cells: torch.Tensor, seed: int) -> torch.Tensor:
    """Hash of integer cells [N, 2] or [N, 3] (float tensor of whole numbers) -> [N] in [0, 1)."""
    c = cells.to(torch.int64)
    z = c[:, 2] if c.shape[1] > 2 else torch.zeros_like(c[:, 0])
    return hash3(c[:, 0], c[:, 1], z, seed)


_PERIOD = 64  # lattice period of the noise table (cells)


@functools.lru_cache(maxsize=1)
def _noise_table() -> torch.Tensor:
    """Random lattice values [1, 1, P+1, P+1, P+1], periodic (the last slice repeats the first)."""
    g = torch.Generator().manual_seed(20240613)
    tab = torch.rand(1, 1, _PERIOD, _PERIOD, _PERIOD, generator=g)
    return torch.nn.functional.pad(tab, (0, 1, 0, 1, 0, 1), mode="circular")


@functools.lru_cache(maxsize=4096)
def _shift(seed: int) -> tuple[float, float, float]:
    """Offset (in cells) of seed's window into the noise table: a plain-integer hash of the seed."""
    out = []
    for k in range(3):
        h = (seed * 0x9E3779B1 + k * 0x85EBCA77 + 0x165667B1) & _M32
        h = ((h ^ (h >> 15)) * 0x2C1B3C6D) & _M32
        h = ((h ^ (h >> 13)) * 0x297A2D39) & _M32
        out.append(((h ^ (h >> 16)) & 0xFFFF) / 65536.0 * _PERIOD)
    return tuple(out)


def value_noise(p: torch.Tensor, seed: int) -> torch.Tensor:
    """Smooth 3D value noise of points [N, 3] (lattice spacing 1) -> [N] in [0, 1].

    Lattice values come from one fixed periodic table (period 64 cells); ``seed`` shifts the lookup so
    different seeds give uncorrelated noise. Smoothstep weights are applied by warping the fractional
    coordinate, so trilinear ``grid_sample`` yields C1 value noise in one fused op.
    """
    q = p + torch.tensor(_shift(seed), dtype=p.dtype, device=p.device)
    f = torch.floor(q)
    w = q - f
    q = torch.remainder(f, _PERIOD) + w * w * (3.0 - 2.0 * w)  # [N, 3] in [0, P]
    grid = (q * (2.0 / _PERIOD) - 1.0).reshape(1, 1, 1, -1, 3)
    table = _noise_table().to(device=p.device, dtype=p.dtype)
    out = torch.nn.functional.grid_sample(table, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out.reshape(-1)


def fbm(p: torch.Tensor, seed: int, octaves: int = 4) -> torch.Tensor:
    """Fractal sum of value noise (lacunarity 2, gain 0.5), normalised to [0, 1]. ``p`` [N, 3]."""
    total = torch.zeros_like(p[:, 0])
    amp, norm = 1.0, 0.0
    q = p
    for o in range(octaves):
        total = total + amp * value_noise(q, seed + 101 * o)
        norm += amp
        amp *= 0.5
        q = q * 2.03 + 17.1
    return total / norm


def _mix(a: torch.Tensor, b: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Blend colours a, b ([3] or [N, 3]) with weights t [N] -> [N, 3]."""
    return a + (b - a) * t[:, None]


def _frac(x: torch.Tensor) -> torch.Tensor:
    return x - torch.floor(x)


def smoothstep(e0: float, e1: float, x: torch.Tensor) -> torch.Tensor:
    t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def albedo(
    kind: str, color: torch.Tensor, color2: torch.Tensor, scale: float, seed: int, pos: torch.Tensor, uv: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Albedo [N, 3] and emission weight [N] (0..1, multiplies the material's emission) of ``kind``."""
    fn = _PATTERNS.get(kind)
    if fn is None:
        raise ValueError(f"unknown material kind {kind!r}; known: {sorted(_PATTERNS)}")
    out = fn(color, color2, scale, seed, pos, uv)
    if isinstance(out, tuple):
        return out[0].clamp(0.0, 1.0), out[1]
    return out.clamp(0.0, 1.0), torch.ones_like(pos[:, 0])


def _plain(c, c2, s, seed, pos, uv):
    return c * (0.93 + 0.14 * fbm(pos * (4.0 / s), seed, 3))[:, None]


def _wood(c, c2, s, seed, pos, uv):
    u, v = uv[:, 0] / s, uv[:, 1]  # u across planks, v along them
    row = torch.floor(u)
    length = 6.0 * s
    off = hash3(row.long(), torch.zeros_like(row.long()), torch.zeros_like(row.long()), seed) * length
    col = torch.floor((v + off) / length)
    tint = cell_hash(torch.stack([row, col], 1), seed + 1)
    grain = fbm(torch.stack([uv[:, 0] * 60.0, uv[:, 1] * 3.0, row * 7.0], 1), seed + 2, 3)
    rings = 0.5 + 0.5 * torch.sin(uv[:, 0] * 180.0 + grain * 12.0 + tint * 20.0)
    base = _mix(c, c2, (0.45 * rings + 0.55 * tint) * 0.8)
    fu = _frac(u) * s
    fv = _frac((v + off) / length) * length
    gap = torch.minimum(torch.minimum(fu, s - fu), torch.minimum(fv, length - fv))
    return base * (0.55 + 0.45 * smoothstep(0.0, 0.004, gap))[:, None]


def _brick(c, c2, s, seed, pos, uv):
    bw, bh, mortar = s, s * 0.32, 0.012
    row = torch.floor(uv[:, 1] / bh)
    u = uv[:, 0] + torch.remainder(row, 2.0) * bw * 0.5
    col = torch.floor(u / bw)
    tint = cell_hash(torch.stack([row, col], 1), seed)
    rough = fbm(pos * (25.0 / s), seed + 3, 3)
    brick = c * ((0.7 + 0.55 * tint) * (0.8 + 0.35 * rough))[:, None]
    fu, fv = _frac(u / bw) * bw, _frac(uv[:, 1] / bh) * bh
    edge = torch.minimum(torch.minimum(fu, bw - fu), torch.minimum(fv, bh - fv))
    mortar_col = c2 * (0.85 + 0.3 * rough)[:, None]
    return _mix(mortar_col, brick, smoothstep(mortar * 0.4, mortar, edge))


def _tiles(c, c2, s, seed, pos, uv):
    cells = torch.floor(uv / s)
    tint = cell_hash(cells, seed)
    f = _frac(uv / s) * s
    edge = torch.minimum(f, s - f).min(dim=1).values
    tile = c * (0.9 + 0.15 * tint + 0.05 * value_noise(pos * (40.0 / s), seed + 1))[:, None]
    return _mix(c2, tile, smoothstep(0.002, 0.004, edge))


def _plaster(c, c2, s, seed, pos, uv):
    k = 0.88 + 0.18 * fbm(pos * (3.0 / s), seed, 4) + 0.05 * value_noise(pos * 60.0, seed + 1)
    return c * k[:, None]


def _concrete(c, c2, s, seed, pos, uv):
    k = 0.78 + 0.3 * fbm(pos * (2.5 / s), seed, 4)
    pores = (hash3(*(torch.floor(pos * 150.0).long().unbind(1)), seed + 5) > 0.985).float()
    size = torch.tensor([2.4 * s, 1.2 * s], device=pos.device)  # formwork panels
    panel = _frac(uv / size) * size
    seam = torch.minimum(panel, size - panel).min(dim=1).values
    k = k * (1.0 - 0.45 * pores) * (0.75 + 0.25 * smoothstep(0.0, 0.006, seam))
    return _mix(c, c2, 0.25 * fbm(pos * 0.7, seed + 9, 2)) * k[:, None]


def _marble(c, c2, s, seed, pos, uv):
    warp = fbm(pos * (1.8 / s), seed, 5)
    band = torch.sin((pos[:, 0] + 0.6 * pos[:, 1] + 0.8 * pos[:, 2]) * (4.0 / s) + warp * 9.0)
    vein = 0.35 + 0.65 * smoothstep(0.0, 0.12, band.abs())  # thin veins
    base = c * (0.92 + 0.1 * value_noise(pos * (12.0 / s), seed + 2))[:, None]
    return _mix(c2, base, vein)


def _stone(c, c2, s, seed, pos, uv):
    bh = s * 0.5
    row = torch.floor(uv[:, 1] / bh)
    width = s * (0.8 + 0.6 * hash3(row.long(), row.long() * 0, row.long() * 0, seed))
    u = uv[:, 0] + hash3(row.long(), row.long() * 0 + 1, row.long() * 0, seed) * s
    col = torch.floor(u / width)
    tint = cell_hash(torch.stack([row, col], 1), seed + 1)
    rough = fbm(pos * (8.0 / s), seed + 2, 4)
    block = _mix(c, c2, 0.6 * tint) * (0.7 + 0.45 * rough)[:, None]
    fu, fv = _frac(u / width) * width, _frac(uv[:, 1] / bh) * bh
    edge = torch.minimum(torch.minimum(fu, width - fu), torch.minimum(fv, bh - fv))
    return block * (0.35 + 0.65 * smoothstep(0.004, 0.02, edge))[:, None]


def _carpet(c, c2, s, seed, pos, uv):
    k = (0.8 + 0.35 * value_noise(pos * 180.0, seed)) * (0.88 + 0.2 * fbm(pos * 1.5, seed + 1, 3))
    border = torch.minimum(_frac(uv[:, 0] / (4 * s)), _frac(uv[:, 1] / (4 * s)))
    return _mix(c, c2, (border < 0.06).float() * 0.7) * k[:, None]


def _fabric(c, c2, s, seed, pos, uv):
    k = (0.85 + 0.2 * value_noise(pos * 70.0, seed)) * (0.9 + 0.15 * fbm(pos * 3.0, seed + 1, 3))
    return c * k[:, None]


def _leather(c, c2, s, seed, pos, uv):
    return _mix(c, c2, 0.3 * fbm(pos * 2.0, seed, 3)) * (0.85 + 0.25 * fbm(pos * 35.0, seed + 1, 3))[:, None]


def _metal(c, c2, s, seed, pos, uv):
    brushed = value_noise(pos * torch.tensor([3.0, 90.0, 3.0], device=pos.device), seed)
    return c * (0.88 + 0.15 * brushed)[:, None]


def _grass(c, c2, s, seed, pos, uv):
    patches = fbm(pos * (0.25 / s), seed, 4)
    blades = value_noise(pos * (9.0 / s), seed + 1)
    return _mix(c, c2, smoothstep(0.3, 0.7, patches)) * (0.7 + 0.5 * blades)[:, None]


def _sand(c, c2, s, seed, pos, uv):
    warp = fbm(pos * 0.3, seed, 3)
    ripple = 0.5 + 0.5 * torch.sin(pos[:, 0] * (5.0 / s) + pos[:, 2] * (1.5 / s) + warp * 10.0)
    grain = value_noise(pos * 60.0, seed + 1)
    return _mix(c, c2, 0.35 * ripple + 0.3 * warp) * (0.92 + 0.12 * grain)[:, None]


def _rock(c, c2, s, seed, pos, uv):
    t = fbm(pos * (1.2 / s), seed, 5)
    strata = 0.5 + 0.5 * torch.sin(pos[:, 1] * (9.0 / s) + t * 6.0)
    return _mix(c, c2, 0.6 * t + 0.25 * strata) * (0.7 + 0.45 * value_noise(pos * (10.0 / s), seed + 2))[:, None]


def _snow(c, c2, s, seed, pos, uv):
    return _mix(c, c2, 0.3 * fbm(pos * (0.5 / s), seed, 4)) * (0.95 + 0.05 * value_noise(pos * 30.0, seed))[:, None]


def _asphalt(c, c2, s, seed, pos, uv):
    k = (0.75 + 0.45 * value_noise(pos * 70.0, seed)) * (0.85 + 0.25 * fbm(pos * 0.4, seed + 1, 3))
    patches = smoothstep(0.55, 0.75, fbm(pos * 0.15, seed + 2, 3))  # repaired patches
    return _mix(c * k[:, None], c2, 0.15 * patches)


def _leaves(c, c2, s, seed, pos, uv):
    clumps = value_noise(pos * (3.0 / s), seed)
    speck = value_noise(pos * (14.0 / s), seed + 1)
    return _mix(c, c2, clumps) * (0.6 + 0.6 * speck)[:, None]


def _bark(c, c2, s, seed, pos, uv):
    k = 0.6 + 0.6 * value_noise(pos * torch.tensor([40.0, 2.5, 40.0], device=pos.device), seed)
    return _mix(c, c2, fbm(pos * 4.0, seed + 1, 2)) * k[:, None]


def _facade(c, c2, s, seed, pos, uv):
    """Building wall with a window grid (storey ``s`` metres); the windows carry the emission."""
    bay, storey = 0.8 * s, s
    fu, fv = _frac(uv[:, 0] / bay), _frac(uv[:, 1] / storey)
    cell = torch.stack([torch.floor(uv[:, 0] / bay), torch.floor(uv[:, 1] / storey)], 1)
    window = ((fu > 0.25) & (fu < 0.75) & (fv > 0.25) & (fv < 0.7)).float()
    lit = (cell_hash(cell, seed + 4) > 0.45).float()
    wall = c * (0.8 + 0.3 * fbm(pos * 1.5, seed, 3))[:, None]
    glass = c2 * (0.7 + 0.6 * cell_hash(cell, seed + 3))[:, None]
    return _mix(wall, glass, window), window * lit


def _books(c, c2, s, seed, pos, uv):
    """Bookshelf front: boards every ``s`` metres in v, books of random width, colour and height."""
    fv = _frac(uv[:, 1] / s)
    slot = torch.floor(uv[:, 1] / s)
    width = 0.03
    col = torch.floor(uv[:, 0] / width)
    h = cell_hash(torch.stack([col, slot], 1), seed)
    hue = torch.stack(
        [h, cell_hash(torch.stack([col, slot], 1), seed + 1), cell_hash(torch.stack([col, slot], 1), seed + 2)], 1
    )
    book = 0.05 + 0.5 * hue * hue
    top = 0.08 + 0.12 * h  # gap above the book
    board = (fv > 0.92).float()
    gap = (fv < top).float() * (1.0 - board)
    out = _mix(book, c2 * 0.25, gap)
    return _mix(out, c.expand_as(out), board)


def _painting(c, c2, s, seed, pos, uv):
    p = pos * (2.0 / s)
    rgb = torch.stack([fbm(p, seed, 3), fbm(p, seed + 7, 3), fbm(p, seed + 13, 3)], 1)
    return _mix(c2.expand_as(rgb), (rgb - 0.5) * 2.5 + 0.5, torch.ones_like(p[:, 0]) * 0.85)


def _window(c, c2, s, seed, pos, uv):
    """Glazing with mullions every ``s`` metres: panes emit, the frame does not."""
    f = _frac(uv / s) * s
    edge = torch.minimum(f, s - f).min(dim=1).values
    pane = (edge > 0.025).float()
    return _mix(c2.expand(len(pos), 3), c, pane), pane


def _glow(c, c2, s, seed, pos, uv):
    return c.expand(len(pos), 3).clone()


def _water(c, c2, s, seed, pos, uv):
    return _mix(c, c2, fbm(pos * (0.2 / s), seed, 3))


_PATTERNS = {
    "plain": _plain,
    "wood": _wood,
    "brick": _brick,
    "tiles": _tiles,
    "plaster": _plaster,
    "concrete": _concrete,
    "marble": _marble,
    "stone": _stone,
    "carpet": _carpet,
    "fabric": _fabric,
    "leather": _leather,
    "metal": _metal,
    "grass": _grass,
    "sand": _sand,
    "rock": _rock,
    "snow": _snow,
    "asphalt": _asphalt,
    "leaves": _leaves,
    "bark": _bark,
    "facade": _facade,
    "books": _books,
    "painting": _painting,
    "window": _window,
    "glow": _glow,
    "water": _water,
}
