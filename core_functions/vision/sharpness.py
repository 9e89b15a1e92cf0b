"""Image sharpness: the variance of the Laplacian, the focus measure of the focus loop.

The image is normalised by its mean (so the measure does not follow the exposure) and smoothed
lightly first (so sensor noise, which the Laplacian amplifies most, does not dominate it): what
remains rises and falls with the edges' steepness, which is what defocus changes.
"""
from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from core_functions.vision.detect import to_gray

#: Pre-smoothing (px) before the Laplacian.
NOISE_SIGMA = 1.0


def sharpness(image: NDArray[np.generic], roi: tuple[int, int, int, int] | None = None) -> float:
    """Variance of the Laplacian of the mean-normalised image (x 1e4), over ``roi`` = (x, y, w, h) if given."""
    gray = to_gray(image)
    if roi is not None:
        x, y, w, h = roi
        gray = gray[max(0, y) : y + h, max(0, x) : x + w]
        if gray.size == 0:
            raise ValueError(f"region {roi} lies outside the image")
    mean = float(gray.mean())
    if mean <= 1e-6:
        return 0.0
    smooth = cv2.GaussianBlur(gray / mean, (0, 0), NOISE_SIGMA)
    return float(cv2.Laplacian(smooth, cv2.CV_32F, ksize=3).var() * 1e4)
