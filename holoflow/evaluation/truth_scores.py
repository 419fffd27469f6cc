"""A finished scene scored against a truth set (holoflow.evaluation.truth_set; docs/truth-sets.md): what a
viewer sees walking 0 / 0.25 / 0.5 / 1 m off the panorama centre.

The scene (``transfer_opt/scene.ply``) is rendered by holoflow's rasterizer at each truth view's
``viewmat`` and K, at the view's size, in sRGB (the space Gaussians are trained in, holoflow.recon.views),
colour clamped to [0, 1]. Per ring (cameras.json ``ring``):

- ``psnr``: PSNR over all the ring's pixels together (pooled squared error, sRGB); ``psnr_mean`` /
  ``ssim``: means of the per-view values;
- ``abs_rel`` / ``delta1``: the render's depth (alpha-composited camera z / alpha) against the views'
  Z over the pixels whose truth is finite and whose alpha >= ``empty_alpha``: mean |z - z*| / z* and
  the fraction with max(z / z*, z* / z) < 1.25; ``scale``: the median of z / z*, the scene's size against
  the truth's (a run whose metric depth is 3 % too large renders every surface 3 % too far, and an eye
  that steps 0.5 m walks through a room 3 % too big: it sees the walls slide); ``depth_coverage`` = the
  share of finite-truth pixels that had a rendered depth;
- ``empty``: fraction of pixels with alpha < ``empty_alpha`` (0.5); ``cracked``: alpha < ``crack_alpha``
  (0.9);
- ``edges``: the fraction of pixels within ``EDGE_REACH`` px of a depth edge of the truth view
  (``depth_edges``: a step of over ``EDGE_JUMP`` between neighbours, or the sky's border), ``psnr_edges``
  / ``psnr_surfaces`` over them and over the rest: a geometry a little off shifts what the eye sees by a
  pixel or two, which costs at the edges (a frame over the sky, a shelf over the wall) and barely on the
  smooth surfaces between them;
- with the set's panorama (``pano_z.exr``): ``unseen``, the fraction of pixels whose surface the
  panorama's centre never saw (``seen_from_centre``: behind something else from there, or sky where the
  centre saw a frame), ``psnr_seen`` / ``psnr_unseen`` over each part, and ``psnr_panorama``: the
  panorama itself resampled at each seen pixel's exact surface direction (``panorama_at_surfaces``),
  against the truth: what a perfect geometry with the panorama's own colours scores there, the ceiling
  of any scene built from that panorama.

Pure functions of tensors, plus ``score_truth`` (files in, scores and pictures out).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

EMPTY_ALPHA = 0.5
CRACK_ALPHA = 0.9
DELTA = 1.25
SEEN_TOL = 0.01  # relative (+ 1 cm): a surface point this near the panorama's depth in its direction was seen
EDGE_JUMP = 0.05  # relative camera-z step between neighbouring truth pixels that is a depth edge
EDGE_REACH = 2  # px: the edges' band reaches this far to either side


def per_view_psnr(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """PSNR dB of each image pair [V, H, W, 3] in [0, 1]: [V] float64 (+inf where equal)."""
    return -10.0 * torch.log10(((pred.double() - target.double()) ** 2).flatten(1).mean(1))


def pooled_psnr(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> float:
    """PSNR dB of the squared error pooled over all pixels of pred / target [V, H, W, 3] in [0, 1], or over
    the pixels where mask [V, H, W] (NaN when it selects none)."""
    err = (pred.double() - target.double()) ** 2
    if mask is not None:
        if not bool(mask.any()):
            return math.nan
        err = err[mask]
    mse = float(err.mean())
    return math.inf if mse == 0.0 else -10.0 * math.log10(mse)


def depth_errors(
    depth: torch.Tensor, alpha: torch.Tensor, truth: torch.Tensor, empty_alpha: float = EMPTY_ALPHA
) -> dict:
    """AbsRel, delta < 1.25 and scale (the median of z / z*) of rendered depth [V, H, W] (metres; camera z)
    against truth [V, H, W] (camera z, +inf / NaN = no truth) over pixels with finite truth > 0 and alpha
    [V, H, W] >= ``empty_alpha``; ``coverage`` = those pixels / finite-truth pixels. NaN where no pixel
    qualifies."""
    t = truth.double()
    finite = torch.isfinite(t) & (t > 0)
    m = finite & (alpha >= empty_alpha) & (depth > 0)
    n = int(m.sum())
    if n == 0:
        return dict(abs_rel=math.nan, delta1=math.nan, scale=math.nan, coverage=0.0, pixels=0)
    d, g = depth.double()[m], t[m]
    ratio = torch.maximum(d / g, g / d)
    return dict(
        abs_rel=float(((d - g).abs() / g).mean()),
        delta1=float((ratio < DELTA).double().mean()),
        scale=float((d / g).median()),
        coverage=n / max(int(finite.sum()), 1),
        pixels=n,
    )


def depth_edges(z: torch.Tensor, jump: float = EDGE_JUMP, reach: int = EDGE_REACH) -> torch.Tensor:
    """Pixels [V, H, W] bool within ``reach`` px (a square window) of a pixel on a depth edge of truth
    camera z [V, H, W] (metres, +inf / NaN = sky): one of two 4-neighbours whose z differ by more than
    ``jump`` (relative), or one finite and one not. A straight edge's band is 2 ``reach`` + 2 px wide."""
    import torch.nn.functional as F

    t = z.double()
    finite = torch.isfinite(t) & (t > 0)
    lt = torch.log(torch.where(finite, t, torch.ones_like(t)))
    step = math.log1p(jump)
    edge = torch.zeros_like(finite)
    for dim in (1, 2):
        n = t.shape[dim] - 1
        a, b = lt.narrow(dim, 0, n), lt.narrow(dim, 1, n)
        fa, fb = finite.narrow(dim, 0, n), finite.narrow(dim, 1, n)
        cut = (fa != fb) | (fa & fb & ((a - b).abs() > step))
        edge.narrow(dim, 0, n).logical_or_(cut)
        edge.narrow(dim, 1, n).logical_or_(cut)
    k = 2 * reach + 1
    return F.max_pool2d(edge[:, None].double(), k, stride=1, padding=reach)[:, 0] > 0


def surface_points(viewmats: torch.Tensor, K: torch.Tensor, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World points [V, H, W, 3] (metres; NaN where z is not finite) of the truth views' pixels, from
    viewmats [V, 4, 4], K [3, 3] and camera z [V, H, W], and the pixels' unit ray directions [V, H, W, 3]."""
    from holoflow.geometry.camera import pinhole_rays

    V, H, W = z.shape
    origins, dirs = pinhole_rays(K.double().expand(V, 3, 3), viewmats.double(), H, W)  # [V, H, W, 3]
    cam_z = torch.einsum("vhwc,vc->vhw", dirs, viewmats.double()[:, 2, :3])  # camera z of each unit ray
    t = torch.where(torch.isfinite(z), z.double() / cam_z, torch.full_like(cam_z, math.nan))
    return origins + dirs * t[..., None], dirs


def seen_from_centre(points: torch.Tensor, dirs: torch.Tensor, pano_depth: torch.Tensor) -> torch.Tensor:
    """Which truth pixels show a surface the panorama's centre saw: points / dirs [V, H, W, 3]
    (``surface_points``), pano_depth [Hp, Wp] radial metres (inf = sky). A finite point is seen when its
    distance is within ``SEEN_TOL`` of the panorama's farthest depth over the 3 x 3 pixels around its
    direction (a surface within a pixel of a silhouette counts as seen: at the centre, everything is); a
    sky pixel when the panorama sees sky along the same direction. [V, H, W] bool."""
    import torch.nn.functional as F

    from holoflow.geometry.sampling import pad_equirect, sample_equirect

    pd = pano_depth.double()
    farthest = F.max_pool2d(pad_equirect(pd[None], 1), 3, stride=1)[0]  # [Hp, Wp]: 3 x 3 maximum
    finite = torch.isfinite(points).all(-1)
    r = torch.linalg.vector_norm(torch.nan_to_num(points), dim=-1)
    u = torch.where(finite[..., None], torch.nan_to_num(points) / r.clamp_min(1e-9)[..., None], dirs)
    at = sample_equirect(farthest[None], u, "nearest")[:, 0]  # [V, H, W]
    sky_there = ~torch.isfinite(sample_equirect(pd[None], u, "nearest")[:, 0])
    return torch.where(finite, r <= at * (1 + SEEN_TOL) + 0.01, sky_there)


def panorama_at_surfaces(points: torch.Tensor, dirs: torch.Tensor, pano_srgb: torch.Tensor) -> torch.Tensor:
    """The panorama pano_srgb [3, Hp, Wp] (sRGB) sampled bilinearly at the direction of each truth
    pixel's surface point from the centre (``surface_points``; sky: the pixel's ray): [V, H, W, 3]."""
    from holoflow.geometry.sampling import sample_equirect

    finite = torch.isfinite(points).all(-1, keepdim=True)
    u = torch.where(finite, torch.nan_to_num(points), dirs)
    u = u / torch.linalg.vector_norm(u, dim=-1, keepdim=True).clamp_min(1e-9)
    return sample_equirect(pano_srgb.double(), u, "bilinear").movedim(1, -1).float()


def ring_scores(
    rgb: torch.Tensor,
    alpha: torch.Tensor,
    depth: torch.Tensor,
    truth_rgb: torch.Tensor,
    truth_z: torch.Tensor,
    empty_alpha: float = EMPTY_ALPHA,
    crack_alpha: float = CRACK_ALPHA,
    seen: torch.Tensor | None = None,
    panorama: torch.Tensor | None = None,
) -> dict:
    """Scores of one ring (module docstring): rgb / truth_rgb [V, H, W, 3] sRGB, alpha / depth / truth_z
    [V, H, W]; seen [V, H, W] (``seen_from_centre``) and panorama [V, H, W, 3] (``panorama_at_surfaces``)
    when the set has its panorama."""
    from holoflow.quality import metrics

    p = per_view_psnr(rgb, truth_rgb)
    s = [metrics.ssim(a, b) for a, b in zip(rgb, truth_rgb)]
    out = dict(
        views=len(rgb),
        psnr=pooled_psnr(rgb, truth_rgb),
        psnr_mean=float(p.mean()),
        ssim=sum(s) / len(s),
        empty=float((alpha < empty_alpha).double().mean()),
        cracked=float((alpha < crack_alpha).double().mean()),
        per_view_psnr=[round(float(x), 3) for x in p],
        per_view_ssim=[round(float(x), 4) for x in s],
        per_view_cracked=[round(float(x), 5) for x in (alpha < crack_alpha).double().flatten(1).mean(1)],
    )
    out.update(depth_errors(depth, alpha, truth_z, empty_alpha))
    edges = depth_edges(truth_z)
    out.update(
        edges=float(edges.double().mean()),
        psnr_edges=pooled_psnr(rgb, truth_rgb, edges),
        psnr_surfaces=pooled_psnr(rgb, truth_rgb, ~edges),
    )
    if seen is not None:
        out.update(
            unseen=float((~seen).double().mean()),
            psnr_seen=pooled_psnr(rgb, truth_rgb, seen),
            psnr_unseen=pooled_psnr(rgb, truth_rgb, ~seen),
            psnr_panorama=pooled_psnr(panorama, truth_rgb, seen) if panorama is not None else math.nan,
        )
    return out


def render_truth_views(
    model, viewmats: torch.Tensor, K: torch.Tensor, width: int, height: int, backend: str = "cpu"
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``model`` rendered at viewmats [V, 4, 4] with K [3, 3]: (rgb [V, H, W, 3] sRGB in [0, 1], alpha
    [V, H, W], depth [V, H, W] expected camera z in metres, 0 where alpha is 0)."""
    from holoflow.recon.optimize import render_views

    blank = torch.zeros(height, width, 3)
    rgb, alpha, depth = render_views(
        model, [dict(image=blank, viewmat=vm, K=K) for vm in viewmats], backend, with_depth=True
    )
    return rgb, alpha[..., 0], depth[..., 0]


def ring_keys(rings: list[float]) -> list[str]:
    """The distinct rings in ascending order as keys f"{r:g}" ('0', '0.25', ...)."""
    return [f"{r:g}" for r in sorted(set(rings))]


def score_truth(model_file: Path, truth_dir: Path, backend: str = "cpu") -> tuple[dict, dict]:
    """Score the scene in ``model_file`` (a 3DGS PLY) against the truth set in ``truth_dir``. Returns
    (scores: {rings: {ring key: ring_scores}, truth, views, gaussians, seconds}, pictures: {ring key:
    (truth [V, H, W, 3], render [V, H, W, 3]) sRGB})."""
    import time

    from holoflow.evaluation.truth_set import read_truth_set
    from holoflow.splat import GaussianModel
    from holoflow.splat.rasterize import backend_device

    t0 = time.monotonic()
    ts = read_truth_set(truth_dir)
    model = GaussianModel.load_ply(model_file).to(backend_device(backend))
    H, W = ts.rgb.shape[1:3]
    rgb, alpha, depth = render_truth_views(model, ts.viewmats, ts.K, W, H, backend)
    rings = torch.tensor(ts.rings)
    pano = _read_panorama(ts.folder / ts.cameras.get("pano", "pano_z.exr"))
    scores, pictures = {}, {}
    for key in ring_keys(ts.rings):
        m = torch.isclose(rings, torch.tensor(float(key)))
        seen = at = None
        if pano is not None:
            points, dirs = surface_points(ts.viewmats[m], ts.K, ts.z[m])
            seen, at = seen_from_centre(points, dirs, pano[1]), panorama_at_surfaces(points, dirs, pano[0])
        scores[key] = ring_scores(rgb[m], alpha[m], depth[m], ts.rgb[m], ts.z[m], seen=seen, panorama=at)
        pictures[key] = (ts.rgb[m], rgb[m])
    return dict(
        rings=scores,
        truth=str(ts.folder),
        views=len(ts.names),
        gaussians=len(model),
        size=[int(W), int(H)],
        seconds=time.monotonic() - t0,
    ), pictures


def _read_panorama(path: Path) -> tuple[torch.Tensor, torch.Tensor] | None:
    """A truth set's panorama file (linear R, G, B + Z radial metres): (sRGB [3, H, W], depth [H, W]), or
    None when the set has none."""
    from holoflow.imageops.color import linear_to_srgb_torch
    from holoflow.io.exr import read_exr

    if not path.is_file():
        return None
    ch = read_exr(path)[0]
    if "Z" not in ch:
        return None
    rgb = torch.from_numpy(np.stack([ch["R"], ch["G"], ch["B"]], -1).astype(np.float32))  # [H, W, 3]
    return linear_to_srgb_torch(rgb).permute(2, 0, 1), torch.from_numpy(np.asarray(ch["Z"], np.float64))


def _f(x, fmt: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def ring_table(scores: dict) -> list[str]:
    """The ring table as text lines: one row per ring."""
    head = (
        f"  {'ring':>6s} {'views':>5s} {'PSNR dB':>8s} {'mean':>7s} {'SSIM':>7s} {'AbsRel':>7s} {'d<1.25':>7s}"
        f" {'scale':>6s} {'empty %':>8s} {'a<0.9 %':>8s} {'edges %':>8s} {'edge dB':>8s} {'surf dB':>8s}"
        f" {'unseen %':>8s} {'seen dB':>8s} {'unseen dB':>9s} {'pano dB':>8s}"
    )
    rows = [
        f"truth set {scores['truth']} ({scores['views']} views, {scores['size'][0]}x{scores['size'][1]} px); "
        f"{scores['gaussians']} Gaussians",
        head,
    ]
    for key, r in scores["rings"].items():
        rows.append(
            f"  {key + ' m':>6s} {r['views']:5d} {_f(r['psnr'], '{:.2f}'):>8s}"
            f" {_f(r['psnr_mean'], '{:.2f}'):>7s} {_f(r['ssim'], '{:.4f}'):>7s}"
            f" {_f(r['abs_rel'], '{:.4f}'):>7s} {_f(r['delta1'], '{:.4f}'):>7s}"
            f" {_f(r.get('scale'), '{:.3f}'):>6s} {_f(100 * r['empty'], '{:.2f}'):>8s}"
            f" {_f(100 * r['cracked'], '{:.2f}'):>8s} {_f(_pct(r.get('edges')), '{:.2f}'):>8s}"
            f" {_f(r.get('psnr_edges'), '{:.2f}'):>8s} {_f(r.get('psnr_surfaces'), '{:.2f}'):>8s}"
            f" {_f(_pct(r.get('unseen')), '{:.2f}'):>8s} {_f(r.get('psnr_seen'), '{:.2f}'):>8s}"
            f" {_f(r.get('psnr_unseen'), '{:.2f}'):>9s} {_f(r.get('psnr_panorama'), '{:.2f}'):>8s}"
        )
    rows.append(
        "PSNR: pooled over the ring's pixels (mean: of the per-view values), sRGB; AbsRel / d<1.25 / scale "
        f"(median z / Z): rendered camera z vs the views' Z (finite truth, alpha >= {EMPTY_ALPHA}); "
        f"empty: alpha < {EMPTY_ALPHA}; "
        f"a<0.9: alpha < {CRACK_ALPHA}; edges: pixels within {EDGE_REACH} px of a depth edge of the truth "
        f"(a step over {EDGE_JUMP:.0%} or the sky's border; edge / surf dB: PSNR over them and over the rest); "
        "unseen: surfaces the panorama's centre never saw (seen / unseen dB: "
        "PSNR over each part); pano dB: the panorama itself at the seen surfaces' exact directions, the "
        "ceiling of a scene built from it."
    )
    return rows


def _pct(x: float | None) -> float | None:
    return None if x is None else 100 * x


def ring_strip(truth: torch.Tensor, *renders: torch.Tensor, side: int = 256, gap: int = 4) -> np.ndarray:
    """One picture of a ring: its views [V, H, W, 3] sRGB side by side, each fitted into ``side`` px, truth
    above the renders (one row each): uint8 [(1 + R) side + R gap, V side + (V - 1) gap, 3]."""
    from holoflow.report.pictures import mosaic

    def u8(x):
        return (x.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)

    tiles = [t for images in (truth, *renders) for t in u8(images)]
    return mosaic(tiles, len(truth), side, gap=gap)


def write_pictures(pictures: dict, folder: Path, prefix: str) -> dict[str, Path]:
    """One PNG per ring (``ring_strip``) as folder/{prefix}-ring-{key}.png: {ring key: path}."""
    from holoflow.io.image import write_png

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for key, (truth, render) in pictures.items():
        out[key] = folder / f"{prefix}-ring-{key}.png"
        write_png(out[key], ring_strip(truth, render))
    return out
