"""Surfaces of an equirect depth map: edge-aware depth smoothing and per-pixel surface normals.

A panorama's depth says where each pixel's surface is; how that surface is turned decides how its
Gaussian must lie so that neighbours still overlap when seen from another eye (a disc facing the
panorama centre on a wall seen at 70 deg incidence turns into a sliver seen from 0.5 m away).

``smooth_depth``: a depth network draws each surface with per-pixel noise of a few percent; as points,
neighbours then sit in front of and behind each other, and an eye off the centre sees the cracks
between them. The filter averages log depth over a (2 radius + 1)^2 window with weights
exp(-(delta log depth / range)^2 / 2) (a bilateral filter in log depth, columns wrapping at the seam,
rows clamped at the poles): within a surface (neighbours within ``range`` relative) noise averages out,
across an occlusion edge (a step of several ``range``) nothing mixes. ``range`` follows the depth's own
noise (``depth_noise``): exact depth, whose only "noise" is the curvature of log depth over a plane,
is left nearly unchanged (smoothing it would bend its creases), a network's is averaged. A network's
depth that metric_align laid on the room's planes says what its noise was before (the EXR header's
``holoflow.depth_noise``): measured after, the exact planes (most of a room) hide the noise left on
everything off them.

``surface_normals``: the normal of each pixel's surface from the 3D points of its neighbours: along
each image axis the one-sided difference towards the neighbour on the same surface (the smaller
relative depth change, when below ``tol``; the mean of both when both are), summed over the window's
pixels of the same surface, crossed. Where an axis has
no neighbour on the same surface (a one-pixel-wide object, a lone pixel), the normal faces the centre.
Normals point towards the panorama centre (n . ray < 0).

Conventions: radial depth in metres, finite > 0 wherever a surface is (sky already on its far shell,
holoflow/geometry/pointcloud.py); NaN / inf / <= 0 = no surface (kept as is, normal facing the
centre); world frame and pixel centres of docs/conventions.md.
"""

from __future__ import annotations

import torch

from holoflow.geometry.sphere import equirect_directions


def _shift(x: torch.Tensor, dy: int, dx: int) -> torch.Tensor:
    """x [H, W, ...] read at (row + dy, column + dx): columns wrap, rows clamp."""
    H = x.shape[0]
    rows = torch.clamp(torch.arange(H, device=x.device) + dy, 0, H - 1)
    return torch.roll(x[rows], -dx, 1)


def _padded(x: torch.Tensor, r: int) -> torch.Tensor:
    """x [H, W, ...] with r rows clamped above and below and r columns wrapped on either side
    [H + 2r, W + 2r, ...]: ``_window(x_padded, r, dy, dx)`` is ``_shift(x, dy, dx)`` for |dy|, |dx| <= r,
    as a view (a window over a whole panorama reads no copy per offset)."""
    H, W = x.shape[:2]
    rows = torch.clamp(torch.arange(-r, H + r, device=x.device), 0, H - 1)
    cols = torch.arange(-r, W + r, device=x.device) % W  # wraps more than once on a panorama narrower than r
    return x[rows][:, cols]


def _window(xp: torch.Tensor, r: int, dy: int, dx: int) -> torch.Tensor:
    """The [H, W, ...] view of ``_padded(x, r)`` read at (row + dy, column + dx)."""
    H, W = xp.shape[0] - 2 * r, xp.shape[1] - 2 * r
    return xp[r + dy : r + dy + H, r + dx : r + dx + W]


def _residual(logd: torch.Tensor) -> torch.Tensor:
    """Log depth [H, W] less the mean of its four neighbours (``_shift``'s borders): [H, W]."""
    return logd - sum(_shift(logd, dy, dx) for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0))) / 4


def depth_noise(radial_depth: torch.Tensor, edge: float = 0.05) -> float:
    """Per-pixel noise of radial_depth [H, W] as a relative standard deviation: the median absolute
    difference between each pixel's log depth and the mean of its four neighbours (pixels with a surface,
    differences under ``edge``: no occlusion edge), scaled to a Gaussian's standard deviation. Exact
    depth of smooth surfaces scores its curvature (~1e-4 at P_f's sizes), a network's depth its noise."""
    d = radial_depth
    valid = torch.isfinite(d) & (d > 0)
    logd = torch.log(torch.where(valid, d, torch.ones_like(d)))
    ok = valid & _shift(valid, 0, 1) & _shift(valid, 0, -1) & _shift(valid, 1, 0) & _shift(valid, -1, 0)
    r = _residual(logd)[ok].abs()
    r = r[r < edge]
    return float(1.4826 * r.median() / 1.25**0.5) if r.numel() else 0.0


def smooth_depth(
    radial_depth: torch.Tensor,
    radius: int = 2,
    range_rel: float = 0.05,
    noise_factor: float = 0.0,
    noise: float | None = None,
) -> torch.Tensor:
    """Edge-aware smoothing of radial_depth [H, W] (metres; module docstring): [H, W], same dtype.
    radius (px): half window (0: unchanged); range_rel: relative depth difference at which a
    neighbour's weight falls to exp(-1/2); with noise_factor > 0 it is at most noise_factor x the
    depth's noise (relative standard deviation: ``noise`` when known, else ``depth_noise``), so exact
    depth is left nearly as it is and a network's noise is averaged out; with ``noise`` given, a pixel
    already within a tenth of it of its four neighbours' mean (laid on a plane) keeps its depth. Pixels
    without a surface are neither changed nor used."""
    if radius < 1:
        return radial_depth
    if noise_factor > 0:
        range_rel = min(range_rel, noise_factor * (depth_noise(radial_depth) if noise is None else noise))
        if range_rel <= 0:
            return radial_depth
    d = radial_depth
    valid = torch.isfinite(d) & (d > 0)
    logd = torch.log(torch.where(valid, d, torch.ones_like(d)))
    total = torch.zeros_like(logd)
    weight = torch.zeros_like(logd)
    inv = 1.0 / (2.0 * range_rel * range_rel)
    logd_p, valid_p = _padded(logd, radius), _padded(valid, radius)
    w, wn = torch.empty_like(logd), torch.empty_like(logd)  # reused: no large temporaries
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            n, ok = _window(logd_p, radius, dy, dx), _window(valid_p, radius, dy, dx)
            torch.sub(n, logd, out=w).pow_(2).mul_(-inv).exp_().mul_(ok)  # exp(-(delta / range)^2 / 2)
            total += torch.mul(w, n, out=wn)
            weight += w
    out = torch.exp(total / weight.clamp_min(1e-30))
    if noise is not None:  # what lies within a tenth of the noise of its neighbours was laid on a plane
        valid &= _residual(logd).abs() >= 0.1 * noise
    return torch.where(valid, out.to(d.dtype), d)


def surface_normals(radial_depth: torch.Tensor, tol: float = 0.1, radius: int = 2) -> torch.Tensor:
    """Unit normals [H, W, 3] (world, towards the centre) of radial_depth [H, W] (metres; module
    docstring). tol: relative depth change beyond which a neighbour lies on another surface; radius
    (px): the tangents are averaged over the (2 radius + 1)^2 window's pixels of the same surface (a
    least-squares plane: what noise is left in the depth tilts a one-pixel tangent by tens of degrees)."""
    H, W = radial_depth.shape
    d = radial_depth
    dirs = equirect_directions(H, W, device=d.device, dtype=d.dtype)  # [H, W, 3]
    valid = torch.isfinite(d) & (d > 0)
    safe = torch.where(valid, d, torch.ones_like(d))
    p = dirs * safe[..., None]  # [H, W, 3]

    def tangent(dy: int, dx: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Tangent [H, W, 3] along one image axis (per pixel step) and whether it is known [H, W]."""
        fwd, bwd = _shift(p, dy, dx) - p, p - _shift(p, -dy, -dx)  # [H, W, 3]
        rel_f = (_shift(safe, dy, dx) / safe).log().abs()
        rel_b = (_shift(safe, -dy, -dx) / safe).log().abs()
        ok_f = _shift(valid, dy, dx) & valid & (rel_f < tol)
        ok_b = _shift(valid, -dy, -dx) & valid & (rel_b < tol)
        if dy:  # the pole rows have no neighbour beyond them (clamped rows read the pixel itself)
            rows = torch.arange(H, device=d.device)[:, None]
            ok_f &= (rows + dy >= 0) & (rows + dy < H)
            ok_b &= (rows - dy >= 0) & (rows - dy < H)
        both = (ok_f & ok_b)[..., None]
        one = torch.where((ok_f & (~ok_b | (rel_f <= rel_b)))[..., None], fwd, bwd)
        return torch.where(both, 0.5 * (fwd + bwd), one), ok_f | ok_b

    t_u, ok_u = tangent(0, 1)  # east, one column
    t_v, ok_v = tangent(1, 0)  # south, one row
    if radius > 0:
        logd = safe.log()
        logd_p = _padded(logd, radius)
        known_p = _padded(torch.cat([t_u * ok_u[..., None], t_v * ok_v[..., None]], -1), radius)  # [., ., 6]
        sums = torch.zeros(H, W, 6, dtype=t_u.dtype, device=t_u.device)
        step, diff = torch.empty_like(sums), torch.empty_like(logd)  # reused: no large temporaries
        same = torch.empty(H, W, dtype=torch.bool, device=d.device)
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                torch.sub(_window(logd_p, radius, dy, dx), logd, out=diff)
                torch.lt(diff.abs_(), tol, out=same)
                sums += torch.mul(_window(known_p, radius, dy, dx), same[..., None], out=step)
        t_u, t_v = sums[..., :3], sums[..., 3:]
    n = torch.cross(t_u, t_v, dim=-1)
    norm = torch.linalg.vector_norm(n, dim=-1, keepdim=True)
    known = (ok_u & ok_v)[..., None] & (norm > 1e-12 * safe[..., None] ** 2)
    n = torch.where(known, n / norm.clamp_min(1e-30), -dirs)
    facing = (n * dirs).sum(-1, keepdim=True)
    return torch.where(facing > 0, -n, n)
