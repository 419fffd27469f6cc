"""Align the tangent faces' relative disparities into one consistent radial disparity.

A relative-depth network gives each face an affine-ambiguous *perspective* disparity d ~ 1/z. With face
obliquity cos (holoflow.depth.faces), the radial disparity 1/r = cos / z, so the aligned radial
disparity of face f at pixel p is modelled as

    D_f(p) = cos_f(p) * (s_f(p) * d_f(p) + o_f(p))

which is linear in the unknown scale s and offset o. Three solvers (``METHODS``):

- ``median``: s = 1 / median(d_f), o = 0 per face; no overlap information (the naive baseline).
- ``affine``: one (s_f, o_f) per face, solved jointly so that overlapping faces agree (sparse least
  squares over all overlap pairs), gauge mean(s) = 1.
- ``grid``: 360MonoDepth style; s and o live on a coarse (cols x rows) node grid per face, bilinear
  between nodes, solved jointly over the overlaps, with a smoothness term between neighbouring nodes
  and a regulariser pulling each node to its face's ``affine`` solution (which keeps scales away from
  zero and fixes the gauge).

Data residuals are reweighted (Huber IRLS) so that edge-mixed pixels do not drag the fit. Faces with
too few valid pixels, or whose fitted scale comes out <= 0, are dropped (weight 0 in the blend) and
reported in the residuals.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from holoflow.depth.config import TangentDepthParams
from holoflow.depth.faces import Overlaps

METHODS = ("median", "affine", "grid")
MIN_VALID = 8  # a face with fewer valid pixels is dropped
REL_FLOOR = 0.05  # relative residuals divide by disparity + this fraction of its 90th percentile
HUBER_MIN = 0.02  # smallest Huber threshold on a relative residual
PERMC = "MMD_AT_PLUS_A"  # SuperLU column order: minimum degree on A' + A, suited to the symmetric normal matrix


@dataclass
class Alignment:
    """Result of an alignment: ``radial`` [F, h, w] aligned radial disparity (NaN where invalid),
    ``scale`` / ``offset`` [F, rows, cols] node grids (1 x 1 for median / affine; they act on the
    face's normalised disparity d / ``norm``), ``norm`` [F], ``face_ok`` [F] and ``residuals`` (JSON-able).
    """

    radial: np.ndarray
    scale: np.ndarray
    offset: np.ndarray
    norm: np.ndarray
    face_ok: np.ndarray
    residuals: dict = field(default_factory=dict)


def align_faces(
    disp: np.ndarray,
    valid: np.ndarray,
    cos: np.ndarray,
    overlaps: Overlaps,
    cfg: TangentDepthParams,
    robust_iters: int = 3,
) -> Alignment:
    """Align per-face perspective disparities ``disp`` [F, h, w] into radial disparities.

    ``valid`` [F, h, w] marks usable pixels (finite engine output; NaN / inf are masked here too);
    ``cos`` [F, h, w] face obliquity; from ``cfg``: ``align`` (the method), ``grid`` = (cols, rows)
    nodes per face for ``grid``, ``smoothness`` and ``scale_reg`` (docs/depth.md).
    """
    method, grid, smoothness, scale_reg = cfg.align, cfg.grid, cfg.smoothness, cfg.scale_reg
    if method not in METHODS:
        raise ValueError(f"unknown alignment method {method!r}; choose one of {METHODS}")
    disp = np.asarray(disp, dtype=np.float64)
    F, h, w = disp.shape
    valid = np.asarray(valid, dtype=bool) & np.isfinite(disp)
    d, norm = _normalise(np.where(valid, disp, 0.0), valid)
    face_ok = valid.reshape(F, -1).sum(1) >= MIN_VALID
    dropped = {int(f): "fewer than %d valid pixels" % MIN_VALID for f in np.flatnonzero(~face_ok)}

    if method == "median":
        med = np.array([np.median(d[f][valid[f]]) if face_ok[f] else 1.0 for f in range(F)])
        for f in np.flatnonzero(face_ok & ~(med > 0)):
            dropped[int(f)] = "median disparity <= 0"
        face_ok &= med > 0
        scale = np.where(face_ok, 1.0 / np.where(med > 0, med, 1.0), 0.0).reshape(F, 1, 1)
        offset = np.zeros((F, 1, 1))
    else:
        scale, offset = _solve_until_positive(
            d, valid, overlaps, face_ok, dropped, (1, 1), 0.0, 0.0, None, robust_iters
        )
        if method == "grid":
            cols, rows = int(grid[0]), int(grid[1])
            if cols < 1 or rows < 1:
                raise ValueError(f"alignment grid must be >= 1 x 1, got {grid}")
            # refine on the affine-aligned faces, rescaled so their typical disparity is 1: then the node
            # scales are ~1 and offsets ~0 and every term of the energy is relative (scene-scale free)
            s_a, o_a = scale[:, :1, :1], offset[:, :1, :1]  # [F, 1, 1]
            pre = s_a * d + o_a
            typical = np.median(np.abs(pre[valid & face_ok[:, None, None]])) if face_ok.any() else 1.0
            typical = typical if typical > 0 and np.isfinite(typical) else 1.0
            ones = np.ones(len(face_ok))
            s_g, o_g = _solve_until_positive(
                pre / typical,
                valid,
                overlaps,
                face_ok,
                dropped,
                (cols, rows),
                smoothness,
                scale_reg,
                (ones, 0 * ones),
                robust_iters,
            )
            scale, offset = s_g * s_a, s_g * o_a + typical * o_g  # compose: nodes act on d directly
    s_map, o_map = _grid_maps(scale, h, w), _grid_maps(offset, h, w)  # [F, h, w]
    radial = cos * (s_map * d + o_map)
    radial = np.where(valid & face_ok[:, None, None], radial, np.nan)
    res = _residual_report(radial, overlaps, valid & face_ok[:, None, None])
    res.update(
        method=method,
        grid=[int(scale.shape[2]), int(scale.shape[1])],
        dropped_faces={str(k): v for k, v in sorted(dropped.items())},
    )
    return Alignment(radial, scale, offset, norm, face_ok, res)


def _normalise(d: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Divide each face by a robust spread of its valid values (10-90% range, else |median|, else 1)."""
    F = d.shape[0]
    norm = np.ones(F)
    for f in range(F):
        v = d[f][valid[f]]
        if v.size:
            lo, hi, med = np.percentile(v, [10, 90, 50])
            tiny = 1e-6 * max(abs(lo), abs(hi), 1e-300)  # a spread below this is rounding noise
            for spread in (hi - lo, abs(med), 1.0):
                if spread > tiny and np.isfinite(spread):
                    norm[f] = spread
                    break
    return d / norm[:, None, None], norm


def _node_taps(x: np.ndarray, y: np.ndarray, h: int, w: int, cols: int, rows: int):
    """Bilinear node taps [N, 4] (flat node index within the face) and weights [N, 4] of pixel coords."""
    gx = np.clip(x / w, 0, 1) * (cols - 1)
    gy = np.clip(y / h, 0, 1) * (rows - 1)
    x0 = np.minimum(np.floor(gx).astype(np.int64), max(cols - 2, 0))
    y0 = np.minimum(np.floor(gy).astype(np.int64), max(rows - 2, 0))
    ax, ay = gx - x0, gy - y0
    x1, y1 = np.minimum(x0 + 1, cols - 1), np.minimum(y0 + 1, rows - 1)
    idx = np.stack([y0 * cols + x0, y0 * cols + x1, y1 * cols + x0, y1 * cols + x1], 1)
    wts = np.stack([(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay], 1)
    return idx, wts


def _grid_maps(nodes: np.ndarray, h: int, w: int) -> np.ndarray:
    """Per-pixel values [F, h, w] of node grids [F, rows, cols] (bilinear)."""
    F, rows, cols = nodes.shape
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    idx, wts = _node_taps(x.ravel(), y.ravel(), h, w, cols, rows)
    flat = nodes.reshape(F, -1)
    return (flat[:, idx] * wts[None]).sum(-1).reshape(F, h, w)


def _solve_until_positive(d, valid, overlaps, face_ok, dropped, grid, smoothness, scale_reg, prior, robust_iters):
    """Solve; drop faces whose mean scale is <= 0 and solve again until none is (face_ok updated)."""
    while True:
        scale, offset = _solve(d, valid, overlaps, face_ok, grid, smoothness, scale_reg, prior, robust_iters)
        bad = face_ok & ~(scale.reshape(len(face_ok), -1).mean(1) > 0)
        if not bad.any():
            return np.where(face_ok[:, None, None], scale, 0.0), np.where(face_ok[:, None, None], offset, 0.0)
        for f in np.flatnonzero(bad):
            dropped[int(f)] = "fitted scale <= 0"
        face_ok &= ~bad


def _solve(d, valid, ov: Overlaps, face_ok, grid, smoothness, scale_reg, prior, robust_iters):
    """Sparse least squares for node scales/offsets [F, rows, cols] (see the module docstring)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    F, h, w = d.shape
    cols, rows = grid
    n_nodes = cols * rows
    n = 2 * F * n_nodes  # unknowns: scales of every node of every face, then offsets
    flat_d, flat_v = d.reshape(F, -1), valid.reshape(F, -1)

    # data rows: cos_a (s_a d_a + o_a) - cos_b (s_b d_b + o_b) = 0 over usable overlap pairs
    fa, fb = ov.face_a, ov.face_b
    tap_ok = (flat_v[fb[:, None], ov.idx_b] | (ov.wts_b <= 0)).all(1) if len(ov) else np.zeros(0, bool)
    use = face_ok[fa] & face_ok[fb] & flat_v[fa, ov.pix_a] & tap_ok
    fa, fb, pa = fa[use], fb[use], ov.pix_a[use]
    ca, cb = ov.cos_a[use], ov.cos_b[use]
    da = flat_d[fa, pa]
    db = (flat_d[fb[:, None], ov.idx_b[use]] * ov.wts_b[use]).sum(1)
    xa, ya = pa % w + 0.5, pa // w + 0.5
    na, wa = _node_taps(xa, ya, h, w, cols, rows)
    nb, wb = _node_taps(ov.x_b[use], ov.y_b[use], h, w, cols, rows)
    P = fa.size
    r_idx = np.repeat(np.arange(P), 16)
    c_idx = np.concatenate(
        [
            (fa[:, None] * n_nodes + na),
            (F * n_nodes + fa[:, None] * n_nodes + na),
            (fb[:, None] * n_nodes + nb),
            (F * n_nodes + fb[:, None] * n_nodes + nb),
        ],
        1,
    ).ravel()
    vals = np.concatenate(
        [ca[:, None] * wa * da[:, None], ca[:, None] * wa, -cb[:, None] * wb * db[:, None], -cb[:, None] * wb], 1
    ).ravel()
    side_a = (np.arange(16) < 8)[None].repeat(P, 0).ravel()
    data = sp.csr_matrix((vals, (r_idx, c_idx)), shape=(P, n))
    data_a = sp.csr_matrix((vals * side_a, (r_idx, c_idx)), shape=(P, n))  # D_a alone

    reg_rows, reg_rhs = [], []
    if prior is None:
        # gauge: the mean aligned perspective disparity over all valid pixels of usable faces is 1 (a gauge
        # on the scales alone would let faces whose disparity is constant, e.g. all sky, take all the
        # scale and collapse the others to zero); a tiny ridge pins what the data leave free
        px = valid & face_ok[:, None, None]
        g = np.concatenate([np.where(px, d, 0.0).sum((1, 2)), px.sum((1, 2))]) / max(px.sum(), 1)
        reg_rows.append(sp.csr_matrix(g[None]))
        reg_rhs.append(np.ones(1))
        ridge = 1e-4
        reg_rows.append(sp.identity(n, format="csr") * ridge)
        prior_s = np.repeat(np.where(face_ok, 1.0, 0.0), n_nodes)
        reg_rhs.append(np.concatenate([prior_s, np.zeros(F * n_nodes)]) * ridge)
    else:
        # pull every node to its face's affine solution: keeps scales away from zero, fixes the gauge
        wr = np.sqrt(scale_reg / max(n_nodes, 1))
        reg_rows.append(sp.identity(n, format="csr") * wr)
        reg_rhs.append(np.concatenate([np.repeat(prior[0], n_nodes), np.repeat(prior[1], n_nodes)]) * wr)
        if smoothness > 0 and n_nodes > 1:
            reg_rows.append(_smoothness_rows(F, cols, rows) * np.sqrt(smoothness / n_nodes))
            reg_rhs.append(np.zeros(reg_rows[-1].shape[0]))
    reg = sp.vstack(reg_rows).tocsr()
    # normal equations (D' W D + R' R + 1e-12 I) x = R' b_reg (the data rows have a zero right side);
    # the regulariser's part is the same in every robust iteration
    RtR = (reg.T @ reg).tocsr() + sp.identity(n, format="csr") * 1e-12
    Rtb = reg.T @ np.concatenate(reg_rhs)

    # data weight: mean over pairs, scaled to the number of faces so the regularisers stay comparable
    base = np.sqrt(F / max(P, 1))
    wts = np.ones(P)
    x = np.zeros(n)
    for it in range(max(robust_iters, 0) + 1):
        dw = data.copy()  # rows weighted
        dw.data *= np.repeat(base * wts, np.diff(data.indptr))
        AtA = (dw.T @ dw + RtR).tocsc()
        x = spla.spsolve(AtA, Rtb, permc_spec=PERMC)
        if it == robust_iters or P == 0:
            break
        # relative residuals (far pixels, with small disparities, pin the offsets as much as near ones
        # pin the scales), Huber-weighted against the edge-mixed pairs
        r = data @ x
        da_x = data_a @ x
        level = 0.5 * (np.abs(da_x) + np.abs(da_x - r))
        level = level + REL_FLOOR * max(np.percentile(level, 90), 1e-12)  # weights differ <= 1 / REL_FLOOR
        rel = r / level
        k = max(1.5 * 1.4826 * np.median(np.abs(rel)), HUBER_MIN)  # sky pairs agree exactly: MAD can be 0
        huber = np.where(np.abs(rel) <= k, 1.0, np.sqrt(k / np.maximum(np.abs(rel), 1e-300)))
        wts = huber / level
        wts = wts / np.sqrt(np.mean(wts**2))  # the data term keeps its total weight
    x = np.where(np.isfinite(x), x, 0.0)
    scale = x[: F * n_nodes].reshape(F, rows, cols)
    offset = x[F * n_nodes :].reshape(F, rows, cols)
    return scale, offset


def _smoothness_rows(F: int, cols: int, rows: int):
    """Sparse rows (node_k - node_l) for horizontally / vertically adjacent nodes, scales and offsets."""
    import scipy.sparse as sp

    n_nodes = cols * rows
    ids = np.arange(n_nodes).reshape(rows, cols)
    pairs = np.concatenate(
        [np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], 1), np.stack([ids[:-1, :].ravel(), ids[1:, :].ravel()], 1)]
    )
    blocks = (np.arange(2 * F) * n_nodes)[:, None, None] + pairs[None]  # [2F, E, 2]
    blocks = blocks.reshape(-1, 2)
    E = blocks.shape[0]
    r = np.repeat(np.arange(E), 2)
    vals = np.tile([1.0, -1.0], E)
    return sp.csr_matrix((vals, (r, blocks.ravel())), shape=(E, 2 * F * n_nodes))


def _residual_report(radial: np.ndarray, ov: Overlaps, ok: np.ndarray) -> dict:
    """Overlap disagreement of the aligned faces: RMS and relative (|D_a - D_b| / mean) overall and per face."""
    F = radial.shape[0]
    flat, flat_ok = radial.reshape(F, -1), ok.reshape(F, -1)
    if len(ov):
        use = flat_ok[ov.face_a, ov.pix_a] & (flat_ok[ov.face_b[:, None], ov.idx_b] | (ov.wts_b <= 0)).all(1)
    else:
        use = np.zeros(0, bool)
    a = flat[ov.face_a[use], ov.pix_a[use]]
    b = (np.nan_to_num(flat[ov.face_b[use][:, None], ov.idx_b[use]]) * ov.wts_b[use]).sum(1)
    r = a - b
    scale = np.mean(np.abs(np.concatenate([a, b]))) if r.size else 1.0
    per_face = {}
    for f in range(F):
        m = (ov.face_a[use] == f) | (ov.face_b[use] == f)
        if m.any():
            per_face[f"{f:02d}"] = float(np.sqrt(np.mean(r[m] ** 2)) / max(scale, 1e-30))
    return {
        "pairs": int(r.size),
        "rms": float(np.sqrt(np.mean(r**2))) if r.size else 0.0,
        "rel_rms": float(np.sqrt(np.mean(r**2)) / max(scale, 1e-30)) if r.size else 0.0,
        "rel_mean_abs": float(np.mean(np.abs(r)) / max(scale, 1e-30)) if r.size else 0.0,
        "per_face_rel_rms": per_face,
    }
