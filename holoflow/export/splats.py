"""Gaussian-splat exchange formats: SPZ, antimatter15 ``.splat``, PlayCanvas compressed PLY.

Input is a 3DGS PLY's fields as :func:`holoflow.io.ply.read_gaussians` returns them (values before
activation, docs/conventions.md); :func:`activate` turns them into :class:`Splats` (linear scales,
unit (w, x, y, z) quaternions, opacity in (0, 1), SH DC and higher bands as stored).

Axes. holoflow's world is the OpenCV frame of the panorama centre: +x right, +y down, +z forward
("RDF"). Formats that say they are +Y up (SPZ: "RUB", right-up-back; glTF: +Y up, right-handed) get
``F = diag(1, -1, -1)``, a 180 deg turn about x (det +1, so nothing is mirrored): a point p -> F p;
a rotation R -> F R F, i.e. quaternion (w, x, y, z) -> (w, x, -y, -z); scales unchanged; each SH
coefficient's basis polynomial changes sign with its parity in (y, z) (:data:`SH_FLIP`). The
panorama's centre (+z) then looks along -Z, which is where a glTF camera and SPZ's "back" convention
look. ``.splat`` and the compressed PLY carry no axis convention of their own: their viewers treat
them like the INRIA PLY, so they keep holoflow's frame, as ``scene.ply`` does.

Colour. 3DGS colour is ``rgb = 0.5 + SH_C0 * f_dc``: sRGB display values (docs/conventions.md);
every format here stores those, quantised as it specifies.
"""

from __future__ import annotations

import gzip
import struct
from dataclasses import dataclass, replace

import numpy as np

SH_C0 = 0.28209479177387814

#: holoflow (x right, y down, z forward) -> +Y up (x right, y up, z back): SPZ's RUB and glTF
Y_UP = np.diag([1.0, -1.0, -1.0])

#: sign of SH coefficient 1..15 (3DGS order) under (x, y, z) -> (x, -y, -z): degree 1 (y, z, x),
#: degree 2 (xy, yz, 3z^2-1, xz, x^2-y^2), degree 3 (y(3x^2-y^2), xyz, y(4z^2-x^2-y^2),
#: z(2z^2-3x^2-3y^2), x(4z^2-x^2-y^2), z(x^2-y^2), x(x^2-3y^2))
SH_FLIP = np.array([-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1], dtype=np.float64)


@dataclass
class Splats:
    """Activated Gaussians (float64 numpy):
    means [N, 3] metres; scales [N, 3] metres (linear, > 0); quats [N, 4] unit (w, x, y, z);
    opacities [N] in (0, 1); sh_dc [N, 3] (rgb = 0.5 + SH_C0 * sh_dc, sRGB display values);
    sh_rest [N, K - 1, 3], K = (sh_degree + 1)^2, coefficient-major (3DGS order)."""

    means: np.ndarray
    scales: np.ndarray
    quats: np.ndarray
    opacities: np.ndarray
    sh_dc: np.ndarray
    sh_rest: np.ndarray

    @property
    def sh_degree(self) -> int:
        return int(round((self.sh_rest.shape[1] + 1) ** 0.5)) - 1

    @property
    def rgb(self) -> np.ndarray:
        """[N, 3] sRGB display colour of the SH DC term (may leave [0, 1] slightly)."""
        return 0.5 + SH_C0 * self.sh_dc

    def __len__(self) -> int:
        return self.means.shape[0]

    def subset(self, index: np.ndarray) -> "Splats":
        return Splats(*(getattr(self, k)[index] for k in ("means", "scales", "quats", "opacities", "sh_dc", "sh_rest")))


def activate(fields: dict[str, np.ndarray]) -> Splats:
    """:class:`Splats` from a 3DGS PLY's fields (read_gaussians: opacity logit, log scale, f_dc,
    f_rest channel-major, rot (w, x, y, z) not necessarily unit). A zero quaternion becomes the
    identity; a non-finite value raises ValueError (an export must not hide a broken scene)."""
    col = lambda names: np.stack([np.asarray(fields[k], np.float64) for k in names], 1)  # noqa: E731
    n = len(fields["x"])
    n_rest = sum(1 for k in fields if k.startswith("f_rest_"))
    K = n_rest // 3 + 1
    if n_rest % 3 or int(round(K**0.5)) ** 2 != K or K > 16:
        raise ValueError(f"{n_rest} f_rest values do not form SH bands of degree <= 3")
    means = col("xyz")
    log_scales = col([f"scale_{i}" for i in range(3)])
    quats = col([f"rot_{i}" for i in range(4)])
    logits = np.asarray(fields["opacity"], np.float64)
    dc = col([f"f_dc_{i}" for i in range(3)])
    rest = col([f"f_rest_{i}" for i in range(n_rest)]) if n_rest else np.zeros((n, 0))
    for name, a in (
        ("position", means),
        ("scale", log_scales),
        ("rotation", quats),
        ("opacity", logits),
        ("colour", dc),
        ("SH", rest),
    ):
        if not np.isfinite(a).all():
            raise ValueError(f"the scene has non-finite {name} values: nothing exported")
    norm = np.linalg.norm(quats, axis=1, keepdims=True)
    quats = np.where(norm > 1e-12, quats / np.maximum(norm, 1e-12), np.array([1.0, 0, 0, 0]))
    return Splats(
        means=means,
        scales=np.exp(log_scales),
        quats=quats,
        opacities=1.0 / (1.0 + np.exp(-logits)),
        sh_dc=dc,
        sh_rest=rest.reshape(n, 3, K - 1).transpose(0, 2, 1).copy(),
    )


def to_y_up(s: Splats) -> Splats:
    """The same Gaussians in the +Y-up frame (x right, y up, z back): module docstring."""
    k = s.sh_rest.shape[1]
    return replace(
        s, means=s.means @ Y_UP, quats=s.quats * np.array([1.0, 1.0, -1.0, -1.0]), sh_rest=s.sh_rest * SH_FLIP[:k, None]
    )


# -- antimatter15 .splat ---------------------------------------------------------------------------
SPLAT_DTYPE = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])


def splat_bytes(s: Splats) -> bytes:
    """The 32-byte-per-Gaussian ``.splat`` layout (antimatter15/splat): position 3 x f32 (metres),
    scale 3 x f32 (linear metres), RGBA 4 x u8 (sRGB colour of the DC term and opacity, x 255),
    rotation 4 x u8 ((w, x, y, z) unit quaternion x 128 + 128). Sorted by size x opacity, largest
    first, as the reference converter does (a stable sort: equal inputs give equal bytes). No SH
    beyond degree 0; holoflow's frame (module docstring)."""
    importance = np.prod(s.scales, axis=1) * s.opacities
    order = np.argsort(-importance, kind="stable")
    rec = np.zeros(len(s), SPLAT_DTYPE)
    rec["position"] = s.means[order]
    rec["scale"] = s.scales[order]
    rgba = np.concatenate([s.rgb[order], s.opacities[order, None]], 1)
    rec["rgba"] = np.clip(np.round(rgba * 255.0), 0, 255)
    rec["rotation"] = np.clip(np.round(s.quats[order] * 128.0 + 128.0), 0, 255)
    return rec.tobytes()


# -- Niantic SPZ (version 3, gzip container) -------------------------------------------------------
SPZ_MAGIC = 0x5053474E  # "NGSP"
SPZ_VERSION = 3
SPZ_COLOR_SCALE = 0.15


def spz_bytes(s: Splats, fractional_bits: int = 12) -> bytes:
    """Niantic SPZ v3 (nianticlabs/spz, load-spz.cc): gzip of a 16-byte header (magic "NGSP", version 3,
    count, SH degree, fractional bits, flags 0, reserved 0) and the sections positions (3 x 24-bit
    signed fixed point, ``fractional_bits`` bits after the point, lowered for scenes past
    2^(23 - bits) m), alphas (opacity x 255), colours (f_dc x 0.15 x 255 + 127.5), scales
    ((log scale + 10) x 16), rotations (smallest three of (x, y, z, w): 2-bit index of the largest,
    3 x (9-bit magnitude + sign)), SH (coefficient x 128 + 128, coefficient-major, channel-minor).
    Converted to SPZ's RUB axes first. Deterministic: the gzip header's time is 0."""
    s = to_y_up(s)
    n = len(s)
    bits = int(fractional_bits)
    extent = float(np.abs(s.means).max()) if n else 0.0
    while bits > 1 and round(extent * (1 << bits)) >= 1 << 23:
        bits -= 1
    if round(extent * (1 << bits)) >= 1 << 23:
        raise ValueError(f"scene extent {extent:.3g} m does not fit SPZ's 24-bit positions")
    fixed = np.round(s.means * (1 << bits)).astype(np.int64) & 0xFFFFFF  # [N, 3] two's complement
    positions = np.stack([(fixed >> sh) & 0xFF for sh in (0, 8, 16)], -1).astype(np.uint8)  # [N, 3, 3]
    alphas = _u8(s.opacities * 255.0)
    colors = _u8(s.sh_dc * (SPZ_COLOR_SCALE * 255.0) + 127.5)
    scales = _u8((np.log(s.scales) + 10.0) * 16.0)
    rotations = _smallest_three_spz(s.quats)
    sh = _u8(s.sh_rest * 128.0 + 128.0)  # [N, K - 1, 3]
    header = struct.pack("<IIIBBBB", SPZ_MAGIC, SPZ_VERSION, n, s.sh_degree, bits, 0, 0)
    body = b"".join(a.tobytes() for a in (positions, alphas, colors, scales, rotations, sh))
    return gzip.compress(header + body, compresslevel=6, mtime=0)


def _smallest_three_spz(quats_wxyz: np.ndarray) -> np.ndarray:
    """[N, 4] unit (w, x, y, z) -> [N, 4] u8 (a little-endian u32 each): SPZ v3's packing of (x, y, z, w)."""
    q = quats_wxyz[:, [1, 2, 3, 0]]  # SPZ order (x, y, z, w)
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)[:, None]  # largest positive
    packed = np.zeros(len(q), np.uint64)
    for axis in range(4):
        mag = np.round(np.abs(q[:, axis]) * np.sqrt(2.0) * 511.0).clip(0, 511).astype(np.uint64)
        word = mag | (np.uint64(1) << np.uint64(9)) * (q[:, axis] < 0)
        skip = largest == axis
        packed = np.where(skip, packed, (packed << np.uint64(10)) | word)
    packed |= largest.astype(np.uint64) << np.uint64(30)
    return packed.astype("<u4").view(np.uint8).reshape(-1, 4)


# -- PlayCanvas / SuperSplat compressed PLY --------------------------------------------------------
CHUNK = 256


def compressed_ply_bytes(s: Splats) -> bytes:
    """The PlayCanvas compressed PLY (SuperSplat, splat-transform): Gaussians in Morton order, in chunks
    of 256; ``element chunk`` holds 18 floats per chunk (min/max of x y z, of the log scales clamped to
    [-20, 20], and of the DC colour r g b); ``element vertex`` 4 uint32 per Gaussian:
    position and log scale as 11-10-11 bits within the chunk's bounds, rotation as 2 bits (index of
    the largest of (w, x, y, z)) + 3 x 10 bits (the others x sqrt(1/2) + 0.5), colour 8-8-8 within the
    chunk's colour bounds + opacity x 255; ``element sh`` (degree > 0) uint8 f_rest = coefficient x 32 +
    127.5, channel-major as the INRIA PLY. holoflow's frame (module docstring)."""
    n = len(s)
    s = s.subset(_morton_order(s.means))
    log_scales = np.clip(np.log(s.scales), -20.0, 20.0)
    rgb = s.rgb
    n_chunks = (n + CHUNK - 1) // CHUNK
    chunk = np.zeros((n_chunks, 18), np.float32)
    packed = np.zeros((n, 4), np.uint32)
    for c in range(n_chunks):
        sl = slice(c * CHUNK, min(n, (c + 1) * CHUNK))
        parts = []
        for j, values in enumerate((s.means[sl], log_scales[sl], rgb[sl])):
            lo, hi = values.min(0).astype(np.float32), values.max(0).astype(np.float32)
            chunk[c, 6 * j : 6 * j + 3], chunk[c, 6 * j + 3 : 6 * j + 6] = lo, hi
            span = (hi - lo).astype(np.float64)
            parts.append(np.where(span > 0, (values - lo) / np.where(span > 0, span, 1.0), 0.0))
        pos, scl, col = parts
        packed[sl, 0] = _pack_11_10_11(pos)
        packed[sl, 2] = _pack_11_10_11(scl)
        col8 = _u8(np.concatenate([col, s.opacities[sl, None]], 1) * 255.0).astype(np.uint32)
        packed[sl, 3] = (col8[:, 0] << 24) | (col8[:, 1] << 16) | (col8[:, 2] << 8) | col8[:, 3]
    packed[:, 1] = _smallest_three_playcanvas(s.quats)
    names = [
        "min_x",
        "min_y",
        "min_z",
        "max_x",
        "max_y",
        "max_z",
        "min_scale_x",
        "min_scale_y",
        "min_scale_z",
        "max_scale_x",
        "max_scale_y",
        "max_scale_z",
        "min_r",
        "min_g",
        "min_b",
        "max_r",
        "max_g",
        "max_b",
    ]
    header = [
        "ply",
        "format binary_little_endian 1.0",
        "comment written by holoflow (PlayCanvas compressed)",
        f"element chunk {n_chunks}",
        *(f"property float {k}" for k in names),
        f"element vertex {n}",
        *(f"property uint packed_{k}" for k in ("position", "rotation", "scale", "color")),
    ]
    k = s.sh_rest.shape[1]
    body = chunk.astype("<f4").tobytes() + packed.astype("<u4").tobytes()
    if k:
        header += [f"element sh {n}", *(f"property uchar f_rest_{i}" for i in range(3 * k))]
        body += _u8(s.sh_rest.transpose(0, 2, 1).reshape(n, 3 * k) * 32.0 + 127.5).tobytes()
    return ("\n".join(header + ["end_header"]) + "\n").encode("ascii") + body


def _pack_11_10_11(t: np.ndarray) -> np.ndarray:
    """[M, 3] values in [0, 1] -> [M] u32: x 11 bits (31..21), y 10 bits (20..11), z 11 bits (10..0)."""
    q = [np.round(np.clip(t[:, i], 0, 1) * m).astype(np.uint32) for i, m in enumerate((2047, 1023, 2047))]
    return (q[0] << 21) | (q[1] << 11) | q[2]


def _smallest_three_playcanvas(quats_wxyz: np.ndarray) -> np.ndarray:
    """[N, 4] unit (w, x, y, z) -> [N] u32: index of the largest (2 bits, 31..30), then the other three
    in order, 10 bits each, value x sqrt(1/2) + 0.5 (the largest made positive)."""
    q = quats_wxyz
    largest = np.argmax(np.abs(q), axis=1)
    q = q * np.where(q[np.arange(len(q)), largest] < 0, -1.0, 1.0)[:, None]
    # the three others in order: column k is q[:, k] before the largest, q[:, k + 1] from it on
    rest = np.stack([np.where(largest > k, q[:, k], q[:, k + 1]) for k in range(3)], 1)  # [N, 3]
    v = np.round(np.clip(rest * np.sqrt(0.5) + 0.5, 0, 1) * 1023).astype(np.uint32)
    return (largest.astype(np.uint32) << 30) | (v[:, 0] << 20) | (v[:, 1] << 10) | v[:, 2]


def _morton_order(means: np.ndarray) -> np.ndarray:
    """[N] permutation sorting positions [N, 3] along a 3D Morton curve (10 bits per axis over the
    bounding box), so a chunk of 256 holds neighbours and its bounds stay tight."""
    if len(means) == 0:
        return np.zeros(0, np.int64)
    lo, hi = means.min(0), means.max(0)
    q = np.round((means - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023).astype(np.uint64)
    code = np.zeros(len(means), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + 2 - axis)
    return np.argsort(code, kind="stable")


def _u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x), 0, 255).astype(np.uint8)
