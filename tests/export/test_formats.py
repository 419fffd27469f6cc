"""Exports read back by independent readers (gsply, trimesh, pygltflib; .splat by a numpy parser of
the published 32-byte layout), with stated error bounds, and the axis change of +Y-up formats checked
on Gaussians placed forward / up / right in holoflow's frame (+x right, +y down, +z forward).

Bounds (from each format's quantisation; rgb = 0.5 + SH_C0 * f_dc, opacity post-sigmoid):
| format | position | colour (rgb) | opacity |
|---|---|---|---|
| scene.spz | 0.5 / 2^12 m (12 fractional bits) | 0.5 * SH_C0 / (0.15 * 255) = 0.0037 | 0.5 / 255 |
| scene.splat | float32 (1e-6 relative) | 0.5 / 255 | 0.5 / 255 |
| scene.compressed.ply | 0.5 / 1023 of its chunk's extent | 0.5 / 255 of its chunk's colour range | 0.5 / 255 |
| scene.glb | float32 | float32 | float32 |
"""

import numpy as np
import pytest
import torch

from holoflow.export.config import ExportParams
from holoflow.export.gltf import gaussians_glb_bytes, mesh_glb_bytes
from holoflow.export.mesh import rgbd_mesh
from holoflow.export.splats import (
    SH_C0,
    SH_FLIP,
    SPLAT_DTYPE,
    Y_UP,
    activate,
    compressed_ply_bytes,
    splat_bytes,
    spz_bytes,
)
from holoflow.flow.params import ParamError
from holoflow.splat.project import eval_sh, quat_to_rotmat

gsply = pytest.importorskip("gsply")
trimesh = pytest.importorskip("trimesh")
pygltflib = pytest.importorskip("pygltflib")

F = Y_UP  # holoflow -> +Y up (SPZ's RUB, glTF)


def scene_fields(n: int = 1000, sh_degree: int = 0, seed: int = 0) -> dict:
    """A 3DGS PLY's fields (before activation): a room-sized cloud with the hard cases in front:
    a zero quaternion, opacity saturated at 0 and 1, tiny and large scales."""
    rng = np.random.default_rng(seed)
    k = (sh_degree + 1) ** 2 - 1
    f = {c: rng.uniform(-4, 4, n) for c in "xyz"}
    f.update({f"f_dc_{i}": rng.uniform(-1.7, 1.7, n) for i in range(3)})  # rgb in [0.02, 0.98]
    f.update({f"f_rest_{i}": rng.uniform(-0.4, 0.4, n) for i in range(3 * k)})
    f["opacity"] = rng.uniform(-5, 5, n)
    f.update({f"scale_{i}": rng.uniform(-6, 0, n) for i in range(3)})
    f.update({f"rot_{i}": rng.normal(size=n) for i in range(4)})
    if n >= 5:
        for i in range(4):
            f[f"rot_{i}"][0] = 0.0  # zero quaternion -> identity
        f["opacity"][1], f["opacity"][2] = -30.0, 30.0  # saturated
        for i in range(3):
            f[f"scale_{i}"][3], f[f"scale_{i}"][4] = -9.5, 1.5
    return {key: np.asarray(v, np.float32) for key, v in f.items()}


def read_splat(data: bytes) -> dict:
    """The antimatter15 layout, parsed from its description (not from holoflow's writer)."""
    rec = np.frombuffer(data, SPLAT_DTYPE)
    q = (rec["rotation"].astype(np.float64) - 128.0) / 128.0
    return {
        "means": rec["position"].astype(np.float64),
        "scales": rec["scale"].astype(np.float64),
        "rgb": rec["rgba"][:, :3] / 255.0,
        "opacity": rec["rgba"][:, 3] / 255.0,
        "quats": q / np.linalg.norm(q, axis=1, keepdims=True),
    }


def match(ref: np.ndarray, got: np.ndarray) -> np.ndarray:
    """Index into ``got`` for each row of ``ref`` (formats may reorder Gaussians): nearest position."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(got).query(ref)
    assert len(set(idx.tolist())) == len(ref), "positions do not match one to one"
    return idx


def cov(quats_wxyz: np.ndarray, scales: np.ndarray) -> np.ndarray:
    R = quat_to_rotmat(torch.from_numpy(quats_wxyz)).numpy()
    return R @ (scales[:, :, None] ** 2 * np.eye(3)) @ R.transpose(0, 2, 1)


def sig(x):
    return 1.0 / (1.0 + np.exp(-x))


@pytest.fixture(scope="module")
def ref():
    return activate(scene_fields())


def test_activate_conventions(ref):
    f = scene_fields()
    np.testing.assert_allclose(ref.scales[:, 0], np.exp(f["scale_0"]), rtol=1e-6)
    np.testing.assert_allclose(ref.opacities, sig(f["opacity"].astype(np.float64)), atol=1e-12)
    np.testing.assert_allclose(ref.rgb[:, 0], 0.5 + SH_C0 * f["f_dc_0"], atol=1e-7)
    assert np.allclose(ref.quats[0], [1, 0, 0, 0]) and np.allclose(np.linalg.norm(ref.quats, axis=1), 1)
    bad = dict(f, x=f["x"].copy())
    bad["x"][5] = np.nan
    with pytest.raises(ValueError, match="non-finite position"):
        activate(bad)


def test_spz_round_trip_through_gsply(ref, tmp_path):
    (tmp_path / "s.spz").write_bytes(spz_bytes(ref))
    g = gsply.read_spz(tmp_path / "s.spz")
    means = np.asarray(g.means, np.float64)
    np.testing.assert_array_less(np.abs(means - ref.means @ F), 0.5 / 2**12 + 1e-6)  # RUB axes
    rgb = 0.5 + SH_C0 * np.asarray(g.sh0, np.float64)
    assert np.abs(rgb - ref.rgb).max() <= 0.5 * SH_C0 / (0.15 * 255) + 1e-6
    assert np.abs(sig(np.asarray(g.opacities, np.float64)) - ref.opacities).max() <= 0.5 / 255 + 1e-4
    inside = (np.log(ref.scales) > -10) & (np.log(ref.scales) < 5.9)
    assert np.abs(np.asarray(g.scales)[inside] - np.log(ref.scales)[inside]).max() <= 0.5 / 16 + 1e-5
    q = np.asarray(g.quats, np.float64)  # (w, x, y, z)
    want = ref.quats * [1, 1, -1, -1]
    assert np.abs(np.abs((q * want).sum(1))).min() > 0.998  # same rotation up to sign


def test_spz_is_deterministic(ref):
    assert spz_bytes(ref) == spz_bytes(ref)


def test_splat_round_trip(ref):
    got = read_splat(splat_bytes(ref))
    assert len(got["means"]) == len(ref)
    idx = match(ref.means, got["means"])
    np.testing.assert_allclose(got["means"][idx], ref.means, rtol=1e-6, atol=1e-6)  # holoflow's frame
    np.testing.assert_allclose(got["scales"][idx], ref.scales, rtol=1e-6)
    assert np.abs(got["rgb"][idx] - np.clip(ref.rgb, 0, 1)).max() <= 0.5 / 255 + 1e-9
    assert np.abs(got["opacity"][idx] - ref.opacities).max() <= 0.5 / 255 + 1e-9
    assert np.abs((got["quats"][idx] * ref.quats).sum(1)).min() > 0.995
    size = np.prod(got["scales"], 1) * got["opacity"]
    assert size[0] >= size[-1]  # largest first


def test_compressed_ply_round_trip_through_gsply(ref, tmp_path):
    (tmp_path / "s.compressed.ply").write_bytes(compressed_ply_bytes(ref))
    g = gsply.plyread(str(tmp_path / "s.compressed.ply"))
    means = np.asarray(g.means, np.float64)
    idx = match(ref.means, means)
    extent = ref.means.max(0) - ref.means.min(0)
    err = np.abs(means[idx] - ref.means)
    assert (err <= 0.5 * extent / 1023 + 1e-5).all()  # a chunk's extent <= the scene's
    assert err.mean() < 0.01 * extent.max() / 1023 * 50  # chunks are far tighter than the scene
    rgb = 0.5 + SH_C0 * np.asarray(g.sh0, np.float64)[idx]
    assert np.abs(rgb - ref.rgb).max() <= 0.5 / 255 + 1e-5
    op = sig(np.asarray(g.opacities, np.float64)[idx])
    assert np.abs(op - ref.opacities).max() <= 0.5 / 255 + 1e-4
    q = np.asarray(g.quats, np.float64)[idx]
    assert np.abs((q * ref.quats).sum(1)).min() > 0.998
    log_range = np.ptp(np.log(ref.scales), axis=0)  # >= any chunk's
    assert (np.abs(np.asarray(g.scales)[idx] - np.log(ref.scales)) <= 0.5 * log_range / 1023 + 1e-4).all()


def test_gaussian_glb_round_trip_through_pygltflib(ref, tmp_path):
    (tmp_path / "s.glb").write_bytes(gaussians_glb_bytes(ref))
    gl = pygltflib.GLTF2().load(str(tmp_path / "s.glb"))
    assert "KHR_gaussian_splatting" in gl.extensionsUsed
    prim = gl.meshes[0].primitives[0]
    assert prim.mode == 0 and prim.extensions["KHR_gaussian_splatting"]["kernel"] == "ellipse"
    a = gltf_attributes(gl)
    np.testing.assert_allclose(a["POSITION"], ref.means @ F, atol=1e-6)  # +Y up
    np.testing.assert_allclose(a["KHR_gaussian_splatting:SCALE"], ref.scales, rtol=1e-6)  # linear
    np.testing.assert_allclose(a["KHR_gaussian_splatting:OPACITY"], ref.opacities, atol=1e-7)
    np.testing.assert_allclose(0.5 + SH_C0 * a["KHR_gaussian_splatting:SH_DEGREE_0_COEF_0"], ref.rgb, atol=1e-6)
    xyzw = a["KHR_gaussian_splatting:ROTATION"]
    np.testing.assert_allclose(
        cov(xyzw[:, [3, 0, 1, 2]], a["KHR_gaussian_splatting:SCALE"]), F @ cov(ref.quats, ref.scales) @ F, atol=1e-5
    )


def gltf_attributes(gl) -> dict:
    """Every accessor of the first primitive, decoded from the binary blob with pygltflib's records."""
    blob = gl.binary_blob()
    out = {}
    prim = gl.meshes[0].primitives[0]
    names = {k: v for k, v in vars(prim.attributes).items() if isinstance(v, int)}
    for name, index in names.items():
        acc = gl.accessors[index]
        view = gl.bufferViews[acc.bufferView]
        comps = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
        dt = {5126: "<f4", 5125: "<u4"}[acc.componentType]
        arr = np.frombuffer(blob, dt, acc.count * comps, view.byteOffset + (acc.byteOffset or 0))
        out[name] = (
            arr.reshape(acc.count, comps).squeeze(-1).astype(np.float64)
            if comps == 1
            else arr.reshape(acc.count, comps).astype(np.float64)
        )
    return out


def test_axes_forward_up_right(tmp_path):
    """Gaussians at +z (forward), -y (up), +x (right) in holoflow's frame: SPZ (RUB) and glTF (+Y up)
    put them at -Z, +Y, +X; a Gaussian long along holoflow's up is long along their +Y; .splat and
    the compressed PLY keep holoflow's frame."""
    pos = np.array([[0, 0, 5.0], [0, -2.0, 0], [3.0, 0, 0]])
    f = scene_fields(3)
    for i, c in enumerate("xyz"):
        f[c] = pos[:, i].astype(np.float32)
    for i, v in enumerate(np.log([0.05, 1.0, 0.05])):  # long along the local y axis
        f[f"scale_{i}"] = np.full(3, v, np.float32)
    for i, v in enumerate([1.0, 0, 0, 0]):  # identity: long along holoflow's y
        f[f"rot_{i}"] = np.full(3, v, np.float32)
    s = activate(f)
    want = np.array([[0, 0, -5.0], [0, 2.0, 0], [3.0, 0, 0]])
    (tmp_path / "a.spz").write_bytes(spz_bytes(s))
    g = gsply.read_spz(tmp_path / "a.spz")
    np.testing.assert_allclose(g.means, want, atol=1e-3)
    (tmp_path / "a.glb").write_bytes(gaussians_glb_bytes(s))
    a = gltf_attributes(pygltflib.GLTF2().load(str(tmp_path / "a.glb")))
    np.testing.assert_allclose(a["POSITION"], want, atol=1e-6)
    for q_wxyz, sc in (
        (np.asarray(g.quats, np.float64), np.exp(np.asarray(g.scales, np.float64))),
        (a["KHR_gaussian_splatting:ROTATION"][:, [3, 0, 1, 2]], a["KHR_gaussian_splatting:SCALE"]),
    ):
        long_axis = np.linalg.eigh(cov(q_wxyz, sc))[1][:, :, -1]  # [3, 3] principal direction
        np.testing.assert_allclose(np.abs(long_axis[:, 1]), 1.0, atol=1e-2)
    splat_means = read_splat(splat_bytes(s))["means"]
    np.testing.assert_allclose(splat_means[match(pos, splat_means)], pos, atol=1e-6)
    g2 = gsply.plyread(_write(tmp_path / "a.compressed.ply", compressed_ply_bytes(s)))
    np.testing.assert_allclose(np.asarray(g2.means)[match(pos, np.asarray(g2.means, np.float64))], pos, atol=1e-2)


def _write(path, data):
    path.write_bytes(data)
    return str(path)


def test_sh_rotates_with_the_axes(tmp_path):
    """Degree-3 SH: the +Y-up coefficients seen along F d give the colour the original gives along d."""
    s = activate(scene_fields(200, sh_degree=3, seed=1))
    d = np.random.default_rng(2).normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sh = np.concatenate([s.sh_dc[:, None], s.sh_rest], 1)
    want = eval_sh(torch.from_numpy(sh), torch.from_numpy(d)).numpy()
    flipped = np.concatenate([s.sh_dc[:, None], s.sh_rest * SH_FLIP[:, None]], 1)
    got = eval_sh(torch.from_numpy(flipped), torch.from_numpy(d @ F)).numpy()
    np.testing.assert_allclose(got, want, atol=1e-12)
    (tmp_path / "h.glb").write_bytes(gaussians_glb_bytes(s))
    a = gltf_attributes(pygltflib.GLTF2().load(str(tmp_path / "h.glb")))
    np.testing.assert_allclose(
        a["KHR_gaussian_splatting:SH_DEGREE_3_COEF_6"], s.sh_rest[:, 14] * SH_FLIP[14], atol=1e-7
    )
    (tmp_path / "h.spz").write_bytes(spz_bytes(s))
    g = gsply.read_spz(tmp_path / "h.spz")
    assert np.abs(np.asarray(g.shN, np.float64) - s.sh_rest * SH_FLIP[:, None]).max() <= 0.5 / 128 + 1e-6
    (tmp_path / "h.compressed.ply").write_bytes(compressed_ply_bytes(s))
    g2 = gsply.plyread(str(tmp_path / "h.compressed.ply"))
    idx = match(s.means, np.asarray(g2.means, np.float64))
    assert np.abs(np.asarray(g2.shN, np.float64)[idx] - s.sh_rest).max() <= 0.5 / 32 + 1e-6


# -- mesh.glb ---------------------------------------------------------------------------------------
def box_room(H=64, W=128, sky_rows=8):
    """An equirect RGB-D of a 4 x 3 x 6 m box (camera 1.5 m above the floor) with a 0.5 m ball 2 m
    ahead, the top ``sky_rows`` rows sky (+inf); colour = a function of the direction."""
    from holoflow.geometry.sphere import equirect_directions

    d = equirect_directions(H, W, dtype=torch.float64).numpy()
    half = np.array([2.0, 1.5, 3.0])
    t = np.min(np.where(np.abs(d) > 1e-9, half / np.maximum(np.abs(d), 1e-9), np.inf), axis=-1)
    c = np.array([0, 0, 2.0])
    b = d @ c
    disc = b**2 - (c @ c - 0.25)
    tb = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
    t = np.minimum(t, tb)
    t[:sky_rows] = np.inf
    rgb = 0.5 + 0.5 * d
    return rgb, t


def test_mesh_cuts_discontinuities_and_faces_the_centre():
    rgb, depth = box_room()
    v, c, f = rgbd_mesh(rgb, depth, edge_threshold=0.4, sky="dome")
    a, b, cc = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, cc - a), a + b + cc) < 0
    assert inward.mean() > 0.99
    r = np.linalg.norm(v, axis=1)
    spread = np.ptp(r[f], axis=1) / r[f].min(1)
    assert spread.max() <= 0.4 + 1e-9  # no triangle bridges the ball and the wall
    assert (r > 6).any()  # the dome (2x the 99th percentile depth)
    v2, _, f2 = rgbd_mesh(rgb, depth, sky="omit")
    assert np.linalg.norm(v2, axis=1).max() < 5 and len(f2) < len(f)
    # the ball's silhouette is open: some triangles were cut between it and the wall behind
    v3, _, f3 = rgbd_mesh(rgb, depth, edge_threshold=100.0, sky="omit")
    assert len(f3) > len(f2)


def test_mesh_glb_opens_in_trimesh_with_axes_and_colours(tmp_path):
    rgb, depth = box_room()
    v, c, f = rgbd_mesh(rgb, depth, sky="omit")
    (tmp_path / "mesh.glb").write_bytes(mesh_glb_bytes(v, c, f))
    scene = trimesh.load(str(tmp_path / "mesh.glb"), process=False)
    (m,) = scene.geometry.values()
    np.testing.assert_allclose(scene.graph[scene.graph.nodes_geometry[0]][0], np.eye(4))  # no node transform
    assert len(m.faces) == len(f) and len(m.vertices) == len(v)
    np.testing.assert_allclose(m.vertices, v @ F, atol=1e-5)  # +Y up
    # with a material trimesh keeps COLOR_0 as a vertex attribute (floats, linear as written)
    colours = np.asarray(m.visual.vertex_attributes["color"], np.float64)[:, :3]
    np.testing.assert_allclose(colours, np.clip(c, 0, 1), atol=1e-6)
    unit = v / np.linalg.norm(v, axis=1, keepdims=True)
    ahead = m.vertices[np.argmax(unit[:, 2])]  # holoflow's forward: the ball
    assert ahead[2] < -1 and abs(ahead[1]) < 0.2 and abs(ahead[0]) < 0.2
    floor = m.vertices[np.argmax(unit[:, 1])]  # holoflow's down
    assert floor[1] < -1 and abs(floor[0]) < 0.2 and abs(floor[2]) < 0.2
    gl = pygltflib.GLTF2().load(str(tmp_path / "mesh.glb"))
    assert gl.meshes[0].primitives[0].mode == 4 and "KHR_materials_unlit" in gl.extensionsUsed


def test_mesh_rejects_all_sky():
    with pytest.raises(ValueError, match="no finite"):
        rgbd_mesh(np.zeros((4, 8, 3)), np.full((4, 8), np.inf))


def test_formats_param_is_checked_and_canonical():
    assert ExportParams.from_params({"formats": "mesh, spz"}).formats == "spz,mesh"
    assert ExportParams.from_params({"formats": "glb,spz,splat,mesh,compressed_ply"}).formats == "all"
    assert ExportParams().format_list == ["spz", "splat", "compressed_ply", "glb", "mesh"]
    with pytest.raises(ParamError, match="unknown format ply"):
        ExportParams.from_params({"formats": "spz,ply"})
