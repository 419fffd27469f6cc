"""The PCD set: P_s seen by the supplementary cameras through a z-buffer (HoloDreamer's Pre Optimization
input; stages/pcd_set.py writes it, docs/reconstruction.md explains each choice).

For every base camera, four supplementary cameras (above, below, left, right; ``supplementary_rig``)
are moved by ``offset`` x that base view's median scene depth and turned ``angle_deg`` back towards the
base view's axis. The median is over the geometry only (``solid_points_mask``: not the far sky
shell), so an outdoor view's offset follows its ground and objects. P_s is projected into each with a
z-buffer, nearest point wins, each point covering (2 R - 1)^2 pixels (R = ``splat_radius``, or with 0
each point's own footprint, from P_s's angular step 2 pi / width, width = sqrt(2 N)). Points on
occlusion edges (relative depth gradient over ``edge_threshold``; 0 = keep all) leave the image, since
P_s's edge points are the depth-mixed "rubber sheet" between an object and what lies behind it, but
still count in ``seen`` (1 where any point landed): that test also flags grazing surfaces, which must
not be inpainted.

Tensors: points [N, 3] float64 metres (world = the panorama's OpenCV frame), colours [N, 3] linear,
K [3, 3], viewmats [V, 4, 4] world-to-camera; images [H, W, 3] linear, masks [H, W] in {0, 1}.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from holoflow.geometry.config import PcdSetParams
from holoflow.geometry.pointcloud import depth_gradient, footprint_radius, project_points_zbuffer, solid_points_mask
from holoflow.geometry.rigs import supplementary_rig


@dataclass
class PcdSet:
    """P_s ready to project: ``points`` / ``linear`` [P, 3] the non-edge points and their linear colour,
    ``edge_points`` [E, 3] (coverage only), ``viewmats`` [4 M, 4, 4] the supplementary cameras (view
    4 b + k: base b, side k = above, below, left, right), ``medians`` [M] each base view's median
    geometry depth (m), ``K``, ``width`` x ``height`` px, ``spacing`` P_s's angular step (rad) and
    ``splat_radius`` (0 = footprint)."""

    points: torch.Tensor
    linear: torch.Tensor
    edge_points: torch.Tensor
    viewmats: torch.Tensor
    medians: list[float]
    K: torch.Tensor
    width: int
    height: int
    spacing: float
    splat_radius: int

    def radii(self, viewmat: torch.Tensor, points: torch.Tensor):
        """z-buffer splat radius in px: the fixed one, or each point's footprint [P] at ``viewmat``."""
        return self.splat_radius if self.splat_radius > 0 else footprint_radius(points, viewmat, self.K, self.spacing)

    def view(self, j: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Supplementary view ``j``: (image [H, W, 3] linear, hit [H, W]: a non-edge point landed (the loss
        mask A), seen [H, W]: any point of P_s landed)."""
        V = self.viewmats[j]
        img, hit, _ = project_points_zbuffer(
            self.points, self.linear, self.K, V, self.height, self.width, self.radii(V, self.points)
        )
        seen = hit
        if len(self.edge_points):
            _, edge_hit, _ = project_points_zbuffer(
                self.edge_points,
                self.edge_points[:, :0],
                self.K,
                V,
                self.height,
                self.width,
                self.radii(V, self.edge_points),
            )
            seen = torch.maximum(hit, edge_hit)
        return img, hit, seen


def split_edge_points(points: torch.Tensor, edge_threshold: float) -> torch.Tensor:
    """Keep mask [N] of P_s's points off occlusion edges: relative depth gradient <= ``edge_threshold``
    on P_s's full equirect grid (row-major, width = sqrt(2 N)); all True for a threshold of 0."""
    if edge_threshold <= 0:
        return torch.ones(len(points), dtype=torch.bool, device=points.device)
    w = int(round(math.sqrt(2 * len(points))))
    if w * (w // 2) != len(points):
        raise ValueError(f"ps.ply: {len(points)} points are not a full equirect grid (edge_threshold needs one)")
    grad = depth_gradient(torch.linalg.vector_norm(points, dim=-1).reshape(w // 2, w))  # [H, W]
    return (torch.nan_to_num(grad, nan=float("inf")) <= edge_threshold).reshape(-1)


def median_view_depths(
    points: torch.Tensor, K: torch.Tensor, viewmats: torch.Tensor, width: int, height: int, radii
) -> list[float]:
    """Per base view [M], the median z (m) of the geometry (not the sky shell) its z-buffer keeps;
    the median radius of the geometry for a view that sees none. ``radii(viewmat, points)``."""
    solid = solid_points_mask(points)
    geo = points[solid]  # [G, 3]
    out = []
    for V in viewmats:
        _, hit, z = project_points_zbuffer(geo, geo[:, :0], K, V, height, width, radii(V, geo))
        zs = z[hit > 0]
        out.append(float(zs.median()) if zs.numel() else float(torch.linalg.vector_norm(geo, dim=-1).median()))
    return out


def pcd_set(
    points: torch.Tensor,
    linear: torch.Tensor,
    K: torch.Tensor,
    base_viewmats: torch.Tensor,
    width: int,
    height: int,
    cfg: PcdSetParams,
) -> PcdSet:
    """The PCD set of P_s (``points`` [N, 3], ``linear`` colours [N, 3]) around ``base_viewmats`` [M, 4, 4]
    (intrinsics ``K``, ``width`` x ``height`` px), with pcd_set's ``cfg``; see the module docstring."""
    if len(points) == 0:
        raise ValueError("ps.ply holds no points")
    keep = split_edge_points(points, cfg.edge_threshold)
    spacing = 2.0 * math.pi / math.sqrt(2.0 * len(points))  # P_s's angular step, radians
    pcd = PcdSet(
        points[keep], linear[keep], points[~keep], base_viewmats, [], K, width, height, spacing, cfg.splat_radius
    )
    pcd.medians = median_view_depths(pcd.points, K, base_viewmats, width, height, pcd.radii)
    medians = torch.tensor(pcd.medians, dtype=torch.float64, device=points.device)
    pcd.viewmats = supplementary_rig(base_viewmats, medians, cfg.offset, cfg.angle_deg)  # [4 M, 4, 4]
    return pcd
