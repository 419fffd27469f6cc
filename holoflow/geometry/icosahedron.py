"""The 20 icosahedron tangent faces (gnomonic pinhole images) used for 360 depth estimation.

The icosahedron has a vertex at each pole (world up = -y, docs/conventions.md), five vertices at
latitude +atan(1/2) (longitudes 0, 72, ... deg) and five at -atan(1/2) (longitudes 36, 108, ...).
Faces 0-4 touch the north pole, 5-9 are the upper middle band, 10-14 the lower band, 15-19 touch the
south pole. Each face is a pinhole camera at the origin looking at the face centre with world-up
roll (look_at), so every triangle is upright: apex up (faces 0-4, 10-14) or down (5-9, 15-19).

Padding (360MonoDepth's convention): in the gnomonic plane tangent at the face centre each edge of
the triangle is pushed outward by ``padding`` units (tan of the angle from the centre); the image is
the bounding box of that padded triangle, ``size`` x ``size`` pixels, so fx != fy in general. With
the default 0.3 a face sees about 99 deg (across) x 88 deg (along the apex axis).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from holoflow.geometry.camera import intrinsics, look_at, pinhole_rays

NUM_FACES = 20


@dataclass
class TangentFaces:
    """Cameras of the 20 tangent images: K [20, 3, 3], viewmat [20, 4, 4] (world-to-camera, at the
    origin), centers [20, 3] (unit face-centre directions = optical axes), vertices [20, 3, 3] (unit
    corner directions per face), size (pixels, square image), padding (gnomonic units)."""

    K: torch.Tensor
    viewmat: torch.Tensor
    centers: torch.Tensor
    vertices: torch.Tensor
    size: int
    padding: float


def icosahedron(device=None, dtype=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit vertices [12, 3] and faces [20, 3] (vertex indices) in the layout of the module docstring."""
    dtype = dtype or torch.get_default_dtype()
    lat = math.atan(0.5)
    verts = [(0.0, -1.0, 0.0)]
    for ring, (la, lon0) in enumerate([(lat, 0.0), (-lat, 36.0)]):
        for i in range(5):
            lon = math.radians(lon0 + 72.0 * i)
            verts.append((math.cos(la) * math.sin(lon), -math.sin(la), math.cos(la) * math.cos(lon)))
    verts.append((0.0, 1.0, 0.0))
    up = [1 + i for i in range(5)]
    lo = [6 + i for i in range(5)]
    faces = (
        [(0, up[i], up[(i + 1) % 5]) for i in range(5)]
        + [(up[i], up[(i + 1) % 5], lo[i]) for i in range(5)]
        + [(lo[i], lo[(i + 1) % 5], up[(i + 1) % 5]) for i in range(5)]
        + [(11, lo[i], lo[(i + 1) % 5]) for i in range(5)]
    )
    return (
        torch.tensor(verts, device=device, dtype=torch.float64).to(dtype),
        torch.tensor(faces, device=device, dtype=torch.long),
    )


def tangent_faces(padding: float = 0.3, size: int = 256, device=None, dtype=None) -> TangentFaces:
    """The 20 tangent-face cameras (module docstring) for ``size`` x ``size`` images."""
    if padding < 0 or size < 1:
        raise ValueError(f"tangent_faces: need padding >= 0 and size >= 1, got {padding}, {size}")
    dtype = dtype or torch.get_default_dtype()
    verts, faces = icosahedron(device=device, dtype=torch.float64)
    corners = verts[faces]  # [20, 3, 3]
    centers = corners.sum(1)
    centers = centers / torch.linalg.vector_norm(centers, dim=-1, keepdim=True)
    viewmat = look_at(torch.zeros_like(centers), centers)  # [20, 4, 4]
    cam = torch.einsum("fij,fkj->fki", viewmat[:, :3, :3], corners)  # [20, 3, 3] corners in camera
    gnom = cam[..., :2] / cam[..., 2:]  # [20, 3, 2] triangle in the tangent plane, centred at 0
    inradius = 0.5 * torch.linalg.vector_norm(gnom, dim=-1).mean(-1, keepdim=True)  # [20, 1]
    padded = gnom * ((inradius + padding) / inradius)[..., None]  # edges pushed out by ``padding``
    lo, hi = padded.amin(1), padded.amax(1)  # [20, 2]
    fx, fy = size / (hi[:, 0] - lo[:, 0]), size / (hi[:, 1] - lo[:, 1])
    K = intrinsics(fx, fy, -lo[:, 0] * fx, -lo[:, 1] * fy, device=device, dtype=torch.float64)
    return TangentFaces(
        K=K.to(dtype),
        viewmat=viewmat.to(dtype),
        centers=centers.to(dtype),
        vertices=corners.to(dtype),
        size=size,
        padding=padding,
    )


def face_of_direction(dirs: torch.Tensor, centers: torch.Tensor | None = None) -> torch.Tensor:
    """Index [...] of the face whose spherical triangle holds each direction [..., 3].

    The triangles are the Voronoi cells of the face centres, so this is the nearest centre: every
    direction belongs to exactly one face (ties on an edge go to the lower index)."""
    if centers is None:
        centers = tangent_faces(size=1, device=dirs.device, dtype=dirs.dtype).centers
    return torch.argmax(dirs @ centers.to(dirs.dtype).T, dim=-1)


def equirect_face_index(height: int, width: int, device=None) -> torch.Tensor:
    """For each equirect pixel [H, W], the face (0..19) whose triangle owns it."""
    from holoflow.geometry.sphere import equirect_directions

    return face_of_direction(equirect_directions(height, width, device=device, dtype=torch.float64))


def triangle_mask(faces: TangentFaces) -> torch.Tensor:
    """[20, size, size] bool: pixels whose ray lies in the face's own (unpadded) triangle."""
    _, dirs = pinhole_rays(faces.K, faces.viewmat, faces.size, faces.size)  # [20, s, s, 3]
    own = face_of_direction(dirs, faces.centers)
    return own == torch.arange(NUM_FACES, device=own.device)[:, None, None]


def frustum_weight(faces: TangentFaces, ramp: float = 0.5) -> torch.Tensor:
    """Blending weight [20, size, size]: 1 in the middle of the image, falling smoothly (smoothstep)
    to 0 at the border over the outer ``ramp`` of the half-size (0 < ramp <= 1)."""
    if not 0 < ramp <= 1:
        raise ValueError(f"frustum_weight: ramp must be in (0, 1], got {ramp}")
    s = faces.size
    t = (torch.arange(s, device=faces.K.device, dtype=faces.K.dtype) + 0.5) * (2.0 / s) - 1.0  # [s] in (-1, 1)
    edge = 1.0 - torch.maximum(t.abs()[:, None], t.abs()[None, :])  # [s, s] distance to the border
    a = (edge / ramp).clamp(0, 1)
    w = a * a * (3 - 2 * a)
    return w.expand(NUM_FACES, s, s).clone()
