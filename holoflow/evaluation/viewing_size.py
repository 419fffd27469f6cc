"""What people see: a finished scene scored at a viewing size.

The paper's Table II protocol taken where a viewer looks, not at the training size:

- **base**: the run's base cameras (the PANO-set rig, rotations only, at the panorama centre) at
  ``size`` px square with horizontal field of view ``fov_deg`` (default 512 px at the paper's 47.43
  deg). The scene (``transfer_opt/scene.ply``, holoflow's own rasterizer) is rendered there and
  compared in sRGB [0, 1] with the SOURCE's views through the same cameras at the same size: for a
  user's photo (``--use base_pano=photo.jpg``) the photo itself, read at full resolution from the
  file the run recorded; otherwise the detail panorama. Source views are antialiased
  (``equirect_to_pinhole`` mode "antialias": the panorama prefiltered down to the view's pixel size
  when it has more px/deg, then ``supersample`` x ``supersample`` bilinear samples per pixel).
  PSNR (dB) and SSIM are means of the per-camera values over the cameras whose view axis is more than
  ``pole_deg`` from both poles; the polar cameras (within ``pole_deg`` of the zenith or nadir) are
  scored on their own, with their mean PSNR's gap below the others' mean (``polar_gap_db``, > 0 =
  worse).
- **nr**: NIQE and BRISQUE (holoflow.quality.nriqa, lower = better) of the renders and of the source's own
  views at a seeded subset of ``nr_cameras`` non-polar cameras (0 = all), and their ratio
  render / source (a photo has its own score; 1.0 = as natural as the source).
- **novel**: ``per_distance`` cameras at each distance of ``distances`` metres off the centre
  (``novel_rig``: eyes moved in several directions, looking sideways or back at the strong edges of
  the run's depth, ``edge_targets``; or, with ``rig`` "rings", ``ring_rig``: the truth sets' fixed
  eyes), each scored by its EMPTY fraction (pixels whose rendered alpha <
  ``empty_alpha``), its CRACKED fraction (alpha < ``crack_alpha``), NIQE / BRISQUE of the renders
  against the source's views of ``nr`` (``novel_nr``; sizes >= 192 px) and, where truth exists (a
  procedural base_pano with its scene.json), PSNR against the true render.

Everything here is a pure function of the run's files; ``holoflow eval --run`` prints ``table``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from holoflow.geometry.camera import elevation_deg, polar_views

PAPER_FOV_DEG = 47.43  # focal 582.69 px at 512 px (LucidDreamer / HoloDreamer)


@dataclass(frozen=True)
class ViewingSpec:
    """How a run is scored (module docstring). Sizes in px, angles in degrees, distances in metres."""

    size: int = 512
    fov_deg: float = PAPER_FOV_DEG
    pole_deg: float = 25.0
    supersample: int = 2
    nr_cameras: int = 12
    empty_alpha: float = 0.5
    crack_alpha: float = 0.9
    distances: tuple[float, ...] = (0.25, 0.5, 1.0)
    per_distance: int = 8
    pitch_deg: float = 30.0
    wall_margin: float = 0.3
    seed: int = 0
    backend: str = "cpu"
    novel_nr: bool = True
    rig: str = "edges"  # novel eyes: edges = novel_rig at the depth's edges; rings = ring_rig (fixed eyes)


# Goals per profile: psnr (dB, at least), brisque / niqe (ratio render / source, at most),
# polar_gap (dB, at most), empty_0.5 (novel cameras 0.5 m off centre, fraction, at most), seconds
# (end to end on a 2-core CPU, the paper's on a GPU; checked by the profile bench, at most).
GOALS = {
    "preview": {"psnr": 32.0, "brisque": 1.5, "polar_gap": 1.0, "empty_0.5": 0.005, "seconds": 35.0},
    "quality": {"psnr": 37.0, "brisque": 1.2, "niqe": 1.1, "polar_gap": 1.0, "empty_0.5": 0.005, "seconds": 300.0},
    "paper": {"psnr": 40.19, "polar_gap": 1.0, "empty_0.5": 0.005, "seconds": 240.0},
}


def view_intrinsics(size: int, fov_deg: float) -> torch.Tensor:
    """Pinhole K [3, 3] float32 of a size x size view with horizontal field of view ``fov_deg``."""
    from holoflow.geometry.camera import intrinsics_from_fov

    return intrinsics_from_fov(fov_deg, size, size, dtype=torch.float32)


def source_views(
    pano: torch.Tensor, viewmats: torch.Tensor, K: torch.Tensor, size: int, supersample: int = 2, chunk: int = 8
) -> torch.Tensor:
    """The source's own views: panorama pano [3, H, W] linear light, seen from its centre through
    cameras viewmats [C, 4, 4] with K [3, 3] at size x size px, antialiased (module docstring) ->
    sRGB [C, size, size, 3] in [0, 1]."""
    from holoflow.geometry.sampling import equirect_to_pinhole
    from holoflow.imageops.color import linear_to_srgb_torch

    out = []
    for s in range(0, len(viewmats), chunk):
        vm = viewmats[s : s + chunk].to(pano.dtype)
        v = equirect_to_pinhole(
            pano, K.to(pano.dtype).expand(len(vm), 3, 3), vm, size, size, mode="antialias", supersample=supersample
        )  # [c, 3, size, size]
        out.append(linear_to_srgb_torch(v.permute(0, 2, 3, 1).float()))
    return torch.cat(out)


def render_at(
    model, viewmats: torch.Tensor, K: torch.Tensor, size: int, backend: str = "cpu"
) -> tuple[torch.Tensor, torch.Tensor]:
    """A Gaussian model rendered at cameras viewmats [C, 4, 4], K [3, 3], size x size px:
    (sRGB [C, size, size, 3] clamped to [0, 1], alpha [C, size, size])."""
    from holoflow.recon.optimize import render_views

    blank = torch.zeros(size, size, 3)
    rgb, alpha = render_views(model, [dict(image=blank, viewmat=vm, K=K) for vm in viewmats], backend)
    return rgb, alpha[..., 0]


def per_camera_psnr(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """PSNR in dB of each image pair [C, H, W, 3] in [0, 1]: [C] float64 (+inf where equal)."""
    mse = ((pred.double() - target.double()) ** 2).flatten(1).mean(1)  # [C]
    return -10.0 * torch.log10(mse)


def per_camera_ssim(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """SSIM (holoflow.quality.metrics) of each image pair [C, H, W, 3]: [C] float64."""
    from holoflow.quality import metrics

    return torch.tensor([metrics.ssim(p, t) for p, t in zip(pred, target)], dtype=torch.float64)


def base_scores(renders: torch.Tensor, sources: torch.Tensor, polar: torch.Tensor) -> dict:
    """Table II at the viewing size: renders / sources [C, H, W, 3] sRGB, polar [C] bool.
    psnr / ssim: means over the non-polar cameras; polar_psnr / polar_ssim: over the polar ones,
    polar_worst_psnr their minimum; psnr_pooled: PSNR of the non-polar cameras' pooled MSE;
    polar_gap_db = psnr - polar_psnr (> 0: the poles are worse); per-camera lists keep every value."""
    p, s = per_camera_psnr(renders, sources), per_camera_ssim(renders, sources)
    side, pole = ~polar, polar

    def mean(x, m):
        return float(x[m].mean()) if bool(m.any()) else math.nan

    pooled = float(-10.0 * torch.log10(((renders[side].double() - sources[side].double()) ** 2).mean()))
    out = dict(
        cameras=int(side.sum()),
        polar_cameras=int(pole.sum()),
        psnr=mean(p, side),
        ssim=mean(s, side),
        psnr_pooled=pooled,
        polar_psnr=mean(p, pole),
        polar_ssim=mean(s, pole),
        polar_worst_psnr=float(p[pole].min()) if bool(pole.any()) else math.nan,
        per_camera_psnr=[round(float(x), 4) for x in p],
        per_camera_ssim=[round(float(x), 5) for x in s],
        polar=[bool(x) for x in polar],
    )
    out["polar_gap_db"] = out["psnr"] - out["polar_psnr"]
    return out


def nr_pick(polar: torch.Tensor, count: int, seed: int) -> torch.Tensor:
    """Indices [k] (sorted) of a seeded subset of ``count`` non-polar cameras (0 or more than there are =
    all of them): the cameras NIQE / BRISQUE are taken at."""
    idx = torch.nonzero(~polar).flatten()
    if 0 < count < len(idx):
        g = torch.Generator().manual_seed(seed)
        idx = idx[torch.randperm(len(idx), generator=g)[:count]].sort().values
    return idx


def nr_scores(renders: torch.Tensor, sources: torch.Tensor) -> dict:
    """Mean NIQE and BRISQUE of renders and of sources [C, H, W, 3] (sRGB, H, W >= 192 for NIQE) and
    the ratios render / source. A score whose package is missing is None, with the reason under
    ``unavailable``."""
    from holoflow.quality import nriqa

    out: dict = {"cameras": len(renders)}
    for name, fn in (("niqe", nriqa.niqe), ("brisque", nriqa.brisque)):
        try:
            r = [fn(x) for x in renders]
            s = [fn(x) for x in sources]
        except nriqa.Unavailable as e:
            out[name] = None
            out.setdefault("unavailable", {})[name] = str(e)
            continue
        mr, ms = sum(r) / len(r), sum(s) / len(s)
        out[name] = dict(render=mr, source=ms, ratio=mr / ms if ms > 0 else math.nan)
    return out


def free_distance(depth: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Metres from the panorama centre to the first surface along unit world directions dirs [N, 3],
    read from a radial depth panorama depth [H, W] (metric_align's Z; inf = sky) at the nearest pixel:
    [N] float64 (inf where the ray sees sky)."""
    from holoflow.geometry.sampling import sample_equirect

    d = torch.where(torch.isnan(depth), math.inf, depth).double()
    return sample_equirect(d[None], dirs[None].double(), mode="nearest")[0, 0]  # [N]


def edge_targets(
    depth: torch.Tensor,
    cells: tuple[int, int] = (32, 12),
    max_lat_deg: float = 50.0,
    min_step: float = 0.05,
    max_width: int = 256,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Points on the near side of the strong depth edges of a radial depth panorama depth [H, W]
    (metres; inf / NaN = sky): (points [M, 3] world metres, strength [M]).

    The panorama is first brought to at most ``max_width`` px wide by the minimum over blocks (so an
    edge a network blurred over a few pixels is one step). Strength of a pixel = the largest |log
    depth| step to its right (wrapping) or lower neighbour less the mean of the two steps beside it
    along the same axis (so a wall seen at a grazing angle, whose steps are all alike, has none), sky
    taken as twice the farthest surface. The panorama is cut into cells[0] x cells[1] cells
    (longitude x latitude within +-``max_lat_deg``); each cell whose strongest pixel steps by more than
    ``min_step`` gives that pixel's direction at the nearest depth of its 3 x 3 neighbourhood."""
    from holoflow.geometry.sphere import equirect_directions

    d = torch.where(torch.isnan(depth), math.inf, depth).double()
    f = max(1, depth.shape[1] // max_width)
    if f > 1:  # near side kept: min over f x f blocks
        d = -torch.nn.functional.max_pool2d(-d[None, None], f)[0, 0]
    H, W = d.shape
    finite = torch.isfinite(d) & (d > 0)
    far = 2 * float(d[finite].max()) if bool(finite.any()) else 1.0
    ld = torch.log(torch.where(finite, d, torch.full_like(d, far)))
    right = (ld - torch.roll(ld, -1, 1)).abs()  # [H, W] step to x + 1
    down = torch.nn.functional.pad((ld[:-1] - ld[1:]).abs(), (0, 0, 0, 1))  # [H, W] step to y + 1
    up, below = torch.nn.functional.pad(down[:-1], (0, 0, 1, 0)), torch.nn.functional.pad(down[1:], (0, 0, 0, 1))
    jump_x = right - 0.5 * (torch.roll(right, 1, 1) + torch.roll(right, -1, 1))  # a slope's steps cancel
    jump_y = down - 0.5 * (up + below)
    strength = torch.maximum(jump_x, jump_y).clamp_min(0.0)
    near = -torch.nn.functional.max_pool2d(-torch.where(finite, d, torch.full_like(d, far))[None, None], 3, 1, 1)[0, 0]
    lat = 90.0 - 180.0 * (torch.arange(H, dtype=torch.float64) + 0.5) / H  # [H] degrees
    rows = torch.nonzero(lat.abs() <= max_lat_deg).flatten()
    r0, r1 = int(rows.min()), int(rows.max()) + 1
    dirs = equirect_directions(H, W, dtype=torch.float64)  # [H, W, 3]
    pts, strg = [], []
    for i in range(cells[1]):
        for j in range(cells[0]):
            ys = slice(r0 + (r1 - r0) * i // cells[1], r0 + (r1 - r0) * (i + 1) // cells[1])
            xs = slice(W * j // cells[0], W * (j + 1) // cells[0])
            s = strength[ys, xs]
            if s.numel() == 0:
                continue
            k = int(s.argmax())
            y, x = ys.start + k // s.shape[1], xs.start + k % s.shape[1]
            if float(s.max()) > min_step and float(near[y, x]) < far:
                pts.append(dirs[y, x] * near[y, x])
                strg.append(float(s.max()))
    if not pts:
        return torch.zeros(0, 3, dtype=torch.float64), torch.zeros(0, dtype=torch.float64)
    return torch.stack(pts), torch.tensor(strg, dtype=torch.float64)


def turn_deg(per_distance: int) -> torch.Tensor:
    """Where camera k of ``novel_rig`` prefers to look with edge targets, degrees from its move
    direction (positive to the right): 90 (right) to 270 (left) through 180 (back), spread over the
    cameras in a seed-free order that alternates sides: [per_distance] float64."""
    steps = torch.arange(per_distance, dtype=torch.float64)
    spread = 90.0 + 180.0 * steps / max(per_distance - 1, 1)  # 90 .. 270
    order = torch.tensor([(k * 3) % per_distance for k in range(per_distance)]) if per_distance % 3 else steps.long()
    return spread[order]


def novel_rig(
    distances: tuple[float, ...],
    per_distance: int,
    seed: int,
    free=None,
    pitch_deg: float = 30.0,
    margin: float = 0.3,
    targets=None,
    min_turn_deg: float = 60.0,
    window_deg: float = 45.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Novel cameras off the centre: (viewmats [D * per_distance, 4, 4] float32, offsets [D * per] m).

    For camera k of a distance d: the eye moves horizontally (at the centre's height) along azimuth
    phi + 2 pi k / per_distance (phi seeded, uniform in one step) by d metres, shortened to ``margin``
    metres in front of the first surface along that direction when ``free`` (a function: unit
    directions [N, 3] -> metres [N], e.g. ``free_distance`` on the run's depth) says it is nearer.

    Without ``targets`` it looks, by k mod 4: along its move (toward the wall it approached), 90 deg
    right of it, back across the centre, 90 deg left, tilted by a seeded pitch uniform in [-pitch_deg,
    pitch_deg]. With ``targets`` = (points [M, 3], strength [M]) (``edge_targets``: the near sides of
    the depth edges, where a step uncovers what the centre never saw) it looks at one of them: among
    the points whose azimuth from the centre is within ``window_deg`` of ``turn_deg(k)`` off its move
    and at least ``min_turn_deg`` away from the move (sideways or back), the one with the largest
    strength x a seeded factor uniform in [0.5, 1]; a camera with no such point keeps the direction
    ``turn_deg(k)`` with its seeded pitch. The same targets serve every distance, so distances
    compare like for like."""
    from holoflow.geometry.camera import look_at

    g = torch.Generator().manual_seed(seed)
    phi = float(torch.rand(1, generator=g, dtype=torch.float64)) * 2 * math.pi / per_distance
    pitch = (torch.rand(per_distance, generator=g, dtype=torch.float64) * 2 - 1) * math.radians(pitch_deg)
    az = phi + 2 * math.pi * torch.arange(per_distance, dtype=torch.float64) / per_distance  # [P]
    move = torch.stack([torch.sin(az), torch.zeros_like(az), torch.cos(az)], 1)  # [P, 3] +y is down
    if targets is None:
        turn = az + (math.pi / 2) * (torch.arange(per_distance) % 4).double()
    else:
        turn = az + torch.deg2rad(turn_deg(per_distance))
    look = torch.stack([torch.sin(turn) * torch.cos(pitch), -torch.sin(pitch), torch.cos(turn) * torch.cos(pitch)], 1)
    aim = None
    if targets is not None:
        aim = pick_targets(targets, move, turn, g, min_turn_deg, window_deg)  # [P, 3], NaN = none
    room = torch.full((per_distance,), math.inf, dtype=torch.float64) if free is None else free(move).double()
    vms, offs = [], []
    for d in distances:
        off = torch.clamp(torch.minimum(torch.full_like(room, float(d)), room - margin), min=0.0)  # [P]
        eye = move * off[:, None]
        at = eye + look
        if aim is not None:
            ok = torch.isfinite(aim).all(1) & ((aim - eye).norm(dim=1) > margin)
            at = torch.where(ok[:, None], torch.nan_to_num(aim), at)
        vms.append(look_at(eye, at))
        offs.append(off)
    return torch.cat(vms).float(), torch.cat(offs)


def ring_rig(distances: tuple[float, ...], per_distance: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The truth sets' eyes (``truth_set.ring_eyes``) as a novel rig: per distance d, ``per_distance``
    eyes d metres off the centre, each looking horizontally sideways or back from where it moved, the
    same for every run whatever its depth (no wall margin: an eye may stand in a wall of a small room).
    Returns (viewmats [D * per_distance, 4, 4] float32, offsets [D * per_distance] m)."""
    from holoflow.evaluation.truth_set import eye_viewmat, ring_eyes

    eyes = ring_eyes(tuple(distances), per_distance)
    vms = torch.stack([eye_viewmat(e["eye"], e["look"]) for e in eyes]).float()
    return vms, torch.tensor([e["ring"] for e in eyes], dtype=torch.float64)


def pick_targets(
    targets, move: torch.Tensor, turn: torch.Tensor, g: torch.Generator, min_turn_deg: float, window_deg: float
) -> torch.Tensor:
    """The edge point each camera looks at (``novel_rig``): points [M, 3] and strength [M] of
    ``targets``, unit moves [P, 3], preferred azimuths turn [P] radians -> [P, 3] (NaN rows: no point
    qualifies). Consumes P x M seeded uniforms from ``g``."""
    pts, strength = targets
    pts, strength = pts.double(), strength.double()
    P, M = len(move), len(pts)
    jitter = 0.5 + 0.5 * torch.rand(P, M, generator=g, dtype=torch.float64)  # [P, M]
    out = torch.full((P, 3), math.nan, dtype=torch.float64)
    if M == 0:
        return out
    flat = pts * torch.tensor([1.0, 0.0, 1.0], dtype=torch.float64)
    flat = flat / flat.norm(dim=1, keepdim=True).clamp_min(1e-9)  # [M, 3] horizontal
    taz = torch.atan2(flat[:, 0], flat[:, 2])  # [M]
    off_pref = torch.remainder(taz[None] - turn[:, None] + math.pi, 2 * math.pi) - math.pi  # [P, M]
    cos_move = flat @ move.T  # [M, P]
    ok = (off_pref.abs() <= math.radians(window_deg)) & (cos_move.T <= math.cos(math.radians(min_turn_deg)))
    score = torch.where(ok, strength[None] * jitter, torch.full_like(jitter, -1.0))
    best = score.argmax(1)  # [P]
    has = ok.any(1)
    out[has] = pts[best[has]]
    return out


def novel_scores(
    alpha: torch.Tensor,
    offsets: torch.Tensor,
    distances: tuple[float, ...],
    empty_alpha: float,
    renders: torch.Tensor | None = None,
    truth: torch.Tensor | None = None,
    crack_alpha: float = 0.9,
) -> dict:
    """Per distance (key f"{d:g}"): empty = fraction of the pixels of its cameras (alpha [C, H, W], the
    ``novel_rig`` order) whose alpha < ``empty_alpha``, cracked = those with alpha < ``crack_alpha``,
    per-camera empties and cracks, the mean actual offset (m), and with truth [C, H, W, 3] PSNR of
    renders against it (pooled over the distance's cameras)."""
    from holoflow.quality import metrics

    P = len(alpha) // len(distances)
    out = {}
    for i, d in enumerate(distances):
        sl = slice(i * P, (i + 1) * P)
        empty = (alpha[sl] < empty_alpha).double()
        crack = (alpha[sl] < crack_alpha).double()
        r = dict(
            cameras=P,
            empty=float(empty.mean()),
            cracked=float(crack.mean()),
            offset_m=float(offsets[sl].mean()),
            per_camera_empty=[round(float(e), 5) for e in empty.flatten(1).mean(1)],
            per_camera_cracked=[round(float(e), 5) for e in crack.flatten(1).mean(1)],
        )
        if truth is not None and renders is not None:
            r["psnr"] = metrics.psnr(renders[sl], truth[sl])
        out[f"{d:g}"] = r
    return out


@dataclass
class Source:
    """The panorama a run's renders are judged against: linear RGB [3, H, W], what it is, and notes."""

    pano: torch.Tensor
    kind: str  # "photo FILE" or "detail panorama"
    notes: list[str] = field(default_factory=list)


def run_source(run_dir: Path, run_info: dict) -> Source:
    """The run's source (module docstring): the photo given by ``--use base_pano=FILE`` read at full
    resolution from the file the run recorded (checked against the sha256 the import wrote into the
    base panorama, else the imported base panorama itself, which holds the same pixels); otherwise
    the run's detail panorama."""
    from holoflow.io.exr import read_exr, read_rgb

    st = (run_info.get("stages") or {}).get("base_pano") or {}
    if st.get("how") == "used":
        src = Path(st.get("source") or "")
        imported = run_dir / "base_pano" / "pano.exr"
        want = read_exr(imported)[1].get("holoflow.source_sha256") if imported.is_file() else None
        if src.is_file() and src.suffix.lower() != ".exr":
            from holoflow.io.image import read_panorama_image

            rgb, facts = read_panorama_image(src)
            if want is None or facts["sha256"] == want:
                return Source(
                    torch.from_numpy(rgb).permute(2, 0, 1).contiguous(),
                    f"photo {src.name} ({facts['size'][0]}x{facts['size'][1]})",
                )
            note = f"{src} changed since the run (sha256 differs); scored against the imported copy"
        else:
            note = f"{src} not readable as a photo; scored against the run's imported base panorama"
        rgb = read_rgb(imported)
        return Source(
            torch.from_numpy(rgb).permute(2, 0, 1).contiguous(),
            f"imported base panorama ({rgb.shape[1]}x{rgb.shape[0]})",
            [note],
        )
    rgb = read_rgb(run_dir / "detail" / "pano.exr")
    return Source(
        torch.from_numpy(rgb).permute(2, 0, 1).contiguous(), f"detail panorama ({rgb.shape[1]}x{rgb.shape[0]})"
    )


def base_camera_viewmats(run_dir: Path) -> torch.Tensor:
    """The run's base cameras (pano_set/cameras.json) as rotations at the centre: viewmats [C, 4, 4]."""
    from holoflow.recon.views import read_cameras

    cams = read_cameras(run_dir / "pano_set")
    vm = torch.stack([torch.tensor(v["viewmat"], dtype=torch.float32).reshape(4, 4) for v in cams["views"]])
    vm[:, :3, 3] = 0.0
    return vm


def true_novel(run_dir: Path, viewmats: torch.Tensor, K: torch.Tensor, size: int) -> torch.Tensor | None:
    """True sRGB renders [C, size, size, 3] of the run's procedural scene (base_pano/scene.json) at
    the cameras, or None when the run has no procedural truth (a photo, a generated panorama)."""
    from holoflow.imageops.color import linear_to_srgb_torch

    f = run_dir / "base_pano" / "scene.json"
    if not f.is_file():
        return None
    from holoflow.scene import render_pinhole
    from holoflow.scene.model import Scene

    scene = Scene.from_json(f.read_text())
    views = [torch.from_numpy(render_pinhole(scene, K.numpy(), vm.numpy(), size, size)[0]) for vm in viewmats]
    return linear_to_srgb_torch(torch.stack(views))


def score_run(
    run_dir: Path, run_info: dict, spec: ViewingSpec = ViewingSpec(), model_file: str = "transfer_opt/scene.ply"
) -> tuple[dict, dict]:
    """Score a finished run folder (runs/<id>/) at the viewing size (module docstring).
    Returns (scores: base / nr / novel / source / spec / seconds per part, pictures: source and render
    [C, size, size, 3] at the base cameras, polar [C], novel renders and alpha, truth or None)."""
    import time

    from holoflow.io.exr import read_exr
    from holoflow.splat import GaussianModel
    from holoflow.splat.rasterize import backend_device

    t = {}
    t0 = time.monotonic()
    model = GaussianModel.load_ply(run_dir / model_file).to(backend_device(spec.backend))
    K = view_intrinsics(spec.size, spec.fov_deg)
    vm = base_camera_viewmats(run_dir)
    polar = polar_views(vm, spec.pole_deg)
    src = run_source(run_dir, run_info)
    sources = source_views(src.pano, vm, K, spec.size, spec.supersample)
    t["source_views"] = time.monotonic() - t0
    t0 = time.monotonic()
    renders, _ = render_at(model, vm, K, spec.size, spec.backend)
    t["render_base"] = time.monotonic() - t0
    t0 = time.monotonic()
    base = base_scores(renders, sources, polar)
    base["elevation_deg"] = [round(float(e), 3) for e in elevation_deg(vm)]
    t["psnr_ssim"] = time.monotonic() - t0
    t0 = time.monotonic()
    pick = nr_pick(polar, spec.nr_cameras, spec.seed)
    nr = nr_scores(renders[pick], sources[pick]) if spec.size >= 192 and len(pick) else {"cameras": 0}
    nr["camera_ids"] = [int(i) for i in pick]
    t["niqe_brisque"] = time.monotonic() - t0
    t0 = time.monotonic()
    depth_file = run_dir / "metric_align" / "depth.exr"
    free, targets = None, None
    if depth_file.is_file():
        depth = torch.from_numpy(read_exr(depth_file)[0]["Z"])
        free = lambda dirs: free_distance(depth, dirs)  # noqa: E731
        targets = edge_targets(depth)
    if spec.rig == "rings":
        nvm, offsets = ring_rig(spec.distances, spec.per_distance)
    else:
        nvm, offsets = novel_rig(
            spec.distances, spec.per_distance, spec.seed, free, spec.pitch_deg, spec.wall_margin, targets
        )
    nrgb, nalpha = render_at(model, nvm, K, spec.size, spec.backend)
    t["render_novel"] = time.monotonic() - t0
    t0 = time.monotonic()
    truth = true_novel(run_dir, nvm, K, spec.size)
    t["truth_novel"] = time.monotonic() - t0
    novel = novel_scores(nalpha, offsets, spec.distances, spec.empty_alpha, nrgb, truth, spec.crack_alpha)
    t0 = time.monotonic()
    if spec.size >= 192 and spec.novel_nr and len(pick):
        for i, (d, r) in enumerate(novel.items()):
            sl = slice(i * spec.per_distance, (i + 1) * spec.per_distance)
            r["nr"] = nr_scores(nrgb[sl], sources[pick])
    t["novel_niqe_brisque"] = time.monotonic() - t0
    scores = dict(
        base=base,
        nr=nr,
        novel=novel,
        source=src.kind,
        notes=src.notes,
        gaussians=len(model),
        spec={k: list(v) if isinstance(v, tuple) else v for k, v in asdict(spec).items()},
        seconds=t,
        depth_for_novel=depth_file.is_file(),
        edge_targets=0 if targets is None else len(targets[0]),
    )
    pictures = dict(source=sources, render=renders, polar=polar, novel=nrgb, novel_alpha=nalpha, truth=truth)
    return scores, pictures


def goals_for(profile: str | None) -> tuple[str, dict]:
    """(profile whose goals apply, goals): the run's profile's (a comma list: its last known one),
    else the preview's."""
    names = [p for p in (profile or "").split(",") if p in GOALS]
    name = names[-1] if names else "preview"
    return name, GOALS[name]


def _ok(value, goal, at_most: bool) -> str:
    if value is None or goal is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return "met" if (value <= goal if at_most else value >= goal) else "NOT met"


def table(scores: dict, profile: str | None) -> list[str]:
    """The viewing-size table as text lines: each measured figure with the run profile's goal and
    whether it is met (``GOALS``)."""
    name, g = goals_for(profile)
    s, b, nr, nv = scores["spec"], scores["base"], scores["nr"], scores["novel"]
    rows = []

    def row(label, value, fmt, goal=None, at_most=False, goal_text=None):
        v = "-" if value is None or (isinstance(value, float) and math.isnan(value)) else fmt.format(value)
        gt = goal_text or ("-" if goal is None else ("<= " if at_most else ">= ") + fmt.format(goal))
        rows.append(f"  {label:42s}{v:>10s}   {gt:>10s}   {_ok(value, goal, at_most)}".rstrip())

    row(f"base PSNR dB ({b['cameras']} cameras)", b["psnr"], "{:.2f}", g.get("psnr"))
    row("base PSNR dB, pooled MSE", b.get("psnr_pooled"), "{:.2f}")
    row("base SSIM", b["ssim"], "{:.4f}")
    for key in ("niqe", "brisque"):
        r = nr.get(key)
        if r is None:
            why = nr.get("unavailable", {}).get(key, "not measured (size < 192 px)")
            rows.append(f"  {key.upper() + ' render / source':42s}{'-':>10s}   {why}")
            continue
        row(
            f"{key.upper()} render / source ({r['render']:.1f} / {r['source']:.1f})",
            r["ratio"],
            "{:.2f}x",
            g.get(key),
            at_most=True,
        )
    row(f"zenith/nadir PSNR dB ({b['polar_cameras']} cameras)", b["polar_psnr"], "{:.2f}")
    row("zenith/nadir gap below the others dB", b["polar_gap_db"], "{:.2f}", g.get("polar_gap"), at_most=True)
    row("zenith/nadir SSIM", b["polar_ssim"], "{:.4f}")
    for d, r in nv.items():
        goal = g.get("empty_0.5") if d == "0.5" else None
        row(
            f"novel {d} m empty % ({r['cameras']} cams, {r['offset_m']:.2f} m)",
            100 * r["empty"],
            "{:.2f} %",
            None if goal is None else 100 * goal,
            at_most=True,
        )
        if "cracked" in r:
            row(f"novel {d} m alpha < {s.get('crack_alpha', 0.9)} %", 100 * r["cracked"], "{:.2f} %")
        for key in ("niqe", "brisque"):
            x = (r.get("nr") or {}).get(key)
            if x is not None:
                row(
                    f"novel {d} m {key.upper()} / source ({x['render']:.1f} / {x['source']:.1f})", x["ratio"], "{:.2f}x"
                )
        if "psnr" in r:
            row(f"novel {d} m PSNR dB vs truth", r["psnr"], "{:.2f}")
    head = [
        f"viewing size {s['size']} px, {s['fov_deg']} deg horizontal field of view; source: {scores['source']}; "
        f"{scores['gaussians']} Gaussians",
        f"  {'':42s}{'measured':>10s}   goal ({name})",
    ]
    eyes = (
        "novel eyes: the truth sets' rings (fixed eyes looking sideways and back, docs/truth-sets.md)"
        if s.get("rig") == "rings"
        else f"novel eyes move horizontally (<= {s['wall_margin']} m short of the run's depth) and look "
        f"sideways or back at the depth's edges ({scores.get('edge_targets', 0)} found), seed {s['seed']}"
    )
    foot = [
        f"PSNR / SSIM: means of the per-camera values over the base cameras more than {s['pole_deg']} deg from "
        "the poles (sRGB; pooled: the PSNR of their pooled squared error, which easy flat views do not lift); "
        f"zenith/nadir: the cameras within {s['pole_deg']} deg of them. NIQE / BRISQUE (lower is better): means "
        f"over {nr.get('cameras', 0)} of those cameras, render / source. Empty: alpha < {s['empty_alpha']}; "
        f"{eyes}; their NIQE / BRISQUE: against the same source views.",
        "Paper Table II (at 512 px, its own generated panoramas): PSNR 40.19 dB, SSIM 0.984.",
    ]
    return head + rows + [f"  note: {n}" for n in scores.get("notes", [])] + foot


def to_uint8(images: torch.Tensor) -> np.ndarray:
    """sRGB [..., H, W, 3] in [0, 1] -> uint8 numpy (rounded)."""
    return (images.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)
