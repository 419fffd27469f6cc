"""The viewing-size colour fit (holoflow/recon/colour_fit.py): one SART step against a dense
least-squares reference, convergence, SH > 0, unseen Gaussians, and the target views."""

from __future__ import annotations

import math

import pytest
import torch

from holoflow.recon.colour_fit import fit_colours, viewing_views
from holoflow.splat import GaussianModel, rasterize, render
from holoflow.splat.project import SH_C0
from holoflow.splat.synthetic import intrinsics, look_at, room_scene

SIZE = 24


def _model(
    n: int = 300, seed: int = 0, sh_degree: int = 0, colour: float | None = 0.5
) -> tuple[GaussianModel, torch.Tensor]:
    s = room_scene(n, seed=seed, half=1.0)
    rgb = s["colors"] if colour is None else torch.full_like(s["colors"], colour)
    m = GaussianModel.from_points(
        s["means"].numpy(), rgb.numpy(), sh_degree=sh_degree, opacity=0.5, scales=s["scales"] * 1.5, quats=s["quats"]
    )
    with torch.no_grad():
        m.opacity_logits.copy_(torch.logit(s["opacities"].clamp(0.3, 0.95)))
    return m, s["colors"]


def _cameras(count: int = 6) -> tuple[torch.Tensor, torch.Tensor]:
    dirs = [(1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1), (0.3, -1, 0.2), (0.2, 1, -0.3)][:count]
    vm = torch.stack([look_at((0, 0, 0), d) for d in dirs])
    return vm, intrinsics(SIZE, SIZE, 90.0)


def _views(targets: torch.Tensor, vm: torch.Tensor, K: torch.Tensor) -> list[dict]:
    return [dict(image=t, viewmat=v, K=K, mask=None) for t, v in zip(targets, vm)]


def _truth_targets(truth: torch.Tensor, vm, K) -> torch.Tensor:
    m, _ = _model(colour=None)
    with torch.no_grad():
        m.sh_dc[:, 0, :] = (truth - 0.5) / SH_C0
    return render(m, vm, K.expand(len(vm), 3, 3), SIZE, SIZE, backend="reference", depth=False)["rgb"].detach()


@pytest.mark.parametrize("weights, max_colour", [(None, 1.0), ([1.0, 3.0, 0.5], 1.5)])
def test_one_pass_is_the_dense_sart_step(weights, max_colour):
    """The fast path's one pass equals the SART step built from the explicit weight matrix: every
    Gaussian's compositing weight at every pixel, from rendering one indicator channel per Gaussian
    with the dense reference rasterizer; view weights u_v scale each view's rows of it."""
    m, truth = _model(n=60)
    vm, K = _cameras(3)
    target = torch.rand(3, SIZE, SIZE, 3, generator=torch.Generator().manual_seed(1))
    N = len(m)
    eye = torch.eye(N)
    W = (
        rasterize(
            m.means.detach(),
            m.quats.detach(),
            torch.exp(m.log_scales.detach()),
            torch.sigmoid(m.opacity_logits.detach()),
            eye,
            vm,
            K.expand(3, 3, 3),
            SIZE,
            SIZE,
            backend="reference",
            depth=False,
        )["rgb"]
        .reshape(-1, N)
        .double()
    )  # [P, N]
    c = (SH_C0 * m.sh_dc[:, 0, :].detach() + 0.5).double()  # [N, 3]
    u = torch.tensor([1.0] * 3 if weights is None else weights, dtype=torch.float64)
    u = u.repeat_interleave(SIZE * SIZE)[:, None]  # [P, 1]
    resid = W @ c - target.reshape(-1, 3).double()
    num, den = (u * W).T @ resid, (u * W).sum(0)
    ok = den > 0.05
    want = torch.where(ok[:, None], (c - num / den.clamp_min(0.05)[:, None]).clamp(0, max_colour), c)
    fit_colours(m, _views(target, vm, K), 1, backend="cpu", chunk=2, weights=weights, max_colour=max_colour)
    got = (SH_C0 * m.sh_dc[:, 0, :].detach() + 0.5).double()
    assert int(ok.sum()) > N // 2
    torch.testing.assert_close(got, want, rtol=0, atol=2e-5)


def test_converges_to_the_renders_of_known_colours():
    """Targets rendered with known colours from the same geometry: the fit, started at grey, brings
    the renders to them (PSNR rising every pass, > 40 dB at the end) and the well-seen colours back."""
    m, truth = _model()
    vm, K = _cameras()
    target = _truth_targets(truth, vm, K)
    log = fit_colours(m, _views(target, vm, K), 30, backend="cpu")
    p = log["psnr_before_pass"]
    assert all(b >= a - 1e-6 for a, b in zip(p, p[1:])), p
    out = render(m, vm, K.expand(len(vm), 3, 3), SIZE, SIZE, backend="cpu", depth=False)["rgb"].detach()
    assert -10 * math.log10(float(((out - target) ** 2).mean())) > 40.0
    assert p[0] < 25.0


@pytest.mark.parametrize("backend", ["cpu", "reference"])
def test_view_dependent_colours_fit_their_dc_only(backend):
    """SH degree 1: the fit moves the DC band only (the rest as trained) and lowers the error."""
    m, truth = _model(sh_degree=1)
    with torch.no_grad():
        m.sh_rest.normal_(0.0, 0.1, generator=torch.Generator().manual_seed(3))
    rest = m.sh_rest.detach().clone()
    vm, K = _cameras()
    target = _truth_targets(truth, vm, K)
    log = fit_colours(m, _views(target, vm, K), 3, backend=backend)
    assert torch.equal(m.sh_rest.detach(), rest)  # untouched: the same tensor's values
    assert log["psnr_before_pass"][2] > log["psnr_before_pass"][0] + 3.0


def test_unseen_gaussians_keep_their_colour_and_colours_stay_in_range():
    m, truth = _model()
    vm, K = _cameras(1)  # one camera: most of the room unseen
    before = m.sh_dc.detach().clone()
    target = torch.ones(1, SIZE, SIZE, 3) * 2.0  # unreachable: colours clip at 1
    fit_colours(m, _views(target, vm, K), 2, backend="cpu")
    cam = m.means.detach() @ vm[0, :3, :3].T + vm[0, :3, 3]
    behind = cam[:, 2] < 0
    assert bool(behind.any())
    assert torch.equal(m.sh_dc.detach()[behind], before[behind])  # never written
    rgb = SH_C0 * m.sh_dc.detach()[:, 0, :] + 0.5
    assert float(rgb.max()) <= 1.0 + 1e-6 and float(rgb.min()) >= -1e-6
    assert float(rgb[~behind].max()) > 0.99


def test_a_view_weighted_k_is_the_view_taken_k_times():
    """Weight 2 on a view moves the colours as that view listed twice does (SART sums over views)."""
    vm, K = _cameras(3)
    target = torch.rand(3, SIZE, SIZE, 3, generator=torch.Generator().manual_seed(2))
    a, _ = _model()
    b, _ = _model()
    fit_colours(a, _views(target, vm, K), 2, backend="cpu", weights=[1.0, 2.0, 1.0])
    fit_colours(b, _views(target[[0, 1, 1, 2]], vm[[0, 1, 1, 2]], K), 2, backend="cpu")
    torch.testing.assert_close(a.sh_dc.detach(), b.sh_dc.detach(), rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="weights"):
        fit_colours(a, _views(target, vm, K), 1, weights=[1.0, 1.0])


def test_colours_may_pass_one_up_to_max_colour():
    """A target brighter than the Gaussians can reach: colours rise to max_colour and no further."""
    m, _ = _model()
    vm, K = _cameras(1)
    fit_colours(m, _views(torch.ones(1, SIZE, SIZE, 3) * 2.0, vm, K), 3, backend="cpu", max_colour=1.5)
    rgb = SH_C0 * m.sh_dc.detach()[:, 0, :] + 0.5
    assert float(rgb.max()) == pytest.approx(1.5, abs=1e-5) and float(rgb.min()) >= -1e-6


def test_polar_weights_pick_the_views_near_the_poles():
    from holoflow.recon.colour_fit import polar_weights

    dirs = [(0, -1, 0.1), (0, 0, 1), (0.3, 1, 0), (1, -0.6, 0)]  # zenith, horizon, nadir-ish, 31 deg up
    views = [dict(viewmat=look_at((0, 0, 0), d)) for d in dirs]
    assert polar_weights(views, 8.0) == [8.0, 1.0, 8.0, 1.0]
    assert polar_weights([], 8.0) == []


def test_viewing_views_keep_the_field_of_view():
    """Targets at another size than the view set's: the focal scales with the size (same field of
    view) and the images are the panorama's views through those cameras."""
    from holoflow.geometry.sampling import equirect_to_pinhole
    from holoflow.imageops.color import linear_to_srgb_torch

    g = torch.Generator().manual_seed(0)
    pano = torch.rand(3, 32, 64, generator=g)
    vm, _ = _cameras(2)
    cams = dict(
        width=16,
        height=16,
        fx=8.0,
        fy=8.0,
        cx=8.0,
        cy=8.0,
        views=[dict(name=f"{i:03d}", viewmat=v.flatten().tolist()) for i, v in enumerate(vm)],
    )
    views = viewing_views(pano, cams, 48)
    assert [v["name"] for v in views] == ["000", "001"]
    assert float(views[0]["K"][0, 0]) == pytest.approx(24.0) and float(views[0]["K"][0, 2]) == pytest.approx(24.0)
    want = equirect_to_pinhole(pano, views[1]["K"], vm[1], 48, 48, mode="antialias")[0]
    torch.testing.assert_close(views[1]["image"], linear_to_srgb_torch(want.permute(1, 2, 0)))


def test_the_fit_size_follows_p_f_s_width(tmp_path):
    """fit_size 0: a quarter of P_f's width from its pf.json (384 px at 1536, 512 at 2048), 384 px for a
    cloud without one; a size given is kept."""
    import json

    from holoflow.recon.optimize import cloud_fit_size

    assert cloud_fit_size(tmp_path, 0) == 384  # no pf.json: a cloud of the user's own
    for width, size in ((1536, 384), (2048, 512), (256, 64)):
        (tmp_path / "pf.json").write_text(json.dumps({"width": width, "spacing_rad": 6.283 / width}))
        assert cloud_fit_size(tmp_path, 0) == size
    assert cloud_fit_size(tmp_path, 200) == 200
