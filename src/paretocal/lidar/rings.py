"""Laser rings of a spinning LiDAR: read from the file, or recovered from the geometry.

A spinning LiDAR's laser ``k`` sweeps a cone about the sensor's axis. Seen from the sensor
origin, a return at horizontal distance ``d`` from the axis and height ``z`` satisfies::

    z / d = a_k + h_k / d        (a_k = tan of the laser's elevation, h_k its height offset)

a straight line in the plane ``(1 / d, z / d)``. ``h_k`` is the height of the laser's own
origin above the sensor origin (up to 0.2 m on an HDL-64E, 0 on sensors whose points are
computed from one origin); it shifts the elevation of near returns by ``h / d`` (1 deg at 10 m
for 0.2 m), which is why clustering elevation angles alone fails on close, dense rings. The
line model holds for any beam count, spacing (uniform or not) and storage order.

Methods (``method`` of :func:`recover_rings`):

* ``field``: the file's ring field (``ring``, ``laser_id``, ``channel``, ``line``), checked.
* ``scan``: the file order, one laser after another (KITTI's ``.bin``): a new ring starts where
  the azimuth wraps (drops by more than pi). Exact and cheap when the order is like that.
* ``lines``: order-free. A Hough transform over ``(h, a)`` finds the strongest line, its
  points are taken (within a tolerance that follows from the line's own scatter) and their
  votes removed, and so on until no line has enough points; then k-lines refinement, removal
  of lines that other lines already explain, and merging of one laser split in two.
* ``elevation``: elevation-angle histogram clustering (kept for comparison: wrong for near
  returns of lasers with height offsets).
* ``auto`` (default): ``field`` when the file has one and it is plausible; else ``scan`` when
  every scan-order ring fits its line; else ``lines``.

Every method's result is checked against the line model (:func:`ring_purity`): the share of
points within tolerance of their ring's line, and 0 for a ring set that cannot be a spinning
multi-beam LiDAR's (fewer than :data:`MIN_RINGS` rings, or "rings" that scatter across the gaps
between them); ``Rings.notes`` say when a result is not plausible. The geometry is taken about
the sensor origin: clouds stored in another frame must be brought into the sensor frame first
(see :mod:`paretocal.lidar.sensor`); about a wrong origin the returns scatter off their
lines and the result is not plausible.

The rings of one sensor keep their lines from sweep to sweep: ``recover_rings(..., model=r)``
labels a sweep with an earlier sweep's line model (:func:`rings_from_model`) and runs the full
``lines`` recovery only when that does not fit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.ndimage import maximum_filter1d

log = logging.getLogger(__name__)

#: More rings than any spinning LiDAR has (the largest have 128): a sign of a wrong method.
MAX_RINGS = 256
#: Fewer rings than any spinning multi-beam LiDAR has (the smallest have 8, most 16 to 128):
#: a ring set with fewer is a few lasers' returns lumped together, whatever their fit.
MIN_RINGS = 8
#: Returns closer to the axis than this (m) are ignored for fitting (sensor housing, roof).
MIN_AXIS_DISTANCE_M = 0.5
#: Hough grid: ``a`` bins (tan elevation) and height offsets ``h`` (m). The a bin (0.011 deg)
#: is far below the closest beam spacing of real sensors (about 0.1 deg); |h| up to 0.4 m
#: covers every laser head (HDL-64E: 0.21 m).
HOUGH_A_BIN = 0.0002
HOUGH_H_STEP = 0.0025
HOUGH_H_MAX = 0.4
HOUGH_TAN_MAX = 1.2             # +-50 deg of elevation
HOUGH_SAMPLE = 40000            # points voting (a seeded subsample)
#: A line must gather this share of the voting points (and at least MIN_RING_POINTS): a
#: 256-beam sensor's smallest ring still holds several times more.
MIN_RING_SHARE = 0.0008
MIN_RING_POINTS = 15
#: Tolerance of a line in units of its robust scatter (MAD-based sigma).
LINE_TOL_SIGMA = 5.0
#: Two lines closer than this many pooled sigmas at their typical range are one laser split in
#: two (real neighbouring lasers lie 25 or more sigmas apart on every sensor measured) ...
MERGE_SIGMA = 10.0
#: ... when they are also closer than this share of the gap to the lines on either side. A
#: laser split in two lies nearer to itself than to the next laser, whatever the lines' scatter;
#: neighbouring lasers lie at least 0.67 of that gap apart (KITTI's HDL-64E; 0.83 on the
#: Pandar64s of aiMotive and PandaSet). Without it an axis 0.03 deg off (PandaSet's README pose)
#: smeared every Pandar64 ring to a tenth of the 0.17 deg beam spacing, and neighbouring lasers,
#: 10 sigmas apart, were merged down to 2 rings.
MERGE_SIGMA_GAP_SHARE = 0.5
#: ... or when they stay within this share of the gap to the next rings at every distance
#: (the closest distinct lasers measured, two of an HDL-64E, stay at 0.2 of their outer gaps).
MERGE_GAP_SHARE = 0.1
#: A ring set is plausible when most points lie within tolerance of their ring's line.
MIN_PURITY = 0.9
#: A point within this share of the gap to the next ring lies on its ring, however sharp the
#: ring: coordinates stored to 1 mm give rings sigmas of 1e-5, a 300th of their gap, and
#: their returns' tails reach beyond 5 such sigmas.
PURITY_GAP_FLOOR = 0.1
#: Rings are numbered by their elevation seen at this horizontal distance (m): lasers with
#: different height offsets can swap order between near and far, and "the ring above" should
#: mean the geometric neighbour where most edges are found.
ORDER_DISTANCE_M = 10.0


def ring_order(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Indices of rings ``(a, h)`` from the top down (NaN lines last), shape (R,)."""
    key = np.where(np.isfinite(a), a + np.nan_to_num(h) / ORDER_DISTANCE_M, -np.inf)
    return np.argsort(-key, kind="stable")


@dataclass(eq=False)
class Rings:
    """Ring labels of one sweep and the line model behind them.

    Attributes
    ----------
    ring : ndarray, shape (N,), int32
        Ring per point, ``0 .. n_rings - 1`` ordered from the top (highest elevation) down;
        ``-1`` for points that belong to no ring (too close to the axis, or far from every
        line).
    n_rings : int
    tan_elevation : ndarray, shape (n_rings,)
        ``a_k``: tangent of each ring's elevation (far-field), top first.
    offset_m : ndarray, shape (n_rings,)
        ``h_k`` in metres.
    method : str
        ``"field"``, ``"scan"``, ``"lines"`` or ``"elevation"``.
    purity : float
        Share of the points (beyond :data:`MIN_AXIS_DISTANCE_M`) within tolerance of their
        ring's line.
    notes : list of str
        What was tried and why it was not used, for the user.
    """

    ring: np.ndarray
    n_rings: int
    tan_elevation: np.ndarray
    offset_m: np.ndarray
    method: str
    purity: float
    notes: list = field(default_factory=list)

    @property
    def elevation_deg(self) -> np.ndarray:
        """Far-field elevation of each ring in degrees, shape (n_rings,)."""
        return np.degrees(np.arctan(self.tan_elevation))

    def spacing_deg(self) -> np.ndarray:
        """Elevation gap to the neighbouring ring(s) in degrees, shape (n_rings,): the smaller
        of the gaps above and below (the only gap for the top and bottom rings)."""
        el = self.elevation_deg
        if len(el) < 2:
            return np.full(len(el), np.nan)
        gap = np.abs(np.diff(el))
        return np.minimum(np.r_[gap[0], gap], np.r_[gap, gap[-1]])

    def summary(self) -> dict:
        """JSON-ready description (method, count, purity, spacing)."""
        sp = self.spacing_deg()
        return {"method": self.method, "n_rings": int(self.n_rings),
                "purity": round(float(self.purity), 4),
                "spacing_deg_median": None if not np.isfinite(sp).any()
                else round(float(np.nanmedian(sp)), 4),
                "unassigned": round(float(np.mean(self.ring < 0)), 4) if len(self.ring) else 0.0,
                "notes": list(self.notes)}


def azimuth(points: np.ndarray) -> np.ndarray:
    """Azimuth ``atan2(y, x)`` in [0, 2 pi), shape (N,)."""
    return np.mod(np.arctan2(points[:, 1], points[:, 0]), 2.0 * np.pi)


def elevation_deg(points: np.ndarray) -> np.ndarray:
    """Elevation angle in degrees seen from the sensor origin, shape (N,)."""
    return np.degrees(np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1])))


def _line_coords(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(z / d, 1 / d, usable)`` per point, d the distance from the sensor's z axis."""
    d = np.hypot(points[:, 0], points[:, 1])
    ok = d > MIN_AXIS_DISTANCE_M
    safe = np.where(ok, d, 1.0)
    return np.where(ok, points[:, 2] / safe, 0.0), np.where(ok, 1.0 / safe, 0.0), ok


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
    """Ring index per point from clustered elevation angles (order-free, no height offsets).

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


# --- the line model ------------------------------------------------------------------------------

def _fit_line(te: np.ndarray, inv: np.ndarray) -> tuple[float, float]:
    """Least-squares ``te = a + h inv``; h is 0 when the points span no range of distances."""
    if len(te) < 2 or np.ptp(inv) < 1e-6:
        return float(np.mean(te)) if len(te) else 0.0, 0.0
    X = np.column_stack([np.ones(len(te)), inv])
    a, h = np.linalg.lstsq(X, te, rcond=None)[0]
    return float(a), float(h)


def _sigma(r: np.ndarray) -> float:
    """Robust scatter (MAD-based sigma) of absolute residuals, floored at float32 precision."""
    return float(1.4826 * np.median(r)) + 1e-7 if len(r) else 1e-7


@njit(cache=True)
def _label_sums(te, inv, lab, n):  # pragma: no cover - compiled
    """Per label: count, sum of ``inv`` and of ``te`` (in point order, as ``np.bincount``)."""
    count = np.zeros(n)
    s_inv = np.zeros(n)
    s_te = np.zeros(n)
    for i in range(len(lab)):
        k = lab[i]
        count[k] += 1.0
        s_inv[k] += inv[i]
        s_te[k] += te[i]
    return count, s_inv, s_te


@njit(cache=True)
def _label_spread(te, inv, lab, m_inv, m_te, n):  # pragma: no cover - compiled
    """Per label: centred sums of squares and products, and the range of ``inv`` (in point
    order, as ``np.bincount`` and ``np.maximum.at``)."""
    sxx = np.zeros(n)
    sxy = np.zeros(n)
    hi = np.full(n, -np.inf)
    lo = np.full(n, np.inf)
    for i in range(len(lab)):
        k = lab[i]
        di = inv[i] - m_inv[k]                 # centred per label (no cancellation)
        sxx[k] += di * di
        sxy[k] += di * (te[i] - m_te[k])
        hi[k] = max(hi[k], inv[i])
        lo[k] = min(lo[k], inv[i])
    return sxx, sxy, hi, lo


def _group_lines(te: np.ndarray, inv: np.ndarray, lab: np.ndarray,
                 n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``te = a + h inv`` of every label at once: ``a``, ``h`` and the count,
    shapes (n,). As :func:`_fit_line`: h is 0 for a label whose points span no range of
    distances; a and h are NaN for labels without points. (Compiled passes over the points:
    five ``np.bincount`` and two ``ufunc.at`` calls were 0.3 s of a 20-sweep run.)"""
    te = np.ascontiguousarray(te, dtype=np.float64)
    inv = np.ascontiguousarray(inv, dtype=np.float64)
    lab = np.ascontiguousarray(lab, dtype=np.int64)
    count, s_inv, s_te = _label_sums(te, inv, lab, n)
    safe = np.maximum(count, 1.0)
    m_inv = s_inv / safe
    m_te = s_te / safe
    sxx, sxy, hi, lo = _label_spread(te, inv, lab, m_inv, m_te, n)
    spread = (count >= 2) & (hi - lo >= 1e-6) & (sxx > 0)
    h = np.where(spread, sxy / np.where(spread, sxx, 1.0), 0.0)
    a = m_te - h * m_inv
    empty = count == 0
    a[empty] = np.nan
    h[empty] = np.nan
    return a, h, count


@njit(cache=True)
def _label_medians(r, lab, n):  # pragma: no cover - compiled
    """Per label, the two middle values of ``r`` (equal for an odd count); NaN without
    points."""
    count = np.zeros(n, np.int64)
    for i in range(len(lab)):
        count[lab[i]] += 1
    start = np.zeros(n + 1, np.int64)
    for k in range(n):
        start[k + 1] = start[k] + count[k]
    fill = start[:n].copy()
    grouped = np.empty(len(r))
    for i in range(len(lab)):
        grouped[fill[lab[i]]] = r[i]
        fill[lab[i]] += 1
    lo = np.full(n, np.nan)
    hi = np.full(n, np.nan)
    for k in range(n):
        m = count[k]
        if m > 0:
            k1 = (m - 1) // 2
            seg = np.partition(grouped[start[k]:start[k + 1]], k1)
            lo[k] = seg[k1]
            hi[k] = seg[k1] if m % 2 else seg[k1 + 1:].min()
    return lo, hi


def _group_sigma(r: np.ndarray, lab: np.ndarray, n: int) -> np.ndarray:
    """:func:`_sigma` of the absolute residuals ``r`` of every label, shape (n,) (NaN for
    labels without points)."""
    if len(r) == 0:
        return np.full(n, np.nan)
    lo, hi = _label_medians(np.ascontiguousarray(r, dtype=np.float64),
                            np.ascontiguousarray(lab, dtype=np.int64), n)
    return 1.4826 * (0.5 * (lo + hi)) + 1e-7


def fit_ring_lines(te: np.ndarray, inv: np.ndarray, labels: np.ndarray,
                   n_rings: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit each labelled ring's line robustly: a least-squares line, then again on the points
    within :data:`LINE_TOL_SIGMA` robust sigmas of it. All rings at once (no loop over rings).

    Parameters
    ----------
    te, inv : ndarray, shape (N,)
        ``z / d`` and ``1 / d`` per point.
    labels : ndarray, shape (N,), int
        Ring per point, 0 .. n_rings - 1.
    n_rings : int

    Returns
    -------
    a, h, sigma : ndarray, shape (n_rings,)
        The lines ``te = a + h inv`` and their robust scatter; NaN for rings with fewer than
        two points.
    """
    lab = np.asarray(labels, dtype=np.int64)
    nan = np.full(n_rings, np.nan)
    if n_rings == 0 or len(lab) == 0:
        return nan, nan.copy(), nan.copy()
    a1, h1, count = _group_lines(te, inv, lab, n_rings)
    r = np.abs(te - a1[lab] - h1[lab] * inv)
    s1 = _group_sigma(r, lab, n_rings)
    inl = r < LINE_TOL_SIGMA * s1[lab]
    a2, h2, count2 = _group_lines(te[inl], inv[inl], lab[inl], n_rings)
    s2 = _group_sigma(np.abs(te[inl] - a2[lab[inl]] - h2[lab[inl]] * inv[inl]), lab[inl],
                      n_rings)
    refit = count2 >= 2
    a = np.where(refit, a2, a1)
    h = np.where(refit, h2, h1)
    s = np.where(refit, s2, s1)
    few = count < 2
    a[few], h[few], s[few] = np.nan, np.nan, np.nan
    return a, h, s


def ring_purity(points: np.ndarray, ring: np.ndarray) -> float:
    """Share of the points (beyond the axis distance limit) within tolerance of their ring's
    fitted line; points without a ring (-1) count as impure.

    The tolerance is a line's own scatter (:data:`LINE_TOL_SIGMA` sigmas, never below the
    typical ring's, nor below :data:`PURITY_GAP_FLOOR` of the gap to the neighbouring rings)
    but at most a quarter of that gap. A ring set is
    only pure when it is one of a spinning multi-beam LiDAR: fewer than :data:`MIN_RINGS`
    rings give 0, and a ring whose tolerance band (:data:`LINE_TOL_SIGMA` of its own sigmas)
    reaches past the middle of the gap to its neighbour is no laser's ring (a "ring" that mixes
    several lasers scatters across their gaps) and its points count as impure.
    """
    te, inv, ok = _line_coords(np.asarray(points, dtype=np.float64))
    ring = np.asarray(ring)
    n = int(ring.max()) + 1 if len(ring) and ring.max() >= 0 else 0
    if not ok.any() or n < 2:
        return 0.0
    sel = ok & (ring >= 0)
    lab = ring[sel]
    a, h, s = fit_ring_lines(te[sel], inv[sel], lab, n)
    good = np.isfinite(a)
    if good.sum() < MIN_RINGS:
        return 0.0
    typical = float(np.median(inv[sel]))
    at = np.where(good, a + np.nan_to_num(h) * typical, np.nan)
    order = np.argsort(at)[: good.sum()]                 # NaNs sort last
    gaps = np.diff(at[order])
    spacing = np.full(n, np.nan)
    spacing[order] = np.minimum(np.r_[np.inf, gaps], np.r_[gaps, np.inf])
    sharp = good & (LINE_TOL_SIGMA * np.nan_to_num(s, nan=np.inf) < 0.5 * np.nan_to_num(spacing))
    tol = np.minimum(np.maximum(LINE_TOL_SIGMA * np.maximum(s, np.nanmedian(s)),
                                PURITY_GAP_FLOOR * spacing), 0.25 * spacing)
    r = np.abs(te[sel] - a[lab] - h[lab] * inv[sel])
    inside = sharp[lab] & (r < np.nan_to_num(tol[lab], nan=0.0))
    return float(inside.sum() / ok.sum())


def _votes(te: np.ndarray, inv: np.ndarray, H: np.ndarray, n_a: int) -> np.ndarray:
    """Flat accumulator cells voted by each point for every h (the line ``a = te - h inv``)."""
    ia = np.floor((te[None, :] - H[:, None] * inv[None, :] + HOUGH_TAN_MAX)
                  / HOUGH_A_BIN).astype(np.int64)
    ok = (ia >= 0) & (ia < n_a)
    return (np.arange(len(H))[:, None] * n_a + ia)[ok]


def extract_lines(te: np.ndarray, inv: np.ndarray) -> list[tuple[float, float, float]]:
    """Greedy Hough extraction: strongest line first, its points' votes removed, repeat.

    Returns ``(a, h, sigma)`` per line found.
    """
    H = np.arange(-HOUGH_H_MAX, HOUGH_H_MAX + 0.5 * HOUGH_H_STEP, HOUGH_H_STEP)
    n_a = int(np.ceil(2 * HOUGH_TAN_MAX / HOUGH_A_BIN)) + 1
    size = len(H) * n_a

    def smoothed(cells):
        # Votes of a 3-bin box along a, so that a line straddling two bins is one peak.
        acc = np.bincount(cells, minlength=size).astype(np.float32)
        sm = acc.copy()
        sm[1:] += acc[:-1]
        sm[:-1] += acc[1:]
        return sm

    def unsmooth(cells):
        # Take a line's votes out of the smoothed accumulator where they fell (the whole
        # accumulator rebuilt per line cost seconds on clouds with hundreds of lines). The
        # counts are whole numbers, exact in float32: the same values as a rebuild.
        u, cnt = np.unique(cells, return_counts=True)
        cnt = cnt.astype(np.float32)
        acc[u] -= cnt
        up = u + 1 < size
        acc[u[up] + 1] -= cnt[up]
        dn = u >= 1
        acc[u[dn] - 1] -= cnt[dn]

    acc = smoothed(_votes(te, inv, H, n_a))
    alive = np.ones(len(te), dtype=bool)
    min_votes = max(MIN_RING_POINTS, MIN_RING_SHARE * len(te))
    lines = []
    # Tolerance around a Hough peak: two a bins plus the error of h quantised to its step.
    tol0 = 2 * HOUGH_A_BIN + 0.5 * HOUGH_H_STEP * inv
    for _ in range(4 * MAX_RINGS):
        k = int(np.argmax(acc))
        if acc[k] < min_votes:
            break
        ih, ia = divmod(k, n_a)
        a, h = (ia + 0.5) * HOUGH_A_BIN - HOUGH_TAN_MAX, H[ih]
        m = alive & (np.abs(te - a - h * inv) < tol0)
        for _ in range(3):
            if m.sum() < min_votes:
                break
            a, h = _fit_line(te[m], inv[m])
            r = np.abs(te - a - h * inv)
            s = _sigma(r[m])
            m = alive & (r < np.minimum(LINE_TOL_SIGMA * s, tol0))
        if m.sum() < min_votes:
            # Not a line: clear the peak so that the next one is looked at.
            acc[max(k - 1, 0):k + 2] = 0
            continue
        lines.append((a, h, _sigma(np.abs(te[m] - a - h * inv[m]))))
        unsmooth(_votes(te[m], inv[m], H, n_a))
        alive &= ~m
    return lines


#: Points labelled at a time: the (points, lines) residual matrix then stays near 32 MB.
LABEL_BLOCK = 1 << 15


def nearest_line(te: np.ndarray, inv: np.ndarray, a: np.ndarray,
                 h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest line ``te = a + h inv`` per point and its absolute residual,
    shapes (N,) and (N,), computed block by block (bounded memory for any cloud size)."""
    lab = np.empty(len(te), dtype=np.int64)
    res = np.empty(len(te), dtype=np.float64)
    for i in range(0, len(te), LABEL_BLOCK):
        r = np.abs(te[i:i + LABEL_BLOCK, None]
                   - (a[None, :] + h[None, :] * inv[i:i + LABEL_BLOCK, None]))
        k = r.argmin(axis=1)
        lab[i:i + LABEL_BLOCK] = k
        res[i:i + LABEL_BLOCK] = r[np.arange(len(k)), k]
    return lab, res


def _k_lines(te: np.ndarray, inv: np.ndarray, a: np.ndarray, h: np.ndarray,
             iters: int, min_points: int):
    """Assign every point to its nearest line and refit; drop lines left with few points."""
    s = np.full(len(a), np.nan)
    for _ in range(iters):
        lab = np.abs(te[:, None] - (a[None, :] + h[None, :] * inv[:, None])).argmin(axis=1)
        a, h, s = fit_ring_lines(te, inv, lab, len(a))
        keep = np.isfinite(a) & (np.bincount(lab, minlength=len(a)) >= min_points)
        a, h, s = a[keep], h[keep], s[keep]
    return a, h, s


def _prune(te: np.ndarray, inv: np.ndarray, a: np.ndarray, h: np.ndarray, s: np.ndarray):
    """Remove lines whose points other lines explain (a mixture of two lasers' returns)."""
    res = np.abs(te[:, None] - (a[None, :] + h[None, :] * inv[:, None]))
    lab = res.argmin(axis=1)
    counts = np.bincount(lab, minlength=len(a))
    alive = np.ones(len(a), dtype=bool)
    tol = LINE_TOL_SIGMA * np.maximum(s, np.median(s))
    for k in np.argsort(counts):
        m = lab == k
        others = np.flatnonzero(alive & (np.arange(len(a)) != k))
        if len(others) == 0:
            break
        if not m.any():
            alive[k] = False
            continue
        rk = res[m][:, others] / tol[others][None, :]
        if np.mean(rk.min(axis=1) < 1.0) >= 0.7:
            alive[k] = False
            lab[m] = others[rk.argmin(axis=1)]
    return a[alive], h[alive]


def _merge_split(te: np.ndarray, inv: np.ndarray, a: np.ndarray, h: np.ndarray,
                 s: np.ndarray, min_points: int):
    """Merge neighbouring lines that are one laser split in two.

    Two neighbouring lines are one laser when they are closer than :data:`MERGE_SIGMA` pooled
    sigmas and :data:`MERGE_SIGMA_GAP_SHARE` of the gap to the next lines at their typical
    distance (the sigmas alone do not follow the beam spacing: a slightly wrong frame smears
    every ring alike), or when, over the whole range of distances seen, they
    stay closer to each other than :data:`MERGE_GAP_SHARE` of the gap to the next lines (the
    near returns of a laser can follow a slightly different line than its far returns).
    """
    lo, hi = np.percentile(inv, [1, 99])
    while len(a) > 2:
        lab = np.abs(te[:, None] - (a[None, :] + h[None, :] * inv[:, None])).argmin(axis=1)
        typical = np.array([np.median(inv[lab == k]) if (lab == k).any() else np.median(inv)
                            for k in range(len(a))])
        order = ring_order(a, h)
        a, h, s, typical = a[order], h[order], s[order], typical[order]
        pooled = np.sqrt(0.5 * (s[:-1] ** 2 + s[1:] ** 2))
        at = 0.5 * (typical[:-1] + typical[1:])
        sep_at = np.abs((a[:-1] - a[1:]) + (h[:-1] - h[1:]) * at)
        sep = sep_at / pooled
        # Largest separation of each neighbouring pair over the range, and the smallest gap
        # between a pair and the lines on either side of it.
        ends = np.array([lo, hi])
        gap = (a[:-1, None] - a[1:, None]) + (h[:-1, None] - h[1:, None]) * ends[None, :]
        sep_max = np.abs(gap).max(axis=1)
        gap_min = np.abs(gap).min(axis=1)
        outer = np.minimum(np.r_[np.inf, gap_min[:-1]], np.r_[gap_min[1:], np.inf])
        by_sigma = np.where(sep_at < MERGE_SIGMA_GAP_SHARE * outer, sep / MERGE_SIGMA, np.inf)
        score = np.minimum(by_sigma, sep_max / (MERGE_GAP_SHARE * outer))
        k = int(np.argmin(score))
        if score[k] >= 1.0:
            break
        # Drop the pair's weaker line; the k-lines pass gives its points to the stronger one.
        counts = np.bincount(np.abs(te[:, None] - (a[None, :] + h[None, :] * inv[:, None]))
                             .argmin(axis=1), minlength=len(a))
        drop = k if counts[k] < counts[k + 1] else k + 1
        keep = np.arange(len(a)) != drop
        a, h, s = _k_lines(te, inv, a[keep], h[keep], 2, min_points)
    return a, h, s


def rings_from_lines(points: np.ndarray, rng: np.random.Generator | int | None = 0) -> Rings:
    """Order-free ring recovery from the line model (see the module docstring).

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        The sweep in the sensor frame (metres).
    rng : numpy Generator or seed
        Drives the subsample of points that vote in the Hough transform.

    Returns
    -------
    Rings
    """
    rng = np.random.default_rng(rng)
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    te, inv, ok = _line_coords(pts)
    idx = np.flatnonzero(ok)
    ring = np.full(len(pts), -1, dtype=np.int32)
    if len(idx) < MIN_RING_POINTS:
        return Rings(ring, 0, np.zeros(0), np.zeros(0), "lines", 0.0,
                     [f"only {len(idx)} returns beyond {MIN_AXIS_DISTANCE_M} m of the axis"])
    sample = np.sort(rng.choice(idx, min(len(idx), HOUGH_SAMPLE), replace=False))
    lines = extract_lines(te[sample], inv[sample])
    if not lines:
        return Rings(ring, 0, np.zeros(0), np.zeros(0), "lines", 0.0,
                     ["no laser ring found in the line model"])
    a0, h0, _ = (np.array(v) for v in zip(*lines))
    min_points = max(MIN_RING_POINTS, int(MIN_RING_SHARE * len(sample)))
    ts, ivs = te[sample], inv[sample]
    a, h, s = _k_lines(ts, ivs, a0, h0, 3, min_points)
    a, h = _prune(ts, ivs, a, h, s)
    a, h, s = _k_lines(ts, ivs, a, h, 2, min_points)
    a, h, s = _merge_split(ts, ivs, a, h, s, min_points)
    # Judged like every other method's labels: lines found in the wrong frame explain their
    # own points (their tolerance grows with their scatter) but are no laser's rings.
    return _label_rings(pts, te[idx], inv[idx], idx, a, h, np.maximum(s, np.median(s)))


def _label_rings(pts: np.ndarray, te: np.ndarray, inv: np.ndarray, idx: np.ndarray,
                 a: np.ndarray, h: np.ndarray, sigma: np.ndarray) -> Rings:
    """Rings from lines ``(a, h)`` (K,): every point ``idx`` of ``pts`` (with line coordinates
    ``te``, ``inv``) takes its nearest line's ring when within twice
    :data:`LINE_TOL_SIGMA` x ``sigma`` of it (others -1); rings numbered by
    :func:`ring_order`."""
    ring = np.full(len(pts), -1, dtype=np.int32)
    lab, res = nearest_line(te, inv, a, h)
    within = res < LINE_TOL_SIGMA * sigma[lab] * 2.0
    order = ring_order(a, h)
    rank = np.empty(len(order), dtype=np.int32)
    rank[order] = np.arange(len(order), dtype=np.int32)
    ring[idx[within]] = rank[lab[within]]
    return Rings(ring, len(a), a[order], h[order], "lines", ring_purity(pts, ring))


#: k-lines passes when a sweep is labelled with a previous sweep's line model: the rings of
#: one sensor move by less than their scatter between sweeps, so two passes settle them.
MODEL_PASSES = 2


def rings_from_model(points: np.ndarray, model: Rings, view: np.ndarray | None = None) -> Rings:
    """Label a sweep with the line model of an earlier sweep of the same sensor.

    Every point takes the nearest of the model's lines ``(a_k, h_k)``, the lines are refitted
    to their points (:data:`MODEL_PASSES` k-lines passes; a line without points in this sweep
    keeps the model's), and the points within tolerance of their line keep its ring. The ring
    numbers are the model's where the lines keep their order. Much cheaper than
    :func:`rings_from_lines` (no Hough transform); judge the result by its ``purity``.

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        The sweep in the sensor frame (metres).
    model : Rings
        An earlier sweep's rings (its ``tan_elevation`` and ``offset_m``).
    view : ndarray, shape (N,), bool, optional
        Refit the lines to these returns only (where the rings are used, see
        :func:`recover_rings`); every return is still labelled.

    Returns
    -------
    Rings
        With ``method`` "lines".
    """
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    te, inv, ok = _line_coords(pts)
    idx = np.flatnonzero(ok)
    ring = np.full(len(pts), -1, dtype=np.int32)
    a = np.asarray(model.tan_elevation, dtype=np.float64)
    h = np.nan_to_num(np.asarray(model.offset_m, dtype=np.float64))
    keep = np.isfinite(a)
    a, h = a[keep], h[keep]
    if len(a) == 0 or len(idx) == 0:
        return Rings(ring, 0, np.zeros(0), np.zeros(0), "lines", 0.0,
                     ["the line model has no rings" if len(a) == 0 else
                      f"no returns beyond {MIN_AXIS_DISTANCE_M} m of the axis"])
    fit = idx if view is None else idx[view[idx]]
    ti, ii = te[fit], inv[fit]
    s = np.full(len(a), np.nan)
    for _ in range(MODEL_PASSES):
        lab, _ = nearest_line(ti, ii, a, h)
        an, hn, sn = fit_ring_lines(ti, ii, lab, len(a))
        fitted = np.isfinite(an)
        a, h, s = np.where(fitted, an, a), np.where(fitted, hn, h), np.where(fitted, sn, s)
    s_typ = float(np.nanmedian(s)) if np.isfinite(s).any() else 0.0
    # No note: ``notes`` are problems the user is told about, and this is not one.
    return _label_rings(pts, te[idx], inv[idx], idx, a, h,
                        np.maximum(np.nan_to_num(s, nan=s_typ), s_typ))


# --- choosing a method ---------------------------------------------------------------------------

def _as_rings(points: np.ndarray, ring: np.ndarray, method: str, notes=()) -> Rings:
    """Wrap labels into :class:`Rings`, renumbered top first, with their line model."""
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    ring = np.asarray(ring).astype(np.int64)
    te, inv, ok = _line_coords(pts)
    valid = ring >= 0
    ids, inverse = np.unique(ring[valid], return_inverse=True)
    lab = np.full(len(ring), -1, dtype=np.int64)
    lab[valid] = inverse
    n = len(ids)
    sel = ok & valid
    a, h, _ = fit_ring_lines(te[sel], inv[sel], lab[sel], n) if n else (np.zeros(0),) * 3
    order = ring_order(a, h)
    rank = np.empty(n, dtype=np.int32)
    rank[order] = np.arange(n, dtype=np.int32)
    out = np.where(valid, rank[np.maximum(lab, 0)], -1).astype(np.int32)
    purity = ring_purity(pts, out) if n else 0.0
    return Rings(out, n, a[order], h[order], method, purity, list(notes))


def recover_rings(points: np.ndarray, method: str = "auto", ring_field: np.ndarray | None = None,
                  rng: np.random.Generator | int | None = 0, source: str = "",
                  model: Rings | None = None, view: np.ndarray | None = None) -> Rings:
    """Rings of one sweep (see the module docstring for ``method``).

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        The sweep in the sensor frame (metres), in the file's order.
    method : {"auto", "field", "scan", "lines", "elevation"}
    ring_field : ndarray, shape (N,), optional
        The file's ring values.
    rng : numpy Generator or seed
        For the ``lines`` method's subsample.
    source : str
        The file, named in notes and warnings.
    model : Rings, optional
        The rings of an earlier sweep of the same sensor (in its sensor frame). Where the
        ``lines`` method would run, the sweep is first labelled with this line model
        (:func:`rings_from_model`, about 10 times cheaper); the full recovery runs only when
        that result is not plausible (fewer than :data:`MIN_RINGS` rings or purity below
        :data:`MIN_PURITY`).
    view : ndarray, shape (N,), bool, optional
        The returns the features are taken from (those near a camera's view). When given,
        every candidate ring set is judged (its ``purity``) on these returns alone: a sweep
        whose points were moved into one frame (motion-compensated while the vehicle drove
        and pitched) keeps its returns on their lasers' cones only where it was recorded near
        that frame's time, and the rings matter only where the features are taken.

    Returns
    -------
    Rings
        ``notes`` says what was tried and why the result was chosen, and says so when the
        result is not a plausible ring set.
    """
    if method not in ("auto", "field", "scan", "lines", "elevation"):
        raise ValueError(f"unknown ring method {method!r}")
    where = f"{source}: " if source else ""
    notes: list[str] = []
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    view = _usable_view(pts, view)

    def judged(r: Rings) -> Rings:
        if view is not None:
            r.purity = ring_purity(pts[view], r.ring[view]) if r.n_rings >= MIN_RINGS else 0.0
        return r

    if method in ("auto", "field") and ring_field is not None:
        r = judged(_as_rings(pts, ring_field, "field"))
        if method == "field" or (MIN_RINGS <= r.n_rings <= MAX_RINGS
                                  and r.purity >= MIN_PURITY):
            return _noted(r, where)
        notes.append(f"{where}the ring field gives {r.n_rings} rings with purity "
                     f"{r.purity:.2f} (below {MIN_PURITY}); rings recovered from the geometry "
                     "instead")
    elif method == "field":
        raise ValueError("ring method 'field' needs a ring field")
    if method == "elevation":
        return _noted(judged(_as_rings(pts, rings_from_elevation(pts), "elevation")), where)
    if method in ("auto", "scan"):
        scan = rings_from_scan_order(pts)
        n = int(scan.max()) + 1
        if method == "scan":
            return _noted(judged(_as_rings(pts, scan, "scan")), where)
        if MIN_RINGS <= n <= MAX_RINGS:
            r = judged(_as_rings(pts, scan, "scan", notes))
            if r.purity >= MIN_PURITY:
                return r
    if model is not None:
        r = judged(rings_from_model(pts, model, view))
        if r.n_rings >= MIN_RINGS and r.purity >= MIN_PURITY:
            r.notes = notes + r.notes
            return r
        notes.append(f"{where}the earlier sweep's line model gives {r.n_rings} rings with "
                     f"purity {r.purity:.2f}; rings recovered from this sweep instead")
    r = judged(rings_from_lines(pts, rng))
    r.notes = notes + r.notes
    return _noted(r, where)


#: A view with fewer returns than the smallest ring set the line model can judge (MIN_RINGS
#: rings of MIN_RING_POINTS each) judges nothing: the whole sweep is judged instead.
MIN_VIEW_POINTS = MIN_RINGS * MIN_RING_POINTS


def _usable_view(points: np.ndarray, view: np.ndarray | None) -> np.ndarray | None:
    """``view`` as a boolean mask over ``points``, or None when there is none to judge by."""
    if view is None:
        return None
    view = np.asarray(view, dtype=bool)
    if view.shape != (len(points),):
        raise ValueError(f"view has shape {view.shape}; expected ({len(points)},)")
    return view if view.sum() >= MIN_VIEW_POINTS else None


def _noted(r: Rings, where: str = "") -> Rings:
    """``r`` with a note when it is no plausible ring set of a spinning multi-beam LiDAR."""
    if 0 < r.n_rings < MIN_RINGS:
        r.notes.append(f"{where}only {r.n_rings} rings, fewer than any spinning multi-beam "
                       f"LiDAR has ({MIN_RINGS}): not the sensor's rings (points not in the "
                       "sensor frame?)")
    elif r.n_rings == 0:
        r.notes.append(f"{where}no rings found")
    if r.purity < MIN_PURITY:
        r.notes.append(f"{where}{r.n_rings} rings with purity {r.purity:.2f} (below "
                       f"{MIN_PURITY}): the points do not lie on the rings' lines (rings mixed, "
                       "or points not in the sensor frame)")
    return r
