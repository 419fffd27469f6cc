"""Depth engines for the tangent faces: relative disparity and metric depth.

Every engine works on F tangent faces of h x w pixels and returns float arrays [F, h, w]:

- relative engines return a *perspective* disparity (~ 1/z up to an unknown affine map per face), as a
  monocular network does; NaN / inf / negative values are allowed and masked downstream.
- metric engines return perspective depth z in metres (+inf where unbounded).

Engines (registered by name in holoflow/depth/config.py; docs/depth.md says what each is good for):

``simulated`` (SIMULATION, needs the truth): the truth disparity of each face, degraded like a
  relative-depth network: edge mixing (Gaussian blur of the disparity, which only changes it across
  depth discontinuities), a smooth multiplicative bias field per face, multiplicative pixel noise, then
  an unknown per-face scale and shift. Seeded. Calibrated (``SIM_RELATIVE``, tests/depth) so that after
  the best single scale+shift per face the disparity is still off by AbsRel ~0.10 against truth, like
  Depth Anything through 360MonoDepth (paper: 0.116). The metric simulation is the truth z with a
  per-face scale error and pixel noise (``SIM_METRIC``).
``prior`` (no weights, any panorama): a room layout from the ray direction alone (floor plane below
  the eye, ceiling above, a round wall around); no image content is used.
``layout`` (no weights, any panorama): the image-driven estimator of holoflow.depth.layout (a room
  layout indoors, ground / vertical / sky outdoors), computed once on the whole panorama and sampled
  into the faces; its metric scale comes from the camera height (``cfg.camera_height``).
``given`` (a panorama imported with its own depth): the exact perspective disparity / depth of the
  given Z channel; metric_align keeps the given Z itself as the scene's metric depth.
``depth_anything`` / ``zoedepth``: the networks through holoflow.networks (real weights).
``auto`` (the default): ``resolve_engine``'s rule, which also says which engine ran and why.
"""

from __future__ import annotations

import numpy as np

from holoflow.stage import Progress

#: simulated relative engine; sizes are fractions of the face side so any face size behaves alike
SIM_RELATIVE = {
    "edge_blur": 0.01,  # Gaussian sigma of the edge mixing, fraction of the face side
    "bias_std": 0.13,  # std of the log bias field (multiplicative, smooth)
    "bias_cycles": 1.2,  # max spatial frequency of the bias field, cycles per face side
    "noise_std": 0.04,  # std of the multiplicative pixel noise
    "scale_range": (0.3, 3.0),  # per-face scale, log-uniform
    "shift_range": (0.0, 0.5),  # per-face shift, fraction of the face's median scaled disparity
}
#: simulated metric engine
SIM_METRIC = {"scale_std": 0.04, "noise_std": 0.02}

#: layout prior: floor this far below the eye, ceiling above it, a round wall at this radius (metres)
PRIOR_LAYOUT = {"floor": 1.6, "ceiling": 1.4, "wall": 4.0}


#: ``holoflow.engine`` of a base_pano EXR whose Z is the truth of a procedural scene (stages/base_pano.py)
PROCEDURAL = "procedural"


def truth_source(folder, name: str = "pano.exr") -> str | None:
    """Where the truth input's Z channel comes from, read from the EXR header (no pixels):
    ``"procedural"`` when the file says base_pano's procedural engine wrote it (its Z is the scene's
    exact truth), ``"given"`` for any other Z (a user's RGB-D panorama imported with ``--use``), None
    when there is no such file or no Z channel."""
    from pathlib import Path

    import OpenEXR

    path = Path(folder) / name if folder is not None else None
    if path is None or not path.is_file():
        return None
    with OpenEXR.File(str(path), header_only=True) as f:
        header = dict(f.header())
    if "Z" not in {c.split(".")[-1] for c in _channel_names(header)}:
        return None
    made_here = header.get("holoflow.stage") == "base_pano" and header.get("holoflow.engine") == PROCEDURAL
    return "procedural" if made_here else "given"


def _channel_names(header: dict) -> list[str]:
    """Channel names of an OpenEXR header dict (its ``channels`` entry: a list of channel objects)."""
    return [getattr(c, "name", str(c)) for c in header.get("channels", [])]


def resolve_engine(
    engine: str, has_truth: bool, *, source: str | None = None, network: str = "", metric: bool = False
) -> tuple[str, str]:
    """The engine that runs for ``engine`` and why, in one line for the step's output, record and status.

    ``auto``, in this order: a truth depth written by the procedural scene (``source`` "procedural", or
    ``has_truth`` with no ``source``) -> ``simulated``; a Z channel a user gave (``source`` "given") ->
    ``given`` (that depth is kept); relative stage with ``network`` (the local weights ``holoflow
    models`` found, or ``model`` set by the user) -> ``depth_anything``; otherwise ``layout``. The
    metric stage (``metric``) has no network under auto: its scale is the layout engine's camera-height
    rule (a metric network runs by name: ``zoedepth``)."""
    if engine != "auto":
        return engine, f"engine {engine!r} was chosen explicitly"
    if has_truth and source in (None, "procedural"):
        return "simulated", (
            "auto: the input carries a procedural scene's truth depth (Z), so the calibrated simulation runs"
        )
    if has_truth:
        return "given", "auto: the imported panorama has a Z channel (radial depth), which is kept as the depth"
    if metric:
        return "layout", (
            "auto: no truth depth; metric scale from the layout engine's camera-height rule (eye "
            "camera_height above the floor); a metric network runs only by name (engine zoedepth)"
        )
    if network:
        from holoflow.networks.weights import describe

        what = describe(network) or "Depth Anything"
        return "depth_anything", f"auto: relative depth from the network found locally ({what}) at {network}"
    return "layout", (
        "auto: no truth depth and no depth network on this machine, so the image-driven layout "
        "estimator runs; `holoflow models pull` fetches Depth Anything V2 Small (24.8 M parameters, "
        "Apache-2.0)"
    )


def simulated_relative(radial: np.ndarray, cos: np.ndarray, seed: int, params: dict | None = None) -> np.ndarray:
    """SIMULATION of a relative-depth network: face disparities [F, h, w] from truth.

    ``radial`` [F, h, w]: true radial depth sampled into the faces (metres, +inf sky); ``cos`` [F, h, w]
    face obliquity. Sky has true disparity 0 (a network's "far").
    """
    import scipy.ndimage as ndi

    p = {**SIM_RELATIVE, **(params or {})}
    rng = np.random.default_rng(seed)
    F, h, w = radial.shape
    z = np.asarray(radial, dtype=np.float64) * cos
    disp = np.where(np.isfinite(z) & (z > 0), 1.0 / np.where(z > 0, z, 1.0), 0.0)  # [F, h, w]
    side = max(h, w)
    y, x = np.meshgrid((np.arange(h) + 0.5) / side, (np.arange(w) + 0.5) / side, indexing="ij")
    out = np.empty_like(disp)
    for f in range(F):
        d = ndi.gaussian_filter(disp[f], p["edge_blur"] * side, mode="nearest")
        bias = np.zeros((h, w))
        for _ in range(6):  # smooth field: random low-frequency plane waves
            k = rng.uniform(-p["bias_cycles"], p["bias_cycles"], 2) * 2 * np.pi
            bias += np.cos(k[0] * x + k[1] * y + rng.uniform(0, 2 * np.pi))
        bias *= p["bias_std"] / max(bias.std(), 1e-12)
        d = d * np.exp(bias + rng.normal(0.0, p["noise_std"], (h, w)))
        scale = np.exp(rng.uniform(*np.log(p["scale_range"])))
        med = np.median(d[d > 0]) if (d > 0).any() else 1.0
        out[f] = scale * (d + rng.uniform(*p["shift_range"]) * med)
    return out.astype(np.float32)


def simulated_metric(radial: np.ndarray, cos: np.ndarray, seed: int, params: dict | None = None) -> np.ndarray:
    """SIMULATION of a metric network: truth z [F, h, w] x per-face scale error x pixel noise (+inf sky)."""
    p = {**SIM_METRIC, **(params or {})}
    rng = np.random.default_rng(seed)
    F, h, w = radial.shape
    z = np.asarray(radial, dtype=np.float64) * cos
    err = np.exp(rng.normal(0.0, p["scale_std"], (F, 1, 1)) + rng.normal(0.0, p["noise_std"], (F, h, w)))
    return np.where(np.isfinite(z), z * err, np.inf).astype(np.float32)


def layout_radial_depth(dirs: np.ndarray, layout: dict | None = None) -> np.ndarray:
    """Radial depth (metres) [...] of unit world directions [..., 3] in the prior room layout.

    World axes: +y down, so the floor is the plane y = floor, the ceiling y = -ceiling, the wall the
    cylinder x^2 + z^2 = wall^2 about the vertical axis. Always finite and > 0.
    """
    L = {**PRIOR_LAYOUT, **(layout or {})}
    dy = dirs[..., 1]
    horiz = np.sqrt(dirs[..., 0] ** 2 + dirs[..., 2] ** 2)
    t_wall = L["wall"] / np.maximum(horiz, 1e-9)
    t_floor = np.where(dy > 1e-9, L["floor"] / np.maximum(dy, 1e-9), np.inf)
    t_ceil = np.where(dy < -1e-9, L["ceiling"] / np.maximum(-dy, 1e-9), np.inf)
    return np.minimum(np.minimum(t_wall, t_floor), t_ceil)


# Engines at the signature of their stage (holoflow/depth/config.py registers them by name):
# engine(images, dirs, cos, truth_radial, seed, cfg, device, progress, pano) -> (array [F, h, w], facts)
# ``images`` [F, h, w, 3] *linear* RGB faces, passed to a real engine as they are (it encodes sRGB once
# itself: docs/conventions.md, EXR colour is linear light); ``dirs`` [F, h, w, 3] world directions; ``cos``
# [F, h, w]; ``truth_radial`` [F, h, w] true radial depth in the faces (``simulated`` only); ``cfg`` the
# stage's params (an engine's own params are fields there); ``progress(done, total, what)``; ``pano``
# [H, W, 3] the whole linear panorama the faces come from (for engines that look at it whole).
# Relative engines return perspective disparity, metric engines perspective depth z (m, +inf unbounded).


def simulated_relative_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``simulated`` relative engine (SIMULATION from the truth, ``SIM_RELATIVE``)."""
    out = simulated_relative(_need_truth(truth_radial, "depth_anything"), cos, seed)
    _report(progress, len(out))
    return out, {
        "engine": "simulated",
        "simulation": True,
        "calibration": dict(SIM_RELATIVE),
        "note": "SIMULATED relative depth from the scene truth, not a network",
    }


def prior_relative_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``prior`` relative engine: the disparity of the room layout prior (no image content)."""
    _report(progress, len(cos))
    return (1.0 / (layout_radial_depth(dirs) * cos)).astype(np.float32), {
        "engine": "prior",
        "layout": dict(PRIOR_LAYOUT),
        "note": "room layout prior from ray direction",
    }


def depth_anything_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``depth_anything`` relative engine (holoflow.networks.depth_anything; weights: ``cfg.model``)."""
    from holoflow.networks import depth_anything

    side = depth_anything.network_side(cfg.net_size or images.shape[1])
    out = depth_anything.relative_disparity(images, cfg.model, device, progress, batch=cfg.net_batch, side=side)
    return np.asarray(out, dtype=np.float32), {"engine": "depth_anything", "model": cfg.model, "net_side": side}


def given_relative_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``given`` relative engine: the exact perspective disparity 1/z of the given Z (sky 0)."""
    z = _need_given(truth_radial) * cos
    _report(progress, len(z))
    return np.where(np.isfinite(z) & (z > 0), 1.0 / np.where(z > 0, z, 1.0), 0.0).astype(np.float32), {
        "engine": "given",
        "note": "the imported panorama's own Z channel",
    }


def given_metric_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``given`` metric engine: the perspective depth z of the given Z (metres, +inf sky). The
    metric_align stage keeps the given Z itself as the depth (stages/metric_align.py)."""
    z = _need_given(truth_radial) * cos
    _report(progress, len(z))
    return np.where(np.isfinite(z) & (z > 0), z, np.inf).astype(np.float32), {
        "engine": "given",
        "note": "the imported panorama's own Z channel",
    }


def simulated_metric_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``simulated`` metric engine (SIMULATION from the truth, ``SIM_METRIC``)."""
    out = simulated_metric(_need_truth(truth_radial, "zoedepth"), cos, seed)
    _report(progress, len(out))
    return out, {
        "engine": "simulated",
        "simulation": True,
        "calibration": dict(SIM_METRIC),
        "note": "SIMULATED metric depth from the scene truth, not a network",
    }


def prior_metric_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``prior`` metric engine: the z of the room layout prior (no image content)."""
    _report(progress, len(cos))
    return (layout_radial_depth(dirs) * cos).astype(np.float32), {
        "engine": "prior",
        "layout": dict(PRIOR_LAYOUT),
        "note": "room layout prior from ray direction",
    }


def zoedepth_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``zoedepth`` metric engine (holoflow.networks.zoedepth; weights: ``cfg.model``)."""
    from holoflow.networks import zoedepth

    out = zoedepth.metric_depth(images, cfg.model, device, progress)
    return np.asarray(out, dtype=np.float32), {"engine": "zoedepth", "model": cfg.model}


def layout_relative_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``layout`` relative engine: perspective disparity of the image-driven layout (sky 0)."""
    radial, facts = _layout_radial(pano, dirs, cfg)
    _report(progress, len(cos))
    z = radial * cos
    return np.where(np.isfinite(z) & (z > 0), 1.0 / np.where(z > 0, z, 1.0), 0.0).astype(np.float32), {
        "engine": "layout",
        "layout": facts,
        "note": "image-driven layout estimate (no weights)",
    }


def layout_metric_engine(
    images,
    dirs,
    cos,
    truth_radial,
    seed,
    cfg,
    device: str = "cpu",
    progress: Progress = None,
    pano: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """``layout`` metric engine: perspective depth z of the image-driven layout (+inf sky), metres."""
    radial, facts = _layout_radial(pano, dirs, cfg)
    _report(progress, len(cos))
    return (radial * cos).astype(np.float32), {
        "engine": "layout",
        "layout": facts,
        "note": "image-driven layout estimate (no weights)",
    }


def _layout_radial(pano, dirs: np.ndarray, cfg) -> tuple[np.ndarray, dict]:
    """Radial depth [F, h, w] (metres, +inf sky) of the layout engine at the face directions, and its
    facts; ``cfg.camera_height`` and ``cfg.scene`` configure it (holoflow.depth.layout.LayoutConfig)."""
    import torch

    from holoflow.depth.layout import LayoutConfig, estimate_layout_depth
    from holoflow.geometry.sampling import sample_equirect

    if pano is None:
        raise ValueError("engine 'layout' needs the panorama image")
    est = estimate_layout_depth(pano, LayoutConfig(camera_height=cfg.camera_height, scene=cfg.scene))
    disp = np.where(np.isfinite(est.depth), 1.0 / np.maximum(est.depth, 1e-6), 0.0)  # [H, W], sky 0
    d = sample_equirect(
        torch.from_numpy(disp[None].astype(np.float64)),
        torch.from_numpy(np.asarray(dirs, dtype=np.float64)),
        mode="nearest",
    )[:, 0].numpy()
    return np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), np.inf), est.facts


def _need_truth(truth_radial: np.ndarray | None, network: str) -> np.ndarray:
    if truth_radial is None:
        raise ValueError(
            "engine 'simulated' needs the truth depth (a Z channel in the truth "
            f"panorama); use engine 'prior' or '{network}' for a panorama without one"
        )
    return truth_radial


def _need_given(truth_radial: np.ndarray | None) -> np.ndarray:
    if truth_radial is None:
        raise ValueError("engine 'given' needs a Z channel (radial depth) in the imported panorama")
    return np.asarray(truth_radial, dtype=np.float64)


def _report(progress: Progress, n: int) -> None:
    """All ``n`` faces done (the weight-free engines finish in one go)."""
    if progress is not None:
        progress(int(n), int(n), "faces")
