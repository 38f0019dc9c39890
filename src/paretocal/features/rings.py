"""Laser ring recovery for spinning LiDARs whose files carry no ring field (KITTI ``.bin``).

Two methods:

* ``scan``: KITTI writes each laser's sweep in turn, azimuth increasing; a new ring starts where
  the azimuth wraps, i.e. drops by more than pi. Exact on unshuffled KITTI sweeps.
* ``elevation``: cluster the elevation angles (histogram peaks at 0.05 deg, peaks closer than
  0.12 deg merged). Works on shuffled or cropped clouds; less exact for close points, whose
  elevation seen from the sensor origin is shifted by the lasers' mounting offsets.

``auto`` tries ``scan`` and falls back to ``elevation`` when the scan order does not look like
rings (too many rings, or rings that do not span the sweep).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d

MAX_RINGS = 128


def azimuth(points: np.ndarray) -> np.ndarray:
    """Azimuth ``atan2(y, x)`` in [0, 2 pi), shape (N,)."""
    return np.mod(np.arctan2(points[:, 1], points[:, 0]), 2.0 * np.pi)


def elevation_deg(points: np.ndarray) -> np.ndarray:
    """Elevation angle in degrees seen from the sensor origin, shape (N,)."""
    return np.degrees(np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1])))


def rings_from_scan_order(points: np.ndarray, min_ring_points: int = 50) -> np.ndarray:
    """Ring index per point from the file order (azimuth wrap); tiny segments join a neighbour.

    Returns
    -------
    ring : ndarray, shape (N,), int32, values 0 .. R-1 in file order
    """
    psi = azimuth(points)
    start = np.empty(len(points), dtype=bool)
    start[0] = True
    start[1:] = np.diff(psi) < -np.pi
    ring = np.cumsum(start) - 1
    # A few returns jitter across azimuth 0 at a ring's start: such tiny segments are not rings.
    counts = np.bincount(ring)
    small = counts < min_ring_points
    if small.any() and not small.all():
        keep = np.cumsum(~small) - 1           # index of the last big ring at or before each id
        keep = np.where(keep < 0, 0, keep)
        ring = keep[ring]
    return ring.astype(np.int32)


def rings_from_elevation(points: np.ndarray, bin_deg: float = 0.05,
                         merge_deg: float = 0.12) -> np.ndarray:
    """Ring index per point from clustered elevation angles (order-free).

    Returns
    -------
    ring : ndarray, shape (N,), int32, values 0 .. R-1 ordered from the top ring down
    """
    el = elevation_deg(points)
    lo, hi = np.floor(el.min()) - bin_deg, np.ceil(el.max()) + bin_deg
    hist, edges = np.histogram(el, bins=max(1, int(round((hi - lo) / bin_deg))), range=(lo, hi))
    centres = 0.5 * (edges[1:] + edges[:-1])
    win = max(1, int(round(merge_deg / bin_deg)))
    peaks = np.flatnonzero((hist == maximum_filter1d(hist, 2 * win + 1)) &
                           (hist >= max(5, 0.002 * len(points))))
    if len(peaks) == 0:
        return np.zeros(len(points), dtype=np.int32)
    centres_p = centres[peaks]
    merged = [centres_p[0]]
    for c in centres_p[1:]:
        if c - merged[-1] < merge_deg:
            merged[-1] = 0.5 * (merged[-1] + c)
        else:
            merged.append(c)
    centres_p = np.array(merged[::-1])            # top ring first
    bounds = 0.5 * (centres_p[1:] + centres_p[:-1])
    return np.searchsorted(-bounds, -el).astype(np.int32)


def recover_rings(points: np.ndarray, method: str = "auto") -> np.ndarray:
    """Ring index per point, shape (N,) int32 (see the module docstring for ``method``)."""
    if method not in ("auto", "scan", "elevation"):
        raise ValueError(f"unknown ring method {method!r}")
    if method in ("auto", "scan"):
        ring = rings_from_scan_order(points)
        if method == "scan" or _looks_like_rings(points, ring):
            return ring
    return rings_from_elevation(points)


def _looks_like_rings(points: np.ndarray, ring: np.ndarray) -> bool:
    """Scan-order rings are plausible: not too many, and most of them span most of the sweep."""
    n = int(ring.max()) + 1
    if n > MAX_RINGS or n < 2:
        return False
    psi = azimuth(points)
    order = np.argsort(ring, kind="stable")
    r, p = ring[order], psi[order]
    starts = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
    span = np.maximum.reduceat(p, starts) - np.minimum.reduceat(p, starts)
    return np.median(span) > np.pi
