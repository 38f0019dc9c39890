"""Image features: an edge map and its truncated Euclidean distance transform.

Computed once per frame; every candidate extrinsic then reads distances by bilinear lookup.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(eq=False)
class ImageFeatures:
    """Edge features of one image.

    Attributes
    ----------
    edges : ndarray, shape (H, W), uint8
        Edge map, 255 on edge pixels and 0 elsewhere.
    dt : ndarray, shape (H, W), float32
        Euclidean distance in pixels from each pixel centre to the nearest edge pixel centre,
        truncated at ``truncation_px``.
    truncation_px : float
    mean_dt : float
        Mean of ``dt`` over the image: the expected cost of a point placed at random, charged
        to points that leave the image or fall behind the camera.
    edge_uv : ndarray, shape (E, 2), float64
        ``(u, v)`` of the edge pixels, for exact KD-tree oracles and the paper's Chamfer.
    mask : ndarray, shape (H, W), bool, or None
        Usable pixels (None: all). ``mean_dt`` is taken over them, and the objective treats a
        point landing on another pixel like a point outside the image.
    """

    edges: np.ndarray
    dt: np.ndarray
    truncation_px: float
    mean_dt: float
    edge_uv: np.ndarray
    mask: np.ndarray | None = None


#: The image level taken as "white" when thresholds are relative (percentile of the usable
#: pixels): a few saturated lamps or reflections must not set the scale.
WHITE_PERCENTILE = 99.0
#: Relative thresholds never go below this many noise standard deviations of the gradient
#: (estimated from the median gradient, an upper bound in natural images where most pixels
#: are flat): a Rayleigh tail at 6 sigma is exp(-18), so noise alone makes no edge.
NOISE_SIGMAS = 6.0
#: The median of a Rayleigh distribution is 1.1774 sigma.
RAYLEIGH_MEDIAN = 1.1774


def canny_thresholds(gray: np.ndarray, low: float, high: float,
                     mask: np.ndarray | None = None) -> tuple[float, float]:
    """Canny thresholds for ``gray`` (H, W) uint8, given ``low`` and ``high`` for an image that
    uses the full 0-255 range.

    A dark image (night, underexposed) has weaker gradients for the same scene contrast: the
    thresholds scale with the image's white level (its :data:`WHITE_PERCENTILE` percentile over
    the usable pixels), as if it had been stretched to the full range, but never below
    :data:`NOISE_SIGMAS` noise deviations. An image whose white level reaches 255 keeps the
    thresholds as given.
    """
    usable = gray if mask is None else gray[np.asarray(mask, dtype=bool)]
    if usable.size == 0:
        return low, high
    white = float(np.percentile(usable, WHITE_PERCENTILE))
    scale = min(1.0, max(white, 1.0) / 255.0)
    floor = NOISE_SIGMAS * gradient_noise(gray, mask)
    hi = max(high * scale, min(high, floor))
    return hi * low / high, hi


#: CLAHE: contrast limit (OpenCV's clip limit, relative to a flat histogram) and tiles per
#: image side. 2 is the customary limit; tiles follow the image (8 per side at any size).
CLAHE_CLIP = 2.0
CLAHE_TILES = 8


def gradient_noise(gray: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The noise deviation of the Sobel gradient magnitude of ``gray`` (H, W), from its median
    over the usable pixels (a Rayleigh median; an upper bound in natural images, where most
    pixels are flat)."""
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1)
    g = np.hypot(gx, gy)
    usable = g if mask is None else g[np.asarray(mask, dtype=bool)]
    return float(np.median(usable)) / RAYLEIGH_MEDIAN if usable.size else 0.0


def equalize_contrast(gray: np.ndarray) -> np.ndarray:
    """Contrast-limited adaptive histogram equalisation of a grey image (H, W) uint8."""
    return cv2.createCLAHE(clipLimit=CLAHE_CLIP,
                           tileGridSize=(CLAHE_TILES, CLAHE_TILES)).apply(gray)


def edge_map(image_bgr: np.ndarray, blur_sigma: float = 1.0, canny_low: float = 50.0,
             canny_high: float = 150.0, min_edge_px: int = 0, relative: bool = False,
             mask: np.ndarray | None = None, equalize: bool = False,
             noise_sigmas: float | None = None) -> np.ndarray:
    """Canny edges of a Gaussian-blurred grey image.

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3) or (H, W), uint8
    blur_sigma : float
        Gaussian sigma in pixels before Canny (0 disables the blur).
    canny_low, canny_high : float
        Hysteresis thresholds on the L2 gradient magnitude.
    min_edge_px : int
        Drop connected edge fragments of fewer pixels (foliage, noise); 0 keeps all.
    relative : bool
        The thresholds are for a full-range image and scale with the image's white level
        (:func:`canny_thresholds`).
    mask : ndarray, shape (H, W), bool, optional
        Usable pixels, for the white level and noise of relative thresholds.
    equalize : bool
        Equalise local contrast first (CLAHE, :func:`equalize_contrast`): structure in dark
        or flat parts of the image (night scenes, shadows) reaches the thresholds.
    noise_sigmas : float, optional
        The high threshold is this many noise deviations of the blurred image's gradient
        (:func:`gradient_noise`), the low one keeps its ratio to it (``canny_low /
        canny_high``): a dim, low-contrast image keeps its silhouettes, a noisy one does not
        turn noise into edges. Replaces ``relative``.

    Returns
    -------
    ndarray, shape (H, W), uint8 with values 0 and 255
    """
    gray = image_bgr if image_bgr.ndim == 2 else cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
    if equalize:
        gray = equalize_contrast(gray)
    if blur_sigma > 0:
        gray = cv2.GaussianBlur(gray, (0, 0), blur_sigma)
    if noise_sigmas is not None:
        high = noise_sigmas * gradient_noise(gray, mask)
        canny_low, canny_high = high * canny_low / canny_high, high
    elif relative:
        canny_low, canny_high = canny_thresholds(gray, canny_low, canny_high, mask)
    edges = cv2.Canny(gray, canny_low, canny_high, L2gradient=True)
    if min_edge_px > 1:
        n, labels, stats, _ = cv2.connectedComponentsWithStats(edges, connectivity=8)
        small = stats[:, cv2.CC_STAT_AREA] < min_edge_px
        small[0] = False
        edges[small[labels]] = 0
    return edges


def distance_transform(edges: np.ndarray, truncation_px: float) -> np.ndarray:
    """Exact Euclidean distance (pixels) to the nearest edge pixel, truncated; float32 (H, W).

    Parameters
    ----------
    edges : ndarray, shape (H, W)
        Edge map, nonzero on edge pixels.
    truncation_px : float
        The largest distance kept (px).

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    # OpenCV measures the distance to the nearest zero pixel: make edges the zeros.
    dt = cv2.distanceTransform(np.where(edges > 0, 0, 255).astype(np.uint8), cv2.DIST_L2,
                               cv2.DIST_MASK_PRECISE)
    return np.minimum(dt, np.float32(truncation_px)).astype(np.float32)


def drop_masked_edges(edges: np.ndarray, mask: np.ndarray, blur_sigma: float) -> np.ndarray:
    """``edges`` (H, W) without the edge pixels on masked pixels (``mask`` False) or close
    enough to one for its intensity to have reached them: the blur's radius (OpenCV truncates
    the kernel at 3 sigma), the Sobel aperture and non-maximum suppression's neighbour. The
    border of a bonnet or a black frame is an image edge that no LiDAR point should match."""
    reach = int(np.ceil(3 * max(blur_sigma, 0.0))) + 2
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    near = cv2.dilate((~np.asarray(mask, dtype=bool)).astype(np.uint8), kernel) > 0
    out = edges.copy()
    out[near] = 0
    return out


def image_features(image_bgr: np.ndarray, blur_sigma: float = 1.0, canny_low: float = 50.0,
                   canny_high: float = 150.0, truncation_px: float = 10.0,
                   min_edge_px: int = 0, mask: np.ndarray | None = None,
                   relative: bool = False, equalize: bool = False,
                   noise_sigmas: float | None = None) -> ImageFeatures:
    """Edge map, truncated distance transform and edge pixel list of one image.

    Parameters
    ----------
    image_bgr : ndarray, shape (H, W, 3) or (H, W), uint8
        The image as taken.
    blur_sigma : float
        Gaussian sigma in pixels before Canny (0 disables the blur).
    canny_low, canny_high : float
        Canny's hysteresis thresholds on the L2 gradient magnitude.
    truncation_px : float
        The distance transform's truncation (px).
    min_edge_px : int
        Drop connected edge fragments of fewer pixels; 0 keeps all.
    mask : ndarray, shape (H, W), bool, optional
        True on usable pixels: edges on or near masked pixels are dropped before the distance
        transform (:func:`drop_masked_edges`) and ``mean_dt`` is the mean over the usable
        pixels.
    relative : bool
        Thresholds scaled to the image's exposure (:func:`canny_thresholds`).
    equalize : bool
        Local contrast equalised first (CLAHE).
    noise_sigmas : float, optional
        Thresholds from the image's gradient noise (:func:`edge_map`).

    Returns
    -------
    ImageFeatures
        The edge map, the distance transform (px), its mean, the edge pixels (E, 2) and the
        mask.
    """
    edges = edge_map(image_bgr, blur_sigma, canny_low, canny_high, min_edge_px, relative, mask,
                     equalize, noise_sigmas)
    if mask is not None:
        edges = drop_masked_edges(edges, mask, blur_sigma)
    v, u = np.nonzero(edges)
    edge_uv = np.column_stack([u, v]).astype(np.float64)
    if len(edge_uv) == 0:
        dt = np.full(edges.shape, np.float32(truncation_px))
    else:
        dt = distance_transform(edges, truncation_px)
    usable = dt if mask is None else dt[np.asarray(mask, dtype=bool)]
    mean_dt = float(usable.mean(dtype=np.float64)) if usable.size else float(truncation_px)
    return ImageFeatures(edges=edges, dt=dt, truncation_px=float(truncation_px),
                         mean_dt=mean_dt, edge_uv=edge_uv, mask=mask)
