"""holoflow.export.mesh.panorama_mesh_glb: export's mesh.glb from a panorama and its radial depth."""

import numpy as np
import pytest

from holoflow.export.mesh import panorama_mesh_glb, rgbd_mesh


def _sphere(h: int, w: int, radius: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """rgb [h, w, 3] (a ramp along the columns, linear) and a constant radial depth [h, w] (metres)."""
    rgb = np.repeat(np.linspace(0.1, 0.9, w, dtype=np.float32)[None, :, None], h, 0).repeat(3, 2)
    return rgb, np.full((h, w), radius, np.float32)


def test_default_grid_is_half_the_depth_width_and_a_sphere_keeps_every_face():
    rgb, depth = _sphere(16, 32)
    data, info = panorama_mesh_glb(rgb, depth)
    h, w = 8, 16  # 0 = half the depth's width, P_f's resolution
    assert data[:4] == b"glTF"
    assert info == {"mesh_grid": [h, w], "mesh_vertices": h * w + 2, "mesh_faces": 2 * (h - 1) * w + 2 * w}


def test_an_explicit_width_resamples_colour_and_depth_to_it():
    rgb, depth = _sphere(16, 32)
    depth[:, :8] = np.inf  # a quarter of sky, put on the dome
    _, info = panorama_mesh_glb(rgb, depth, width=32, sky="omit")
    verts, _, faces = rgbd_mesh(rgb, depth, sky="omit")
    assert info == {"mesh_grid": [16, 32], "mesh_vertices": len(verts), "mesh_faces": len(faces)}


def test_all_sky_is_refused():
    rgb, depth = _sphere(8, 16, np.inf)
    with pytest.raises(ValueError, match="no finite positive pixel"):
        panorama_mesh_glb(rgb, depth)
