"""LiDAR features: depth-discontinuity edges, reflectance edges and smooth-surface points.

Edges are found along each laser ring (neighbouring returns of one laser) and across rings
(the return of the laser above or below at the same azimuth). Only the near side of a depth jump
is an edge (Levinson & Thrun, RSS 2013): the far side lies on the background. An edge point is
placed at the angular midpoint between the near return and its far neighbour, at the near range:
the true occluding contour lies between the two rays, and placing it on the near ray would bias
the calibration by half a beam spacing. The fraction of the way towards the far ray is a setting
for each direction (along and across rings), 0.5 by default.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lidar.rings import Rings, azimuth, recover_rings

DEPTH_EDGE, INTENSITY_EDGE, SMOOTH = 0, 1, 2
GROUP_NAMES = ("depth_edge", "intensity_edge", "smooth")

#: Grazing angle (deg) below which a surface is not trusted to continue across rings: a
#: surface seen at angle beta changes range by ``r * gap / tan(beta)`` between rings ``gap``
#: radians apart, so a larger jump is a depth edge. 1.6 deg reproduces, on the 0.42 deg median
#: ring spacing of an HDL-64E, the ``0.25 r`` rule that was measured best there; on a 16-beam
#: sensor (2 deg) it asks for ``1.25 r``, so the ground at grazing angles makes no edges.
GRAZING_MIN_DEG = 1.6
#: Neighbours along a ring more than this many azimuth steps apart (the sensor's median step)
#: are not compared: returns are missing in between. On KITTI (0.17 deg steps) this is 1 deg.
MAX_GAP_STEPS = 6.0
#: Neighbouring returns are recorded within a few firings of each other; two returns more than
#: this share of the sweep's duration apart lie on either side of the seam.
MAX_NEIGHBOUR_DT_SWEEPS = 0.5
#: Range tolerance of "the same surface" between neighbouring returns: 5 % of the range (a
#: surface seen at grazing incidence) plus 10 cm (range noise).
SAME_SURFACE_REL = 0.05
SAME_SURFACE_M = 0.1


@dataclass(eq=False)
class LidarFeatures:
    """Feature points of one sweep, in the LiDAR frame.

    Attributes
    ----------
    xyz : ndarray, shape (M, 3), float64
        Positions in metres.
    group : ndarray, shape (M,), int8
        ``DEPTH_EDGE``, ``INTENSITY_EDGE`` or ``SMOOTH``.
    strength : ndarray, shape (M,), float64
        Depth jump in metres (depth edges), reflectance jump (intensity edges), 0 (smooth).
    n_rings : int
        Rings recovered from the sweep.
    source : ndarray, shape (M,), int64
        Index, in the input points, of the return each feature point comes from (the near
        return of an edge), e.g. to look up its time.
    """

    xyz: np.ndarray
    group: np.ndarray
    strength: np.ndarray
    n_rings: int
    source: np.ndarray | None = None


def _between_rays(p: np.ndarray, q: np.ndarray, r: np.ndarray, t: float) -> np.ndarray:
    """Points at range ``r`` on the ray a fraction ``t`` of the way from ray ``p`` to ray ``q``."""
    a = p / np.linalg.norm(p, axis=1, keepdims=True)
    b = q / np.linalg.norm(q, axis=1, keepdims=True)
    m = (1.0 - t) * a + t * b
    return m / np.linalg.norm(m, axis=1, keepdims=True) * r[:, None]


def _ring_neighbours(ring: np.ndarray, psi: np.ndarray, max_gap_deg: float | None,
                     times: tuple[np.ndarray, float] | None):
    """Circular neighbours along each ring (the ring's start follows its end).

    ``ring`` and ``psi`` (azimuth, rad) are (n,), sorted by ring then azimuth. Returns the next
    and previous index along the ring, whether each is a usable neighbour (within the azimuth
    gap, not the point itself, and, with ``times = (t, max_dt)``, recorded within ``max_dt`` s
    of it) and the gap (rad): ``max_gap_deg``, by default :data:`MAX_GAP_STEPS` median azimuth
    steps.
    """
    n = len(ring)
    first = np.r_[True, ring[1:] != ring[:-1]]
    last = np.r_[ring[1:] != ring[:-1], True]
    start_of = np.maximum.accumulate(np.where(first, np.arange(n), 0))
    end_idx = np.flatnonzero(last)
    end_of = end_idx[np.cumsum(first) - 1]
    nxt = np.where(last, start_of, np.arange(n) + 1)
    prv = np.where(first, end_of, np.arange(n) - 1)
    if max_gap_deg is None:
        step = np.mod(psi[nxt] - psi, 2 * np.pi)
        step = step[(step > 0) & (nxt != np.arange(n))]
        max_gap_deg = MAX_GAP_STEPS * float(np.degrees(np.median(step))) if len(step) else 1.0
    gap = np.radians(max_gap_deg)
    dpsi_n = np.mod(psi[nxt] - psi, 2 * np.pi)
    dpsi_p = np.mod(psi - psi[prv], 2 * np.pi)
    ok_n = (dpsi_n < gap) & (nxt != np.arange(n))
    ok_p = (dpsi_p < gap) & (prv != np.arange(n))
    if times is not None:
        t, max_dt = times
        ok_n &= np.abs(t[nxt] - t) < max_dt
        ok_p &= np.abs(t[prv] - t) < max_dt
    return nxt, prv, ok_n, ok_p, gap


def _ring_geometry(ring_elevation_deg, n_rings: int, ring_spacing_deg: float | None,
                   cross_jump_rel: float | None) -> tuple[np.ndarray | None, float | None]:
    """The rings' elevations (deg, None unless known and finite for every ring) and the
    relative cross-ring jump: as given, else (without elevations) from the ring spacing at the
    shallowest grazing angle (:data:`GRAZING_MIN_DEG`)."""
    el = None
    if ring_elevation_deg is not None and len(ring_elevation_deg) >= n_rings > 1:
        el = np.asarray(ring_elevation_deg, dtype=np.float64)
        if not np.isfinite(el[:n_rings]).all():
            el = None
    if cross_jump_rel is None and el is None:
        spacing = ring_spacing_deg if ring_spacing_deg and np.isfinite(ring_spacing_deg) else 0.42
        cross_jump_rel = np.radians(spacing) / np.tan(np.radians(GRAZING_MIN_DEG))
    return el, cross_jump_rel


def lidar_features(  # noqa: PLR0913 - keyword-only options, each documented
        points: np.ndarray, *, depth_jump_m: float = 1.0, cross_ring: bool = True,
        cross_jump_m: float = 0.3, cross_jump_rel: float | None = None,
        ground_tol_m: float | None = None,
        intensity_jump: float = 0.5, min_range_m: float = 1.5,
        max_range_m: float = 70.0, max_gap_deg: float | None = None,
        smooth_ratio: float = 1.0, ring_method: str = "auto",
        along_fraction: float = 0.5, cross_fraction: float = 0.25,
        edge_support: bool = False, edge_contour: bool = False,
        rng: np.random.Generator | int | None = 0,
        ring: np.ndarray | Rings | None = None,
        ring_spacing_deg: float | None = None,
        ring_elevation_deg: np.ndarray | None = None,
        time: np.ndarray | None = None,
        sweep_s: float | None = None, sky_edges: bool = False) -> LidarFeatures:
    """Extract feature points from one sweep.

    Parameters
    ----------
    points : ndarray, shape (N, 4)
        ``x, y, z`` in metres in the sensor frame (origin on the spinning axis, z along it)
        and intensity, in scan order when available.
    depth_jump_m : float
        Minimum range difference to the next return along the ring for a depth edge.
    cross_ring : bool
        Also detect edges against the ring above and below (horizontal contours).
    cross_jump_m, cross_jump_rel : float
        Across rings the far return must be farther by ``max(cross_jump_m, cross_jump_rel * r)``
        (the relative part keeps the ground, seen at grazing angles, from making edges).
        ``None`` (default) derives ``cross_jump_rel`` from the elevation gap between the two
        rings compared and :data:`GRAZING_MIN_DEG` (per pair when the rings' elevations are
        known, so that sensors with uneven spacing, dense at the horizon and sparse below,
        get the threshold each pair of lasers needs).
    ground_tol_m : float, optional
        When set, a pair across rings whose two returns both lie within this height of the
        ground (the 5th percentile of z within 30 m) is never an edge, which lets a smaller
        ``cross_jump_rel`` find far horizontal contours without ground artefacts.
    intensity_jump : float
        Minimum intensity difference between neighbours on one surface for an intensity edge,
        as a fraction of the sweep's 99th-percentile intensity (so that it means the same on
        KITTI's 0-1 reflectance, 8-bit and 16-bit intensities).
    min_range_m, max_range_m : float
        Returns outside this range are ignored.
    max_gap_deg : float, optional
        Neighbours farther apart in azimuth are not compared (missing returns in between).
        ``None`` (default): :data:`MAX_GAP_STEPS` times the sweep's median azimuth step.
    smooth_ratio : float
        Smooth-surface points kept, as a multiple of the depth edges found (0 keeps none).
    ring_method : {"auto", "scan", "lines", "elevation"}
        Used when ``ring`` is not given.
    along_fraction, cross_fraction : float
        Where an edge point is placed between the near ray and its far neighbour (0 = on the
        near ray, 0.5 = midway), along a ring and across rings (the defaults are those of
        ``FeatureSettings``: midway along a ring, a quarter of the way across rings).
    edge_support : bool
        Keep a depth edge only when its near return continues a surface: the next two returns
        on the other side (along the ring, or on the two rings on the other side across
        rings) lie within ``0.05 r + 0.1`` m of its range. Foliage and other isolated returns
        jump in range at almost every return and make edges that no image edge matches.
    edge_contour : bool
        Keep a depth edge only when its contour continues: a vertical contour (an edge along
        the ring) on the ring above or below, a horizontal one (across rings) on a neighbouring
        return of its ring, both near the same range. Needs ``cross_ring``.
    rng : numpy Generator or seed
        Drives the subsampling of smooth points.
    ring : ndarray, shape (N,), or Rings, optional
        Ring index per point (-1: none), when already known (for example recovered from the
        whole sweep before cropping it); recovered with ``ring_method`` otherwise.
    ring_spacing_deg : float, optional
        The sensor's median elevation gap between neighbouring rings; taken from ``ring`` when
        it is a :class:`~paretocal.lidar.rings.Rings`. Used when ``ring_elevation_deg`` is
        not known.
    ring_elevation_deg : ndarray, shape (R,), optional
        Far-field elevation of each ring id (deg); taken from ``ring`` when it is a
        :class:`~paretocal.lidar.rings.Rings`.
    time : ndarray, shape (N,), optional
        Per-point time (s). Returns recorded more than half a sweep apart are not neighbours
        (:data:`MAX_NEIGHBOUR_DT_SWEEPS`): at the seam where a sweep starts and ends, the two
        sides were scanned a revolution apart, and on a moving vehicle they do not meet.
    sweep_s : float, optional
        The whole sweep's duration (s) when ``points`` are part of it; the span of ``time``
        otherwise.
    sky_edges : bool
        Also mark the top of objects against the sky (the laser just above returned nothing
        at this azimuth): tree lines, poles and signs against the sky, which are strong image
        edges at dusk and night. Needs the rings' elevations.

    Returns
    -------
    LidarFeatures
    """
    rng = np.random.default_rng(rng)
    pts = np.asarray(points, dtype=np.float64)
    xyz_all = pts[:, :3]
    rng_all = np.linalg.norm(xyz_all, axis=1)
    if ring is None:
        ring = recover_rings(pts, ring_method, rng=rng)
    labels: np.ndarray
    if isinstance(ring, Rings):
        if ring_spacing_deg is None and ring.n_rings > 1:
            ring_spacing_deg = float(np.nanmedian(ring.spacing_deg()))
        if ring_elevation_deg is None and ring.n_rings > 1:
            ring_elevation_deg = ring.elevation_deg
        n_rings, labels = ring.n_rings, ring.ring
    else:
        labels = np.asarray(ring)
        n_rings = int(labels.max()) + 1 if len(labels) else 0
    keep = (rng_all > min_range_m) & (rng_all < max_range_m) & (labels >= 0)
    src = np.flatnonzero(keep)
    xyz, refl, r, labels = xyz_all[keep], pts[keep, 3], rng_all[keep], labels[keep]
    psi = azimuth(xyz)
    order = np.lexsort((psi, labels))
    ring = np.asarray(labels[order])                 # from here on: ring labels, sorted
    xyz, refl, r, psi, src = xyz[order], refl[order], r[order], psi[order], src[order]
    t = None
    if time is not None and len(time) == len(pts) and len(src):
        t = np.asarray(time, dtype=np.float64)[src]
        span = sweep_s if sweep_s is not None else float(np.ptp(np.asarray(time, np.float64)))
        max_dt = MAX_NEIGHBOUR_DT_SWEEPS * span
        if not max_dt > 0:
            t = None
    n = len(xyz)
    if n < 3:
        empty = np.zeros((0, 3))
        return LidarFeatures(empty, np.zeros(0, np.int8), np.zeros(0), n_rings,
                             np.zeros(0, np.int64))
    scale = float(np.percentile(pts[:, 3], 99)) if len(pts) else 0.0
    refl = refl / scale if scale > 0 else np.zeros_like(refl)

    nxt, prv, ok_n, ok_p, gap = _ring_neighbours(ring, psi, max_gap_deg,
                                                 None if t is None else (t, max_dt))

    # Along-ring depth edges: the near side of a jump to either neighbour.
    jump_n = np.where(ok_n, r[nxt] - r, 0.0)
    jump_p = np.where(ok_p, r[prv] - r, 0.0)
    jump = np.maximum(jump_n, jump_p)
    is_edge = jump > depth_jump_m
    far = np.where(jump_n >= jump_p, nxt, prv)
    # Two neighbouring returns closer in range than this (m) are taken for one surface (the
    # support of an edge, a contour that continues, an object's top against the sky).
    tol = SAME_SURFACE_REL * r + SAME_SURFACE_M
    if edge_support:
        # The next two returns on the other side along the ring must lie on the near return's
        # own surface (one could be a coincidence in foliage).
        back = jump_n >= jump_p
        o1 = np.where(back, prv, nxt)
        o2 = np.where(back, prv[o1], nxt[o1])
        o1_ok = np.where(back, ok_p, ok_n)
        o2_ok = np.where(back, ok_p[o1], ok_n[o1])
        is_edge &= (o1_ok & o2_ok & (np.abs(r[o1] - r) < tol) & (np.abs(r[o2] - r) < tol))
    edge_pos = np.zeros_like(xyz)
    edge_pos[is_edge] = _between_rays(xyz[is_edge], xyz[far[is_edge]], r[is_edge],
                                       along_fraction)
    strength = np.where(is_edge, jump, 0.0)

    el, cross_jump_rel = _ring_geometry(ring_elevation_deg, n_rings, ring_spacing_deg,
                                        cross_jump_rel)
    if cross_ring:
        on_ground = np.zeros(n, dtype=bool)
        if ground_tol_m is not None:
            near = np.hypot(xyz[:, 0], xyz[:, 1]) < 30.0
            z_ground = np.percentile(xyz[near, 2], 5) if near.any() else xyz[:, 2].min()
            on_ground = xyz[:, 2] < z_ground + ground_tol_m
        # Rings are numbered top first, so "above" and "below" are the neighbouring ids present;
        # points are sorted by (ring, azimuth): each ring is one contiguous, azimuth-sorted
        # segment.
        ids, seg_start = np.unique(ring, return_index=True)
        seg_end = np.r_[seg_start[1:], n]
        by_el = np.arange(len(ids))                    # segment indices, top ring first
        pos_of = np.empty(len(ids), dtype=np.int64)
        pos_of[by_el] = np.arange(len(ids))
        seg_of = np.repeat(np.arange(len(ids)), seg_end - seg_start)
        key = seg_of * 8.0 + psi                       # ascending (psi < 2 pi < 8)
        best_jump = np.zeros(n)
        best_far = np.full(n, -1)
        def across(step, with_dpsi=False):
            """Azimuth-nearest return on the ring ``step`` places above (-1) or below (+1)."""
            tgt_pos = pos_of[seg_of] + step
            ok = (tgt_pos >= 0) & (tgt_pos < len(ids))
            tgt = by_el[np.clip(tgt_pos, 0, len(ids) - 1)]
            cand, dpsi = _nearest_in_segment(key, psi, tgt, seg_start[tgt], seg_end[tgt])
            ok &= dpsi < gap
            if t is not None:
                ok &= np.abs(t[cand] - t) < max_dt
            return (cand, ok, np.where(tgt_pos >= 0, dpsi, np.inf)) if with_dpsi else (cand, ok)

        nb = {step: across(step) for step in ((-2, -1, 1, 2) if edge_support else (-1, 1))}
        for step in (-1, 1):                           # the ring above, then the ring below
            cand, ok = nb[step]
            if el is not None and cross_jump_rel is None:
                # The elevation gap of this pair of lasers (see GRAZING_MIN_DEG).
                gap_pair = np.radians(np.abs(el[ring[cand]] - el[ring]))
                rel = gap_pair / np.tan(np.radians(GRAZING_MIN_DEG))
            else:
                rel = cross_jump_rel
            thr = np.maximum(cross_jump_m, rel * r)
            cj = r[cand] - r
            hit = (ok & (cj > thr) & ~is_edge & ~(on_ground & on_ground[cand])
                   & (cj > best_jump))
            if edge_support:
                # The two rings on the other side must hit the near return's own surface.
                (c1, ok1), (c2, ok2) = nb[-step], nb[-2 * step]
                hit &= ok1 & ok2 & (np.abs(r[c1] - r) < tol) & (np.abs(r[c2] - r) < tol)
            best_jump[hit] = cj[hit]
            best_far[hit] = cand[hit]
        idx = np.flatnonzero(best_far >= 0)
        edge_pos[idx] = _between_rays(xyz[idx], xyz[best_far[idx]], r[idx], cross_fraction)
        strength[idx] = best_jump[idx]
        if edge_contour:
            # An occluding contour continues: a vertical one (an along-ring edge) on the ring
            # above or below, a horizontal one (a cross-ring edge) on the neighbouring return
            # of the ring, at about the same range. Foliage jumps in range at random and its
            # edges rarely continue; a pole one return wide does.
            cross = best_far >= 0
            (up, ok_u), (dn, ok_d) = nb[-1], nb[1]
            keep_a = ((ok_u & is_edge[up] & (np.abs(r[up] - r) < tol))
                      | (ok_d & is_edge[dn] & (np.abs(r[dn] - r) < tol)))
            keep_c = ((ok_n & cross[nxt] & (np.abs(r[nxt] - r) < tol))
                      | (ok_p & cross[prv] & (np.abs(r[prv] - r) < tol)))
            is_edge &= keep_a
            cross &= keep_c
            idx = np.flatnonzero(cross)
        is_edge[idx] = True
        if sky_edges and el is not None:
            # The top of an object against the sky: the laser just above returned nothing
            # near this azimuth (its nearest return, if any, is beyond the azimuth gap), while
            # the laser below hits the same surface. Placed towards the missing ray like a
            # cross-ring edge.
            cand_a, _, dpsi_a = across(-1, with_dpsi=True)
            adjacent = ring[cand_a] == ring - 1
            missing = (ring > 0) & ((dpsi_a >= gap) | ~adjacent)
            below, ok_b = nb[1]
            sky = missing & ok_b & (np.abs(r[below] - r) < tol) & ~is_edge
            if edge_support:
                below2, ok_b2 = nb[2]
                sky &= ok_b2 & (np.abs(r[below2] - r) < tol)
            k = np.flatnonzero(sky)
            if len(k):
                el_here = np.arctan2(xyz[k, 2], np.hypot(xyz[k, 0], xyz[k, 1]))
                el_to = el_here + cross_fraction * np.radians(el[ring[k] - 1] - el[ring[k]])
                edge_pos[k] = np.column_stack([np.cos(el_to) * np.cos(psi[k]),
                                               np.cos(el_to) * np.sin(psi[k]),
                                               np.sin(el_to)]) * r[k, None]
                strength[k] = 0.0
                is_edge[k] = True

    # Reflectance edges on one surface (no depth jump): each neighbour pair once.
    same_surface = ok_n & (np.abs(r[nxt] - r) < np.maximum(0.2, 0.03 * r))
    dref = np.abs(refl[nxt] - refl)
    is_int = same_surface & (dref > intensity_jump) & ~is_edge & ~is_edge[nxt]
    int_pos = 0.5 * (xyz[is_int] + xyz[nxt[is_int]])

    # Smooth points: both neighbours on the same surface, far from any edge.
    smooth_ok = (ok_n & ok_p & (np.abs(jump_n) < 0.05 * r + 0.05)
                 & (np.abs(jump_p) < 0.05 * r + 0.05) & ~is_edge & ~is_int)
    sm_idx = np.flatnonzero(smooth_ok)
    n_smooth = min(len(sm_idx), int(round(smooth_ratio * is_edge.sum())))
    sm_idx = np.sort(rng.choice(sm_idx, size=n_smooth, replace=False)) if n_smooth else sm_idx[:0]

    out_xyz = np.vstack([edge_pos[is_edge], int_pos, xyz[sm_idx]])
    group = np.concatenate([np.full(is_edge.sum(), DEPTH_EDGE, np.int8),
                            np.full(len(int_pos), INTENSITY_EDGE, np.int8),
                            np.full(len(sm_idx), SMOOTH, np.int8)])
    strength = np.concatenate([strength[is_edge], dref[is_int], np.zeros(len(sm_idx))])
    source = np.concatenate([src[is_edge], src[is_int], src[sm_idx]]).astype(np.int64)
    return LidarFeatures(out_xyz, group, strength, n_rings, source)


def _nearest_in_segment(key: np.ndarray, psi: np.ndarray, tgt: np.ndarray, start: np.ndarray,
                        end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point, the index of the azimuth-nearest point of segment ``tgt`` (circular).

    ``key = segment * 8 + psi`` is ascending over all points; ``start``/``end`` bound each
    point's target segment. Returns the indices and the angular distances (radians).
    """
    pos = np.searchsorted(key, tgt * 8.0 + psi)
    hi = np.where(pos < end, pos, start)               # wrap past the ring's last return
    lo = np.where(pos - 1 >= start, pos - 1, end - 1)  # wrap before its first
    hi = np.clip(hi, 0, len(psi) - 1)
    lo = np.clip(lo, 0, len(psi) - 1)
    d_hi = np.abs(np.mod(psi[hi] - psi + np.pi, 2 * np.pi) - np.pi)
    d_lo = np.abs(np.mod(psi[lo] - psi + np.pi, 2 * np.pi) - np.pi)
    take_lo = d_lo < d_hi
    return np.where(take_lo, lo, hi), np.where(take_lo, d_lo, d_hi)
