"""Blob detection with sub-pixel ellipse fitting: dark holes or bright discs on a lit surface.

Why this way: a drilled hole in a lit part is a dark ellipse whose edge is softened by the chamfer,
by defocus and by the lens; the background brightness drifts across the image (the lighting
gradient).  So the image is first divided by its own local background (a morphological closing of
a reduced copy: holes vanish, gradients stay), which turns every feature into a relative contrast
that a single threshold can find.  Each candidate is then refined on its own: an iso-contour at
half its own contrast, traced on an up-sampled patch (quarter-pixel steps), an ellipse fitted by
least squares and refitted without the edge points that do not belong (an occluder's edge, a
neighbour touching it).  Blur is symmetric, so the half-contrast contour stays centred on the
feature however soft its edge; how soft it is (``edge_width``) is measured and reported so a
caller can refuse a defocused image.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

Polarity = Literal["dark", "bright"]
Array = NDArray[np.float64]

#: Candidates refined per image at most (the largest first): bounds the work on a noisy image.
MAX_CANDIDATES = 128
#: A filled ellipse covers pi/4 of its bounding box when upright, less when turned and elongated;
#: a component covering less than this share is a streak.
MIN_FILL = 0.3
#: A candidate's contrast must exceed this many standard deviations of the image noise.
NOISE_FACTOR = 6.0
#: ... and at least this relative contrast.
MIN_CONTRAST = 0.04


@dataclass(frozen=True)
class Blob:
    """One fitted ellipse in an image (pixel coordinates, origin at the centre of the top-left pixel)."""

    center: tuple[float, float]
    axes: tuple[float, float]  # full major and minor axis lengths (px)
    angle: float  # deg, OpenCV's convention
    edge: Array  # N x 2 edge points kept by the fit (px)
    contrast: float  # relative to the local background (0..1 for a dark hole)
    edge_width: float  # px: contrast / edge gradient, about 2.5 sigma of the blur
    rms: float  # px: RMS distance of the kept edge points from the ellipse
    coverage: float  # share of the perimeter where edge points were kept (0..1)


def to_gray(image: NDArray[np.generic]) -> NDArray[np.float32]:
    """Any 8/16-bit or float image, mono or BGR(A), as float32 in [0, 1]."""
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] in (3, 4):
        array = cv2.cvtColor(array, cv2.COLOR_BGRA2GRAY if array.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    elif array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f"an image must be a 2D (mono) or 3-channel array, got shape {array.shape}")
    if array.dtype == np.uint8:
        return array.astype(np.float32) / 255.0
    if array.dtype == np.uint16:
        return array.astype(np.float32) / 65535.0
    if np.issubdtype(array.dtype, np.floating):
        return np.clip(array.astype(np.float32), 0.0, 1.0)
    raise ValueError(f"unsupported image type {array.dtype}")


def relative_contrast(gray: NDArray[np.float32], polarity: Polarity, max_size: float) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Feature strength per pixel (how much darker or brighter than the local background, relative to it), and that background."""
    kernel = max_size * 1.4 + 3.0
    scale = max(1, int(kernel // 15))
    # Smoothed first: a closing picks the brightest pixel around, which on a noisy image is noise.
    small = cv2.resize(cv2.GaussianBlur(gray, (0, 0), 1.5), (max(1, gray.shape[1] // scale), max(1, gray.shape[0] // scale)), interpolation=cv2.INTER_AREA)
    size = int(math.ceil(kernel / scale)) | 1
    element = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    op = cv2.MORPH_CLOSE if polarity == "dark" else cv2.MORPH_OPEN
    closed = cv2.morphologyEx(small, op, element, borderType=cv2.BORDER_REPLICATE)
    smoothed = cv2.GaussianBlur(closed, (0, 0), max(1.0, size / 4.0))
    # Smoothing spreads a bright surface into the dark around it, where that would look like a dark
    # feature: never let it raise (dark) or lower (bright) the closing itself.
    background = np.minimum(smoothed, closed) if polarity == "dark" else np.maximum(smoothed, closed)
    background = cv2.resize(background, (gray.shape[1], gray.shape[0]), interpolation=cv2.INTER_LINEAR)
    denominator = np.maximum(background, 0.02)
    if polarity == "dark":
        return (background - gray) / denominator, denominator
    return (gray - background) / denominator, denominator


def noise_level(gray: NDArray[np.float32]) -> float:
    """Robust standard deviation of the pixel noise (median absolute deviation of a high-pass), in image units."""
    high = gray - cv2.GaussianBlur(gray, (0, 0), 1.0)
    return float(1.4826 * np.median(np.abs(high - np.median(high))) * 1.6)


def find_blobs(image: NDArray[np.generic], polarity: Polarity = "dark", min_size: float = 4.0, max_size: float = 400.0) -> list[Blob]:
    """Every elliptical blob of the given polarity whose size (px) lies in ``[min_size, max_size]``."""
    if not (0 < min_size <= max_size and math.isfinite(max_size)):
        raise ValueError(f"blob sizes must satisfy 0 < min_size <= max_size, got {min_size}, {max_size}")
    gray = to_gray(image)
    strength, background = relative_contrast(gray, polarity, max_size)
    smooth = cv2.GaussianBlur(strength, (0, 0), 1.0)
    # The same sensor noise is a larger relative contrast where the background is dark: threshold per pixel.
    threshold = np.maximum(NOISE_FACTOR * noise_level(gray) / 2.5 / background, MIN_CONTRAST)
    mask = (smooth > threshold).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    order = sorted(range(1, count), key=lambda i: -int(stats[i, cv2.CC_STAT_AREA]))
    blobs: list[Blob] = []
    refined = 0
    for label in order:
        if refined >= MAX_CANDIDATES:
            break
        x, y, w, h, area = (int(v) for v in stats[label])
        if max(w, h) < 0.5 * min_size or max(w, h) > 1.6 * max_size or area < 8:
            continue
        if area < MIN_FILL * w * h:
            continue  # a thin streak (the dark side of a bright edge), not a filled ellipse
        refined += 1
        blob = _refine(strength, smooth, labels, label, (x, y, w, h))
        if blob is not None and 0.7 * min_size <= blob.axes[0] <= 1.3 * max_size:
            blobs.append(blob)
    return blobs


def _refine(strength: NDArray[np.float32], smooth: NDArray[np.float32], labels: NDArray[np.int32], label: int, box: tuple[int, int, int, int]) -> Blob | None:
    x, y, w, h = box
    rows, cols = strength.shape
    margin = max(6, int(0.5 * max(w, h)))
    x0, y0 = max(0, x - margin), max(0, y - margin)
    x1, y1 = min(cols, x + w + margin), min(rows, y + h + margin)
    patch = smooth[y0:y1, x0:x1]
    own = labels[y0:y1, x0:x1] == label
    inside = float(np.percentile(patch[own], 90))
    outside_pixels = patch[labels[y0:y1, x0:x1] == 0]
    outside = float(np.median(outside_pixels)) if outside_pixels.size else 0.0
    contrast = inside - outside
    if contrast <= 0:
        return None
    level = outside + 0.5 * contrast
    # Trace the half-contrast contour on an up-sampled copy of the (lightly smoothed) patch.
    factor = 4 if max(w, h) < 80 else 2 if max(w, h) < 200 else 1
    source = strength[y0:y1, x0:x1]
    up = cv2.resize(cv2.GaussianBlur(source, (0, 0), 0.7), None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC) if factor > 1 else source
    binary = (up > level).astype(np.uint8)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    contour = max(contours, key=cv2.contourArea)[:, 0, :].astype(np.float64)
    points = (contour + 0.5) / factor - 0.5 + np.array([x0, y0], dtype=float)
    # Points on the patch border belong to whatever cut the blob off (the image edge, a neighbour), not to its edge.
    keep = (points[:, 0] > x0 + 0.25) & (points[:, 0] < x1 - 1.25) & (points[:, 1] > y0 + 0.25) & (points[:, 1] < y1 - 1.25)
    points = points[keep]
    if len(points) < 12:
        return None
    fitted = _robust_fit(points)
    if fitted is None:
        return None
    (cx, cy), (major, minor), angle, inliers, rms = fitted
    coverage = _coverage(inliers, (cx, cy))
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    ij = np.clip(np.rint(inliers).astype(int), 0, [cols - 1, rows - 1])
    gradient = float(np.median(np.hypot(gx[ij[:, 1], ij[:, 0]], gy[ij[:, 1], ij[:, 0]])))
    edge_width = contrast / gradient if gradient > 1e-9 else math.inf
    return Blob((cx, cy), (major, minor), angle, inliers, contrast, edge_width, rms, coverage)


def ellipse_residuals(points: Array, center: tuple[float, float], axes: tuple[float, float], angle: float) -> Array:
    """Signed distance-like residual of each point from the ellipse (px): (normalised radius - 1) x mean semi-axis."""
    a, b = max(axes[0], 1e-9) / 2.0, max(axes[1], 1e-9) / 2.0
    t = math.radians(angle)
    c, s = math.cos(t), math.sin(t)
    d = points - np.asarray(center)
    u = d[:, 0] * c + d[:, 1] * s
    v = -d[:, 0] * s + d[:, 1] * c
    r = np.sqrt((u / a) ** 2 + (v / b) ** 2)
    return (r - 1.0) * 0.5 * (a + b)


#: Edge points this far (px) from a fit count as belonging to it when arcs are searched.
INLIER_PX = 0.5
#: The contour is cut into this many arcs; fits leaving out up to ARCS_LEFT_OUT of them are tried.
ARCS, ARCS_LEFT_OUT = 8, 2


def _robust_fit(points: Array) -> tuple[tuple[float, float], tuple[float, float], float, Array, float] | None:
    """Least-squares ellipse without the edge points that belong to something else.

    A fit to every point is refitted without its outliers; when that still leaves a poor fit (an
    occluder's edge or a merged neighbour is a long run of wrong points, which pulls the first fit
    too far for trimming to recover), the contour is cut into arcs and the fit over the subset of
    arcs that gathers the most points within :data:`INLIER_PX` wins.
    """
    fit = _trimmed_fit(points)
    if fit is not None and fit[4] <= 0.3:
        return fit
    best, best_count = fit, -1 if fit is None else int(np.sum(np.abs(ellipse_residuals(points, fit[0], fit[1], fit[2])) <= INLIER_PX))
    arcs = np.array_split(np.arange(len(points)), ARCS)
    for left_out in itertools.chain.from_iterable(itertools.combinations(range(ARCS), k) for k in range(1, ARCS_LEFT_OUT + 1)):
        subset = np.concatenate([arcs[i] for i in range(ARCS) if i not in left_out])
        if len(subset) < 6:
            continue
        (cx, cy), (d1, d2), angle = cv2.fitEllipse(points[subset].astype(np.float32))
        if not (math.isfinite(cx) and math.isfinite(cy) and d1 > 0 and d2 > 0):
            continue
        inliers = np.abs(ellipse_residuals(points, (cx, cy), (d1, d2), angle)) <= INLIER_PX
        count = int(inliers.sum())
        if count > best_count:
            refit = _trimmed_fit(points[inliers])
            if refit is not None:
                best, best_count = refit, count
    return best


def _trimmed_fit(points: Array) -> tuple[tuple[float, float], tuple[float, float], float, Array, float] | None:
    """Least-squares ellipse, refitted up to three times without the points far from it."""
    kept = points
    for _ in range(4):
        if len(kept) < 6:
            return None
        (cx, cy), (d1, d2), angle = cv2.fitEllipse(kept.astype(np.float32))
        if not (math.isfinite(cx) and math.isfinite(cy) and d1 > 0 and d2 > 0):
            return None
        residual = ellipse_residuals(kept, (cx, cy), (d1, d2), angle)
        spread = 1.4826 * float(np.median(np.abs(residual)))
        limit = max(3.0 * spread, 0.35)
        good = np.abs(residual) <= limit
        if good.all():
            break
        kept = kept[good]
    residual = ellipse_residuals(kept, (cx, cy), (d1, d2), angle)
    major, minor = (d1, d2) if d1 >= d2 else (d2, d1)
    if d1 < d2:
        angle = (angle + 90.0) % 180.0
    return (float(cx), float(cy)), (float(major), float(minor)), float(angle), kept, float(np.sqrt(np.mean(residual**2)))


def _coverage(points: Array, center: tuple[float, float], bins: int = 36) -> float:
    angles = np.arctan2(points[:, 1] - center[1], points[:, 0] - center[0])
    hit = np.unique(np.floor((angles + math.pi) / (2 * math.pi) * bins).astype(int) % bins)
    return len(hit) / bins
