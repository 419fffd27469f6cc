"""``rasterize``: one contract, three backends (dense torch reference, fast CPU, gsplat CUDA)."""

from __future__ import annotations

import torch

from holoflow.splat.project import eval_sh, pixel_extent, project_gaussians

BACKENDS = ("auto", "reference", "cpu", "gsplat")


def backend_device(backend: str) -> str:
    """The device a model must be on to render with ``backend``: cuda for gsplat, else cpu ("auto" renders
    wherever the model is, so cpu for a model just read from disk)."""
    return "cuda" if backend == "gsplat" else "cpu"


def rasterize(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    opacities: torch.Tensor,
    colors: torch.Tensor,
    viewmats: torch.Tensor,
    Ks: torch.Tensor,
    width: int,
    height: int,
    near: float = 0.01,
    far: float = 1e10,
    background: torch.Tensor | None = None,
    backend: str = "auto",
    sh_degree: int | None = None,
    depth: bool = True,
) -> dict:
    """Render activated Gaussians into C pinhole cameras.

    means [N, 3] world metres; quats [N, 4] (w, x, y, z), normalised inside (zero -> identity);
    scales [N, 3] metres, positive; opacities [N] in (0, 1); colors [N, D] (used as is) or SH
    coefficients [N, K, 3] evaluated per view (degree ``sh_degree``, default sqrt(K) - 1, + 0.5 and
    clamped at 0 as in 3DGS); viewmats [C, 4, 4] world-to-camera (OpenCV axes); Ks [C, 3, 3] with pixel
    centres at +0.5; background [D] or [C, D] added as (1 - alpha) * background.
    backend: "reference" (dense torch), "cpu" (tiles + numba), "gsplat" (CUDA), "auto" (gsplat for
    CUDA tensors, else cpu).
    Returns dict(rgb [C, H, W, D], alpha [C, H, W, 1], depth [C, H, W, 1] = sum_i w_i z_i (accumulated
    camera z, metres; divide by alpha for the expected depth; None with ``depth=False``, which spares
    the compositing a channel: training needs none), meta = dict(means2d [C, N, 2] (keeps its
    gradient for densification statistics), radii [C, N] int (0 = not drawn), depths [C, N],
    packed=False); the "cpu" backend's meta is packed (as gsplat's ``packed=True``): one row per
    drawn (camera, Gaussian) pair, means2d [P, 2], radii [P] (>= 1), depths [P], camera_ids [P] and
    gaussian_ids [P], packed=True)."""
    if backend not in BACKENDS:
        raise ValueError(f"rasterize: unknown backend {backend!r}, expected one of {BACKENDS}")
    _check_shapes(means, quats, scales, opacities, colors, viewmats, Ks, width, height)
    if backend == "auto":
        backend = "gsplat" if means.is_cuda else "cpu"
    if backend == "gsplat":
        if not means.is_cuda:
            raise ValueError(
                "rasterize: backend 'gsplat' renders CUDA tensors, got CPU ones (move the model with .to('cuda'))"
            )
        return _rasterize_gsplat(
            means,
            quats,
            scales,
            opacities,
            colors,
            viewmats,
            Ks,
            width,
            height,
            near,
            far,
            background,
            sh_degree,
            depth,
        )
    if backend == "cpu" and means.device.type != "cpu":
        raise ValueError(f"rasterize: backend 'cpu' needs CPU tensors, got {means.device}")
    C, N = viewmats.shape[0], means.shape[0]
    if backend == "cpu":
        from holoflow.splat.composite_cpu import composite_cpu
        from holoflow.splat.project_cpu import project_cpu

        proj = project_cpu(means, quats, scales, opacities, viewmats, Ks, width, height, near, far)
        gid, start = proj["gaussian_ids"], proj["camera_start"].tolist()
        # Each camera colours and composites only the Gaussians it draws (a few % of a panorama's),
        # in index order, so the image is the bytes the whole set would give.
        outs = []
        for c in range(C):
            rows = slice(start[c], start[c + 1])
            g, d = gid[rows], proj["depths"][None, rows]  # [n], [1, n]
            feats = _features(means[g], colors[g], viewmats[c : c + 1], sh_degree, d, depth)
            outs.append(
                composite_cpu(
                    proj["means2d"][None, rows],
                    proj["conics"][None, rows],
                    opacities[g][None],
                    feats,
                    d,
                    torch.ones_like(d, dtype=torch.bool),
                    proj["ext"][None, rows],
                    width,
                    height,
                )
            )
        if not outs:  # no camera
            F = _features(means[:0], colors[:0], viewmats, sh_degree, means.new_zeros(0, 0), depth).shape[-1]
            outs = [means.new_zeros(0, height, width, F)]
        out = torch.cat(outs)  # [C, H, W, F]
        camera_ids = torch.repeat_interleave(torch.arange(C), torch.diff(proj["camera_start"]))
        meta = dict(
            means2d=proj["means2d"],
            radii=proj["radii"],
            depths=proj["depths"],
            camera_ids=camera_ids,
            gaussian_ids=gid,
            packed=True,
        )
    else:
        from holoflow.splat.reference import composite_dense

        ops = opacities[None].expand(C, N)
        proj = project_gaussians(means, quats, scales, viewmats, Ks, width, height, near, far)
        ext = pixel_extent(proj["cov2d"].detach(), ops.detach())  # [C, N, 2]
        m2 = proj["means2d"].detach()
        on_screen = ((m2 + ext >= 0) & (m2 - ext <= m2.new_tensor([width, height]))).all(-1)
        drawn = proj["valid"] & on_screen & (ops.detach() >= 1 / 255)  # [C, N]
        radii = torch.where(drawn, ext.max(-1).values.ceil(), torch.zeros_like(ext[..., 0])).to(torch.int32)
        feats = _features(means, colors, viewmats, sh_degree, proj["depths"], depth)
        out = composite_dense(proj["means2d"], proj["conics"], ops, feats, proj["depths"], proj["valid"], width, height)
        meta = dict(means2d=proj["means2d"], radii=radii, depths=proj["depths"], packed=False)
    D = out.shape[-1] - (2 if depth else 1)
    alpha = out[..., -1:]
    color = out[..., :D]
    if background is not None:
        color = color + (1 - alpha) * background.to(color).reshape(-1, 1, 1, D)
    return dict(rgb=color, alpha=alpha, depth=out[..., D : D + 1] if depth else None, meta=dict(meta, backend=backend))


def _features(means, colors, viewmats, sh_degree, depths, depth: bool) -> torch.Tensor:
    """What the compositor accumulates per camera and Gaussian [C, N, D (+1) + 1]: colour, the camera
    z where ``depth`` is asked for, and 1 (alpha). depths [C, N]."""
    rgb = camera_colors(means, colors, viewmats, sh_degree)  # [C, N, D]
    extra = [depths[..., None]] if depth else []
    return torch.cat([rgb, *extra, torch.ones_like(depths[..., None])], -1)


def camera_colors(
    means: torch.Tensor, colors: torch.Tensor, viewmats: torch.Tensor, sh_degree: int | None
) -> torch.Tensor:
    """Per-camera colours [C, N, D] of Gaussians at means [N, 3]: colors [N, D] as they are, or SH
    [N, K, 3] evaluated towards each camera centre (degree 0 needs no direction)."""
    C = viewmats.shape[0]
    if colors.dim() == 2:
        return colors[None].expand(C, -1, -1)
    if sh_degree == 0:
        return eval_sh(colors[:, :1], means, 0)[None].expand(C, -1, -1)
    campos = -torch.einsum("cji,cj->ci", viewmats[:, :3, :3], viewmats[:, :3, 3])  # [C, 3]
    d = means[None] - campos[:, None]  # [C, N, 3]
    d = d / torch.sqrt((d * d).sum(-1, keepdim=True).clamp_min(1e-24))
    return eval_sh(colors[None].expand(C, -1, -1, -1), d, sh_degree)  # [C, N, 3]


def render(
    model,
    viewmats: torch.Tensor,
    Ks: torch.Tensor,
    width: int,
    height: int,
    backend: str = "auto",
    background: torch.Tensor | None = None,
    sh_degree: int | None = None,
    **kwargs,
) -> dict:
    """Render a ``GaussianModel`` (activations applied: exp scales, sigmoid opacity, SH colour up to
    ``sh_degree``, default the model's). Other keyword arguments go to ``rasterize``."""
    return rasterize(
        model.means,
        model.quats,
        torch.exp(model.log_scales),
        torch.sigmoid(model.opacity_logits),
        model.sh,
        viewmats,
        Ks,
        width,
        height,
        background=background,
        backend=backend,
        sh_degree=model.sh_degree if sh_degree is None else sh_degree,
        **kwargs,
    )


def _check_shapes(means, quats, scales, opacities, colors, viewmats, Ks, width, height):
    N = means.shape[0]
    want = {
        "means": (means, (N, 3)),
        "quats": (quats, (N, 4)),
        "scales": (scales, (N, 3)),
        "opacities": (opacities, (N,)),
    }
    for name, (t, shape) in want.items():
        if tuple(t.shape) != shape:
            raise ValueError(f"rasterize: {name} has shape {tuple(t.shape)}, expected {shape}")
    if colors.shape[0] != N or colors.dim() not in (2, 3) or (colors.dim() == 3 and colors.shape[-1] != 3):
        raise ValueError(f"rasterize: colors must be [N, D] or SH [N, K, 3], got {tuple(colors.shape)}")
    C = viewmats.shape[0]
    if tuple(viewmats.shape) != (C, 4, 4) or tuple(Ks.shape) != (C, 3, 3):
        raise ValueError(
            f"rasterize: viewmats {tuple(viewmats.shape)} / Ks {tuple(Ks.shape)} must be [C, 4, 4] / [C, 3, 3]"
        )
    if width < 1 or height < 1:
        raise ValueError(f"rasterize: image size {width}x{height} must be at least 1x1")


def _rasterize_gsplat(
    means, quats, scales, opacities, colors, viewmats, Ks, width, height, near, far, background, sh_degree, depth
):
    try:
        from gsplat import rasterization
    except ImportError as exc:
        raise RuntimeError(
            "rasterize: backend 'gsplat' needs the optional extra `cuda` (pip install gsplat) and a CUDA device"
        ) from exc
    sh = colors.dim() == 3
    if sh and sh_degree is None:
        sh_degree = int(round(colors.shape[1] ** 0.5)) - 1
    rc, ra, meta = rasterization(
        means,
        quats,
        scales,
        opacities,
        colors,
        viewmats,
        Ks,
        width,
        height,
        near_plane=near,
        far_plane=far,
        eps2d=0.3,
        sh_degree=sh_degree if sh else None,
        packed=False,
        render_mode="RGB+D" if depth else "RGB",
        rasterize_mode="classic",
        camera_model="pinhole",
    )
    color, z = (rc[..., :-1], rc[..., -1:]) if depth else (rc, None)
    if background is not None:
        color = color + (1 - ra) * background.to(color).reshape(-1, 1, 1, color.shape[-1])
    radii = meta["radii"]
    if radii.dim() == 3:  # gsplat >= 1.5: per-axis radii [C, N, 2]
        radii = radii.max(-1).values
    return dict(
        rgb=color,
        alpha=ra,
        depth=z,
        meta=dict(
            means2d=meta["means2d"], radii=radii.to(torch.int32), depths=meta["depths"], packed=False, backend="gsplat"
        ),
    )


def compile_ahead() -> None:
    """Compile the fast CPU path's numba kernels (or load them from numba's disk cache) as a float32
    model's training uses them: the kernels the preview calls, one specialization each.

    Back to front first (the parallel binning and culling, the backward kernels, the forward ones,
    then the serial binning and culling and the projection), on empty inputs of the dtypes the glue
    passes: a step that starts while this runs compiles front to back (projection, culling,
    binning, forward, backward) and meets this process half way instead of compiling the same
    kernels beside it. Then through this module's own glue, which compiles nothing more when those
    dtypes are the glue's: a forward and backward pass of a small scene (serial culling and
    binning, parallel projection and compositing) and of one above ``cpu.PARALLEL_MIN_GAUSSIANS`` on
    screen (parallel culling and binning), 64 x 64 px each. The serial compositing and projection
    kernels (views under ``PARALLEL_MIN_ENTRIES`` tile entries, scenes under ``PARALLEL_MIN_WORK``)
    are left to their first use. holoflow/flow/executors/ahead.py."""
    import numpy as np

    from holoflow.splat import composite_cpu as cpu
    from holoflow.splat import project_cpu as cp
    from holoflow.splat.synthetic import intrinsics, surface_scene

    f4, f8, i8 = (lambda *shape, dt=dt: np.zeros(shape, dt) for dt in (np.float32, np.float64, np.int64))
    C, N, F, W, H = 1, 0, 4, 16, 16
    cpu._bin_tiles(i8(N), i8(N, 4), f8(N, 2), f4(N, 3), f4(N), f4(N, F), W, H, 1)
    cpu._boxes(np.zeros(N, bool), f8(N, 2), f8(N, 2), f4(N), W, H, i8(N, 4))
    cp._project_bwd_params(f4(N, 4), f4(N, 3), i8(N), f8(N, 9), f8(N, 3), f4(N, 3), f4(N, 4), f4(N, 3))
    cp._project_bwd_pairs(
        f4(N, 3),
        f4(N, 4),
        f4(N, 3),
        f4(C, 4, 4),
        f4(C, 3, 3),
        W,
        H,
        i8(C + 1),
        i8(N),
        i8(N),
        f8(N, 3),
        f4(N, 2),
        f4(N, 3),
        f4(N),
        f8(N, 9),
        f8(N, 3),
    )
    cpu._gather_grads(i8(1), i8(N), i8(N), f8(N, 6 + F), f4(N, 2), f4(N, 3), f4(N), f4(N, F))
    pack = (f8(N, 7), i8(N, 4), f8(N, F), i8(1), i8(N), W, H)  # rec, pbox, ft, offsets, ids: no tiles
    cpu._backward(*pack, f8(H, W), i8(H, W), f8(H, W, F), f8(N, 6 + F))
    cpu._forward(*pack, f4(H, W, F), f8(H, W), i8(H, W), i8(1))
    cpu._bin_tiles_serial(i8(N), i8(N, 4), f8(N, 2), f4(N, 3), f4(N), f4(N, F), W, H, 1)
    cpu._boxes_serial(np.zeros(N, bool), f8(N, 2), f8(N, 2), f4(N), W, H, i8(N, 4))
    cam = (f4(N, 3), f4(N, 4), f4(N, 3), f4(N), f4(C, 4, 4), f4(C, 3, 3), W, H, 0.01, 1e10)
    cp._project_write(
        *cam,
        np.zeros((C, N), bool),
        i8(1, C),
        i8(N),
        f4(N, 2),
        f4(N, 3),
        f8(N, 3),
        f4(N),
        f8(N, 2),
        np.zeros(N, np.int32),
    )
    cp._count_chunks(np.zeros((C, N), bool), i8(1, C))
    cp._project_test(*cam, 0.004, np.zeros((C, N), bool))
    for n, depth in ((cp.PARALLEL_MIN_WORK, True), (2 * cpu.PARALLEL_MIN_GAUSSIANS, False)):  # work = n
        s = surface_scene(n)
        params = [s[k].requires_grad_() for k in ("means", "quats", "scales", "opacities", "colors")]
        out = rasterize(*params, torch.eye(4)[None], intrinsics(64, 64)[None], 64, 64, backend="cpu", depth=depth)
        out["rgb"].sum().backward()
