"""Checks shared by the engine tests."""

import numpy as np


def seam_rank(img: np.ndarray) -> float:
    """Fraction of neighbouring-column colour steps smaller than the step across the seam.

    Steps are |col j - col j-1|, mean over rows and channels; the seam's is |col 0 - col W-1|.
    A seamless panorama's seam is an ordinary column: its rank is uniform in [0, 1] over seeds
    (mean 0.5); an unblended seam is the largest step (rank 1).
    """
    steps = np.abs(img - np.roll(img, 1, axis=1)).mean(axis=(0, 2))  # [W], steps[0] = seam
    return float((steps[1:] < steps[0]).mean())


def seam_is_typical(*imgs: np.ndarray, limit: float = 0.9) -> bool:
    """The seam is no larger than a typical neighbouring-column step: mean seam rank <= ``limit``
    over the given outputs (different seeds or inputs; random tiny models give noisy images, so
    one output's rank is a single draw)."""
    return float(np.mean([seam_rank(i) for i in imgs])) <= limit
