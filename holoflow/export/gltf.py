"""Binary glTF 2.0 (GLB) writing: Gaussians with ``KHR_gaussian_splatting``, and vertex-coloured meshes.

Both are written in glTF's frame, +Y up, right-handed, metres: holoflow's +y-down world goes through
``holoflow.export.splats.Y_UP`` = diag(1, -1, -1) (a 180 deg turn about x; the panorama's centre
then looks along -Z, a glTF camera's default direction).

KHR_gaussian_splatting (the ratified extension): a POINTS primitive with ``POSITION`` (VEC3 float),
``KHR_gaussian_splatting:ROTATION`` (VEC4 float, unit quaternion in glTF's (x, y, z, w) order),
``KHR_gaussian_splatting:SCALE`` (VEC3 float, LINEAR scale in metres), ``KHR_gaussian_splatting:OPACITY``
(SCALAR float, post-sigmoid, [0, 1]), ``KHR_gaussian_splatting:SH_DEGREE_0_COEF_0`` (VEC3 float, the SH DC
coefficient: rgb = 0.5 + SH_C0 * dc) and, for degree l > 0, ``..:SH_DEGREE_l_COEF_n`` (VEC3 float);
the extension object says kernel ``ellipse``, colour space ``srgb_rec709_display`` (3DGS colours are
display values), projection ``perspective``, sorting ``cameraDistance``.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from holoflow.export.splats import Y_UP, Splats, to_y_up

FLOAT, UNSIGNED_INT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
POINTS, TRIANGLES = 0, 4
_TYPES = {1: "SCALAR", 3: "VEC3", 4: "VEC4"}


class GlbBuilder:
    """Accumulates accessors over one binary buffer, then packs a GLB (header, JSON chunk, BIN chunk,
    each chunk 4-byte aligned: JSON padded with spaces, BIN with zeros)."""

    def __init__(self):
        self.blob = bytearray()
        self.gltf = {
            "asset": {"version": "2.0", "generator": "holoflow"},
            "buffers": [],
            "bufferViews": [],
            "accessors": [],
        }

    def accessor(self, data: np.ndarray, target: int | None = None, minmax: bool = False) -> int:
        """Add ``data`` [N] or [N, C] (float32 or uint32) as its own buffer view; its accessor index."""
        data = np.ascontiguousarray(data)
        ctype = FLOAT if data.dtype == np.float32 else UNSIGNED_INT if data.dtype == np.uint32 else None
        if ctype is None:
            raise TypeError(f"glb accessor: float32 or uint32 expected, got {data.dtype}")
        comps = 1 if data.ndim == 1 else data.shape[1]
        while len(self.blob) % 4:
            self.blob.append(0)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": data.nbytes}
        if target is not None:
            view["target"] = target
        self.blob += data.astype(data.dtype.newbyteorder("<")).tobytes()
        self.gltf["bufferViews"].append(view)
        acc = {
            "bufferView": len(self.gltf["bufferViews"]) - 1,
            "componentType": ctype,
            "count": int(data.shape[0]),
            "type": _TYPES[comps],
        }
        if minmax and len(data):
            flat = data.reshape(len(data), -1)
            acc["min"], acc["max"] = flat.min(0).tolist(), flat.max(0).tolist()
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1

    def glb(
        self, primitive: dict, extensions: list[str] = (), materials: list[dict] | None = None, name: str = "holoflow"
    ) -> bytes:
        """The GLB bytes of one scene -> one node -> one mesh holding ``primitive``."""
        g = dict(self.gltf)
        g.update(
            scene=0,
            scenes=[{"nodes": [0]}],
            nodes=[{"mesh": 0, "name": name}],
            meshes=[{"name": name, "primitives": [primitive]}],
        )
        g["buffers"] = [{"byteLength": len(self.blob)}]
        if extensions:
            g["extensionsUsed"] = list(extensions)
        if materials:
            g["materials"] = materials
        js = json.dumps(g, separators=(",", ":")).encode("utf-8")
        js += b" " * (-len(js) % 4)
        bin_ = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        total = 12 + 8 + len(js) + 8 + len(bin_)
        return (
            struct.pack("<III", 0x46546C67, 2, total)
            + struct.pack("<II", len(js), 0x4E4F534A)
            + js
            + struct.pack("<II", len(bin_), 0x004E4942)
            + bin_
        )


def gaussians_glb_bytes(s: Splats) -> bytes:
    """GLB of activated Gaussians with KHR_gaussian_splatting (module docstring), converted to +Y up."""
    s = to_y_up(s)
    b = GlbBuilder()
    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    attrs = {
        "POSITION": b.accessor(f32(s.means), ARRAY_BUFFER, minmax=True),
        "KHR_gaussian_splatting:ROTATION": b.accessor(f32(s.quats[:, [1, 2, 3, 0]]), ARRAY_BUFFER),
        "KHR_gaussian_splatting:SCALE": b.accessor(f32(s.scales), ARRAY_BUFFER),
        "KHR_gaussian_splatting:OPACITY": b.accessor(f32(s.opacities), ARRAY_BUFFER),
        "KHR_gaussian_splatting:SH_DEGREE_0_COEF_0": b.accessor(f32(s.sh_dc), ARRAY_BUFFER),
    }
    k = 0
    for degree in range(1, s.sh_degree + 1):
        for coef in range(2 * degree + 1):
            attrs[f"KHR_gaussian_splatting:SH_DEGREE_{degree}_COEF_{coef}"] = b.accessor(
                f32(s.sh_rest[:, k]), ARRAY_BUFFER
            )
            k += 1
    ext = {
        "kernel": "ellipse",
        "colorSpace": "srgb_rec709_display",
        "projection": "perspective",
        "sortingMethod": "cameraDistance",
    }
    primitive = {"mode": POINTS, "attributes": attrs, "extensions": {"KHR_gaussian_splatting": ext}}
    return b.glb(primitive, extensions=["KHR_gaussian_splatting"], name="gaussians")


def mesh_glb_bytes(vertices: np.ndarray, colors: np.ndarray, faces: np.ndarray) -> bytes:
    """GLB of a triangle mesh: vertices [V, 3] metres in holoflow's frame (converted to +Y up here),
    colors [V, 3] linear RGB in [0, 1] (glTF's COLOR_0 is linear; stored as float VEC3), faces [F, 3]
    vertex indices, counter-clockwise seen from the side a viewer should see (glTF's front face).
    The material is unlit (KHR_materials_unlit): the colours are the panorama's captured light."""
    b = GlbBuilder()
    attrs = {
        "POSITION": b.accessor(np.asarray(vertices @ Y_UP, np.float32), ARRAY_BUFFER, minmax=True),
        "COLOR_0": b.accessor(np.asarray(np.clip(colors, 0, 1), np.float32), ARRAY_BUFFER),
    }
    indices = b.accessor(np.asarray(faces, np.uint32).reshape(-1), ELEMENT_ARRAY_BUFFER)
    material = {
        "name": "vertex_colour_unlit",
        "doubleSided": False,
        "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extensions": {"KHR_materials_unlit": {}},
    }
    primitive = {"mode": TRIANGLES, "attributes": attrs, "indices": indices, "material": 0}
    return b.glb(primitive, extensions=["KHR_materials_unlit"], materials=[material], name="panorama_mesh")
