"""Cameras to score a model at: the run's base cameras with the PANO set, seeded supplementary and
novel cameras, true renders of the procedural scene there, and the pixels hidden from the centre."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

    from holoflow.scene import Scene


MAX_OFFSET_M = 1.0  # novel cameras: at most this far from the centre (metres)


def hidden_from_centre(scene, origins, dirs) -> "torch.Tensor":
    """[N] bool: the surface seen along each ray (origins [N, 3] m, unit dirs [N, 3], world) is
    hidden from the panorama centre (the world origin), i.e. the panorama never saw it.

    A finite hit X is hidden when the ray from the centre towards X stops more than 1 cm + 0.2 % of
    |X| short of it; a sky ray (no hit) is hidden when the centre's ray in the same direction hits
    something (sky is at infinity, so direction alone decides)."""
    import torch

    from holoflow.scene import cast

    t = cast(scene, origins, dirs)[1].double()  # [N]
    sky = ~torch.isfinite(t)
    x = origins.double() + torch.nan_to_num(t, posinf=0.0)[:, None] * dirs.double()  # [N, 3] hit points
    r = x.norm(dim=1)  # [N] m from the centre
    u = torch.where(sky[:, None] | (r[:, None] < 1e-9), dirs.double(), x / r.clamp_min(1e-9)[:, None])
    tc = cast(scene, torch.zeros_like(u), u)[1].double()  # [N]
    return torch.where(sky, torch.isfinite(tc), tc < r * (1 - 2e-3) - 1e-2)


def hidden_masks(scene, viewmats, K, width: int, height: int) -> "torch.Tensor":
    """Per pixel of each camera, whether its surface is hidden from the centre: [C, H, W] bool
    (pixel-centre rays; see ``hidden_from_centre``)."""

    from holoflow.geometry.camera import pinhole_rays

    o, d = pinhole_rays(K.double(), viewmats.double(), height, width)  # [C, H, W, 3] each
    return hidden_from_centre(scene, o.reshape(-1, 3), d.reshape(-1, 3)).reshape(len(viewmats), height, width)


def novel_cameras(
    scene, n: int, offset: float, seed: int, K=None, candidates: int = 16, probe: int = 16
) -> "torch.Tensor":
    """n seeded novel cameras off the centre that look at what the panorama could not see, viewmats
    [n, 4, 4].

    Each eye lies along a random direction u at a uniform random fraction in [offset / 2, offset] of
    the free distance from the centre to the first surface along u (capped at MAX_OFFSET_M), so it is
    inside the scene's free space and really off the base cameras' position. Its view direction is
    the one of ``candidates`` seeded directions (uniform on the sphere) whose ``probe`` x ``probe``
    pixel view (intrinsics K [3, 3] rescaled; None = 90 deg field of view) shows the largest fraction
    of surface hidden from the centre (first candidate on ties): novel-view scores then measure the
    disocclusions the INP set exists for, not only surfaces the panorama already saw."""
    import torch

    from holoflow.geometry.camera import look_at
    from holoflow.scene import cast

    g = torch.Generator().manual_seed(seed)
    u = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=1)
    frac = (0.5 + 0.5 * torch.rand(n, generator=g, dtype=torch.float64)) * offset
    look = torch.nn.functional.normalize(torch.randn(n, candidates, 3, generator=g, dtype=torch.float64), dim=2)
    free = cast(scene, torch.zeros(n, 3), u.float())[1].double()  # [n] metres (inf = sky)
    dist = torch.minimum(frac * torch.nan_to_num(free, posinf=1e9), torch.full_like(frac, MAX_OFFSET_M))
    eyes = u * dist[:, None]  # [n, 3]
    Kp = torch.tensor([[probe / 2, 0, probe / 2], [0, probe / 2, probe / 2], [0, 0, 1]], dtype=torch.float64)
    if K is not None:
        Kp = square_K(K, probe).double()
    vms = look_at(eyes[:, None].expand(n, candidates, 3), eyes[:, None] + look)  # [n, candidates, 4, 4]
    hidden = hidden_masks(scene, vms.reshape(-1, 4, 4), Kp, probe, probe).flatten(1).double().mean(1)
    pick = hidden.reshape(n, candidates).argmax(1)  # [n] first on ties
    return vms[torch.arange(n), pick].float()


def square_K(K, size: int) -> "torch.Tensor":
    """Pinhole K [3, 3] (pixels) for a size x size image with the field of view of K [3, 3], whose
    principal point is the centre of its image (width 2 cx, height 2 cy)."""
    import torch

    s = torch.tensor([size / (2 * float(K[0, 2])), size / (2 * float(K[1, 2])), 1.0], dtype=torch.float64)
    return (K.double() * s[:, None]).to(K.dtype)


def true_views(
    scene, viewmats, K, width: int, height: int, samples: int = 2, cache: dict | None = None
) -> "torch.Tensor":
    """True sRGB renders [C, H, W, 3] of the procedural scene at pinhole cameras (``samples`` per
    pixel side, antialiased like the base panorama). ``cache`` maps camera bytes -> render, so
    variants that share cameras ray-cast each view once."""
    import torch

    from holoflow.imageops.color import linear_to_srgb_torch
    from holoflow.scene import render_pinhole

    cache = {} if cache is None else cache
    out = []
    for vm in viewmats:
        key = (scene.prompt, scene.seed, vm.numpy().tobytes(), K.numpy().tobytes(), width, height, samples)
        if key not in cache:
            cache[key] = torch.from_numpy(
                render_pinhole(scene, K.numpy(), vm.numpy(), width, height, samples=samples)[0]
            )
        out.append(cache[key])
    return linear_to_srgb_torch(torch.stack(out))


@dataclass
class Views:
    """Cameras to score a model at: viewmats [C, 4, 4] (world-to-camera), K [3, 3], targets [C, H, W, 3]
    sRGB; optionally hidden [C, H, W] bool (surface hidden from the centre, see ``score``)."""

    viewmats: "torch.Tensor"
    K: "torch.Tensor"
    targets: "torch.Tensor"
    hidden: "torch.Tensor | None" = None


def pano_views(run_dir: Path) -> Views:
    """The base cameras of a run folder (runs/<id>/) with the PANO set as targets (the paper's
    Table II protocol; needs no truth)."""
    import torch

    from holoflow.recon.views import intrinsics, load_view_set

    views, cams = load_view_set(run_dir / "pano_set", alpha_is_mask=False)
    return Views(torch.stack([v["viewmat"] for v in views]), intrinsics(cams), torch.stack([v["image"] for v in views]))


def base_views(run_dir: Path) -> tuple["Scene", Views]:
    """The procedural scene of a run folder (runs/<id>/) and its base cameras (``pano_views``)."""
    from holoflow.scene.model import Scene

    scene_file = run_dir / "base_pano" / "scene.json"
    if not scene_file.is_file():
        raise SystemExit(
            f"eval: {scene_file} missing: eval needs the procedural base_pano engine (truth); "
            "for a run without truth use `holoflow eval --run RUN`"
        )
    return Scene.from_json(scene_file.read_text()), pano_views(run_dir)


def supp_cameras(run_dir: Path, supp: int, seed: int) -> tuple["torch.Tensor", "torch.Tensor"]:
    """A seeded subset of ``supp`` supplementary cameras (pcd_set; 0 = all): (viewmats [C, 4, 4]
    world-to-camera, K [3, 3] of the set's images)."""
    import torch

    from holoflow.recon.views import intrinsics, read_cameras

    cams = read_cameras(run_dir / "pcd_set")
    vm = torch.stack([torch.tensor(v["viewmat"], dtype=torch.float32).reshape(4, 4) for v in cams["views"]])
    if 0 < supp < len(vm):
        pick = torch.randperm(len(vm), generator=torch.Generator().manual_seed(seed))[:supp]
        vm = vm[pick.sort().values]
    return vm, intrinsics(cams)
