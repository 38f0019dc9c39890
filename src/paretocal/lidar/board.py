"""The checkerboard in the LiDAR's sweeps, without an extrinsic: what moved between frames, a
planar patch of the board's size, its plane and where the scan lines enter and leave it.

The rig stands still while a person moves the board between frames, so the board is where a
sweep returns nearer than the same direction returns in the other sweeps of the recording
(*background subtraction*). Directions are cells of one laser ring and one azimuth bin (two of
the sensor's own azimuth steps, measured from the sweep); a cell's background is the median,
over the other sweeps of the same static scene, of its nearest return. Sweeps of one static
scene are those whose cells mostly agree: a rig moved between two capture days makes two
scenes, each with its own background. The range noise ``sigma`` is measured from the cells
(1.4826 times the median absolute deviation from the background, over every cell of the
recording); a return is in front of the background when nearer by more than
:data:`FOREGROUND_SIGMAS` of it.

What moved (the board, its stand, the person, other passers-by) is cut into connected clusters:
two returns are neighbours within 1.5 ring gaps at their range (the gap between neighbouring
lasers, measured from the rings' elevations). Each cluster's dominant plane is found by RANSAC
(inliers within :data:`PLANE_SIGMAS` sigma), and the board is the rectangle of the board's size
(grown by the sensor's footprint at that range) placed in that plane to hold the most inliers:
the stand below it and an arm beside it stay outside. A cluster is a candidate when the board's
rectangle holds returns of at least :data:`MIN_RINGS_ON` scan lines over at least half the
board's shorter side. Which candidate is the board is for the caller to decide (the image's
board gives its range and the angle it is seen at).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..io.board import Board

#: A return this many range-noise sigmas nearer than its direction's background is in front
#: of it (one in 3.5 million by noise alone, for Gaussian noise).
FOREGROUND_SIGMAS = 5.0
#: A return within this many sigmas of a plane is on it (RANSAC's inlier band).
PLANE_SIGMAS = 4.0
#: Two sweeps show one static scene when more than half their common cells agree within
#: FOREGROUND_SIGMAS (the rest being what moved, and noise).
SAME_SCENE_SHARE = 0.5
#: Returns are neighbours within this many ring gaps at their range.
LINK_GAPS = 1.5
#: A board candidate spans at least this many scan lines (three lines fix a plane's tilt
#: across them; the issue's recordings have 3-4 on boards seen far away).
MIN_RINGS_ON = 3
#: Clusters with fewer returns are not planes worth fitting.
MIN_CLUSTER_POINTS = 20
#: RANSAC trials per cluster: a board holding a third of its cluster's returns is missed by
#: 200 trials with probability (1 - 1/27)^200 = 0.05 %.
RANSAC_TRIALS = 200
#: Orientations of the board's rectangle tried in its plane (deg steps over half a turn).
RECT_STEP_DEG = 3.0


@dataclass(frozen=True, eq=False)
class CloudBoard:
    """A planar patch of a sweep that may be the board.

    Attributes
    ----------
    index : ndarray, shape (M,), int64
        The patch's returns (indices into the sweep's points).
    centroid : ndarray, shape (3,)
        Their mean, in the cloud's frame (m).
    normal : ndarray, shape (3,)
        The plane's unit normal, towards the sensor.
    rms_m : float
        RMS distance of the returns from the plane (m).
    extent_m : tuple of float
        The patch's smaller and larger extent in its plane (m, the smallest rectangle holding it).
    rings : int
        Scan lines on it.
    """

    index: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    rms_m: float
    extent_m: tuple[float, float]
    rings: int

    @property
    def distance_m(self) -> float:
        """The sensor's distance from the plane (m): ``normal . x + distance_m = 0`` on it."""
        return float(-self.normal @ self.centroid)

    def to_dict(self) -> dict:
        """For result.json: returns, scan lines, centroid, normal, fit, extent."""
        return {"points": int(len(self.index)), "rings": int(self.rings),
                "centroid_m": [round(float(v), 4) for v in self.centroid],
                "normal": [round(float(v), 5) for v in self.normal],
                "rms_cm": round(100 * self.rms_m, 2),
                "extent_m": [round(float(v), 3) for v in self.extent_m]}


@dataclass(frozen=True)
class SweepGeometry:
    """What the board search measures of the sensor from the sweeps.

    Attributes
    ----------
    azimuth_step_deg : float
        The median azimuth step between neighbouring returns of a ring (deg).
    ring_gap_deg : float
        The median elevation gap between neighbouring rings (deg).
    sigma_m : float
        The range noise (m): 1.4826 times the median absolute deviation of the cells' nearest
        returns from their background.
    scenes : tuple of int
        Each sweep's static scene (sweeps of one scene share a background).
    """

    azimuth_step_deg: float
    ring_gap_deg: float
    sigma_m: float
    scenes: tuple[int, ...]

    def to_dict(self) -> dict:
        return {"azimuth_step_deg": round(self.azimuth_step_deg, 4),
                "ring_gap_deg": round(self.ring_gap_deg, 3),
                "range_noise_cm": round(100 * self.sigma_m, 2),
                "scenes": list(self.scenes)}


def sensor_coords(points: np.ndarray, sensor_pose: np.ndarray | None = None):
    """Range (m), azimuth (rad) and elevation (rad) of points about the sensor, each (N,)."""
    p = np.asarray(points, dtype=np.float64)[:, :3]
    if sensor_pose is not None:
        p = (p - sensor_pose[:3, 3]) @ sensor_pose[:3, :3]
    d = np.hypot(p[:, 0], p[:, 1])
    return np.linalg.norm(p, axis=1), np.arctan2(p[:, 1], p[:, 0]), np.arctan2(p[:, 2], d)


def azimuth_step(azimuth: np.ndarray, ring: np.ndarray) -> float:
    """The sensor's azimuth step (rad): the median gap between consecutive returns of a ring."""
    gaps = []
    for r in np.unique(ring[ring >= 0]):
        a = np.sort(azimuth[ring == r])
        if len(a) > 10:
            g = np.diff(a)
            gaps.append(g[g > 0])
    got = np.concatenate(gaps) if gaps else np.zeros(0)
    return float(np.median(got)) if len(got) else float(np.radians(0.2))


def ring_gap(elevation: np.ndarray, ring: np.ndarray) -> float:
    """The median elevation gap between neighbouring rings (rad)."""
    el = np.array([np.median(elevation[ring == r]) for r in np.unique(ring[ring >= 0])])
    if len(el) < 2:
        return float(np.radians(2.0))
    return float(np.median(np.diff(np.sort(el))))


def _nanmedian(a: np.ndarray, axis: int) -> np.ndarray:
    """``np.nanmedian`` without its warning for a slice with no number (a cell no sweep has
    a return in is simply NaN)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(a, axis=axis)


def _cells(az: np.ndarray, ring: np.ndarray, n_bins: int) -> np.ndarray:
    """Each return's cell (ring * n_bins + azimuth bin); -1 without a ring."""
    b = np.floor((az + np.pi) / (2 * np.pi) * n_bins).astype(np.int64) % n_bins
    return np.where(ring >= 0, ring.astype(np.int64) * n_bins + b, -1)


def _nearest_per_cell(cell: np.ndarray, rng: np.ndarray, n_cells: int) -> np.ndarray:
    """The nearest return's range in each cell, (n_cells,), NaN where there is none."""
    out = np.full(n_cells, np.inf)
    ok = cell >= 0
    np.minimum.at(out, cell[ok], rng[ok])
    out[~np.isfinite(out)] = np.nan
    return out


def sweep_geometry(coords: list, rings: list) -> tuple[SweepGeometry, np.ndarray]:
    """The sensor's steps, its range noise and the sweeps' static scenes, with the matrix of
    each sweep's nearest return per cell (F, cells) (m, NaN: none).

    Parameters
    ----------
    coords : list of (range, azimuth, elevation)
        :func:`sensor_coords` of each sweep.
    rings : list of ndarray, shape (N,)
        Each sweep's ring per return (-1: none).
    """
    step = float(np.median([azimuth_step(c[1], r) for c, r in zip(coords, rings)]))
    gap = float(np.median([ring_gap(c[2], r) for c, r in zip(coords, rings)]))
    n_bins = max(1, int(round(2 * np.pi / (2 * step))))
    n_rings = int(max(int(r.max()) for r in rings)) + 1
    M = np.stack([_nearest_per_cell(_cells(c[1], r, n_bins), c[0], n_rings * n_bins)
                  for c, r in zip(coords, rings)])
    F = len(M)
    # The noise from the best-agreeing pair of sweeps (one static scene, whatever moved).
    spread = np.full((F, F), np.inf)
    for i in range(F):
        spread[i] = _nanmedian(np.abs(M - M[i]), axis=1)
        spread[i, i] = np.inf
    best = float(np.nanmin(spread)) if F > 1 and np.isfinite(spread).any() else np.nan
    sigma = 1.4826 * best / np.sqrt(2) if np.isfinite(best) else np.nan
    scenes = np.arange(F)
    if np.isfinite(sigma):
        agree = np.zeros((F, F), bool)
        for i in range(F):
            d = np.abs(M - M[i])
            both = np.isfinite(d)
            share = np.sum(both & (d < FOREGROUND_SIGMAS * sigma), axis=1) / \
                np.maximum(both.sum(axis=1), 1)
            agree[i] = share > SAME_SCENE_SHARE
        scenes = connected_components(agree, directed=False)[1]
        # The noise again, now from every cell of every sweep against its scene's background.
        dev = []
        for k in range(F):
            others = (scenes == scenes[k]) & (np.arange(F) != k)
            if others.any():
                dev.append(np.abs(M[k] - _nanmedian(M[others], axis=0)))
        if dev:
            sigma = 1.4826 * float(_nanmedian(np.concatenate(dev), axis=0))
    geo = SweepGeometry(azimuth_step_deg=float(np.degrees(step)),
                        ring_gap_deg=float(np.degrees(gap)), sigma_m=float(sigma),
                        scenes=tuple(int(s) for s in scenes))
    return geo, M


def foreground(k: int, coords: list, rings: list, geo: SweepGeometry,
               M: np.ndarray) -> np.ndarray:
    """Indices of sweep ``k``'s returns nearer than their direction's background (the median
    over the other sweeps of its static scene) by more than :data:`FOREGROUND_SIGMAS` sigma;
    empty when its scene has no other sweep."""
    others = (np.array(geo.scenes) == geo.scenes[k]) & (np.arange(len(M)) != k)
    if not others.any():
        return np.zeros(0, np.int64)
    bg = _nanmedian(M[others], axis=0)
    rng, az = coords[k][0], coords[k][1]
    n_bins = M.shape[1] // (int(max(int(r.max()) for r in rings)) + 1)
    cell = _cells(az, rings[k], n_bins)
    b = np.where(cell >= 0, bg[np.maximum(cell, 0)], np.nan)
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(rng < b - FOREGROUND_SIGMAS * geo.sigma_m)


def clusters(xyz: np.ndarray, rng: np.ndarray, gap_rad: float) -> list[np.ndarray]:
    """Connected clusters of points (indices into ``xyz``): neighbours within
    :data:`LINK_GAPS` ring gaps at the nearer one's range."""
    if len(xyz) < 2:
        return []
    link = LINK_GAPS * rng * np.tan(gap_rad)
    pairs = cKDTree(xyz).query_pairs(float(link.max()), output_type="ndarray")
    if len(pairs):
        d = np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1)
        pairs = pairs[d < np.minimum(link[pairs[:, 0]], link[pairs[:, 1]])]
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xyz),) * 2)
    _, lab = connected_components(g, directed=False)
    return [np.flatnonzero(lab == c) for c in np.unique(lab)]


def ransac_plane(xyz: np.ndarray, tol: float, rng: np.random.Generator,
                 trials: int = RANSAC_TRIALS) -> np.ndarray:
    """The inliers (bool, (N,)) of the plane through three of the points that holds most
    points within ``tol`` (m); the trials' planes are scored at once."""
    idx = rng.choice(len(xyz), size=(trials, 3))
    a, b, c = xyz[idx[:, 0]], xyz[idx[:, 1]], xyz[idx[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-9
    if not ok.any():
        return np.zeros(len(xyz), bool)
    n, a = n[ok] / norm[ok, None], a[ok]
    counts = np.zeros(len(n), np.int64)
    for start in range(0, len(n), 50):                  # bounded memory: 50 planes at a time
        d = np.abs(xyz @ n[start:start + 50].T - np.sum(a[start:start + 50] * n[start:start + 50],
                                                         axis=1))
        counts[start:start + 50] = np.sum(d < tol, axis=0)
    k = int(np.argmax(counts))
    return np.abs((xyz - a[k]) @ n[k]) < tol


def fit_plane(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The least-squares plane of points: centroid (3,), unit normal towards the origin (3,)
    and RMS distance (m)."""
    c = xyz.mean(axis=0)
    _, s, vt = np.linalg.svd(xyz - c, full_matrices=False)
    n = vt[2]
    if n @ c > 0:
        n = -n
    return c, n, float(s[2] / np.sqrt(len(xyz)))


def plane_basis(normal: np.ndarray) -> np.ndarray:
    """Two unit vectors spanning the plane of ``normal``, shape (2, 3)."""
    a = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, a)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(normal, u)])


def best_rectangle(uv: np.ndarray, size: tuple[float, float], cell: float) -> np.ndarray:
    """The points (bool, (N,)) inside the rectangle of ``size`` (m), placed and turned in the
    plane to hold the most of ``uv`` (N, 2) (m); positions on a grid of ``cell`` (m)."""
    best, inside = -1, np.zeros(len(uv), bool)
    w, h = size
    for deg in np.arange(0.0, 180.0, RECT_STEP_DEG):
        t = np.radians(deg)
        R = np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])
        q = uv @ R.T
        lo = q.min(axis=0)
        ij = np.floor((q - lo) / cell).astype(np.int64)
        shape = ij.max(axis=0) + 1
        grid = np.zeros(shape + 1)
        np.add.at(grid, (ij[:, 0] + 1, ij[:, 1] + 1), 1.0)
        S = grid.cumsum(0).cumsum(1)
        kw, kh = max(1, int(w / cell)), max(1, int(h / cell))
        a0 = np.arange(max(1, shape[0] - kw + 1))
        b0 = np.arange(max(1, shape[1] - kh + 1))
        a1, b1 = np.minimum(a0 + kw, shape[0]), np.minimum(b0 + kh, shape[1])
        counts = (S[a1][:, b1] - S[a0][:, b1] - S[a1][:, b0] + S[a0][:, b0])
        i, j = np.unravel_index(int(np.argmax(counts)), counts.shape)
        if counts[i, j] > best:
            best = counts[i, j]
            inside = ((ij[:, 0] >= a0[i]) & (ij[:, 0] < a1[i]) &
                      (ij[:, 1] >= b0[j]) & (ij[:, 1] < b1[j]))
    return inside


def min_extent(uv: np.ndarray) -> tuple[float, float]:
    """The smaller and larger side of the smallest rectangle holding ``uv`` (N, 2) (m)."""
    import cv2

    (_, _), (a, b), _ = cv2.minAreaRect(uv.astype(np.float32))
    return float(min(a, b)), float(max(a, b))


def board_candidates(k: int, coords: list, rings: list, points: np.ndarray, board: Board,
                     geo: SweepGeometry, M: np.ndarray, seed: int = 0) -> list[CloudBoard]:
    """The planar patches of sweep ``k``'s foreground that may be the board, largest first.

    Parameters
    ----------
    k : int
        The sweep.
    coords, rings : list
        :func:`sensor_coords` and the ring per return of every sweep.
    points : ndarray, shape (N, 3+)
        Sweep ``k``'s points (m).
    board : Board
    geo, M : SweepGeometry, ndarray
        From :func:`sweep_geometry`.
    seed : int
        Seeds RANSAC.
    """
    fg = foreground(k, coords, rings, geo, M)
    if len(fg) < MIN_CLUSTER_POINTS or not np.isfinite(geo.sigma_m):
        return []
    xyz = np.asarray(points, dtype=np.float64)[fg, :3]
    rng = coords[k][0][fg]
    gap = np.radians(geo.ring_gap_deg)
    step = np.radians(geo.azimuth_step_deg)
    gen = np.random.default_rng([seed, k])
    out = []
    for c in clusters(xyz, rng, gap):
        if len(c) < MIN_CLUSTER_POINTS:
            continue
        inl = c[ransac_plane(xyz[c], PLANE_SIGMAS * geo.sigma_m, gen)]
        if len(inl) < MIN_CLUSTER_POINTS:
            continue
        centre, normal, _ = fit_plane(xyz[inl])
        uv = (xyz[inl] - centre) @ plane_basis(normal).T
        # The board's size grown by the footprint of a return and a noise band at its range:
        # an edge return lies up to an azimuth step beyond the edge.
        r = float(np.median(rng[inl]))
        grow = 2.0 * (r * step + PLANE_SIGMAS * geo.sigma_m)
        size = (board.size_m[0] + grow, board.size_m[1] + grow)
        on = inl[best_rectangle(uv, size, max(r * step, geo.sigma_m))]
        n_rings = len(np.unique(rings[k][fg[on]]))
        if n_rings < MIN_RINGS_ON or len(on) < MIN_CLUSTER_POINTS:
            continue
        centre, normal, rms = fit_plane(xyz[on])
        ext = min_extent((xyz[on] - centre) @ plane_basis(normal).T)
        if ext[1] < 0.5 * min(board.size_m):
            continue
        out.append(CloudBoard(index=fg[on], centroid=centre, normal=normal, rms_m=rms,
                              extent_m=ext, rings=n_rings))
    return sorted(out, key=lambda b: -len(b.index))


def points_on_board(points: np.ndarray, normal: np.ndarray, centre: np.ndarray,
                    axes: np.ndarray, half_size: np.ndarray, tol_plane: float,
                    grow: float) -> np.ndarray:
    """Indices of the returns on a board placed in the cloud's frame: within ``tol_plane`` (m)
    of its plane and inside its outline grown by ``grow`` (m).

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
    normal, centre : ndarray, shape (3,)
        The board's plane (unit normal) and centre in the cloud's frame.
    axes : ndarray, shape (2, 3)
        Its width and height directions in the cloud's frame.
    half_size : ndarray, shape (2,)
        Half its width and height (m).
    """
    d = np.asarray(points, dtype=np.float64)[:, :3] - centre
    on = np.abs(d @ normal) < tol_plane
    local = d @ axes.T
    on &= np.all(np.abs(local) <= half_size + grow, axis=1)
    return np.flatnonzero(on)


def scan_line_ends(index: np.ndarray, coords: tuple, ring: np.ndarray, step_rad: float,
                   sigma_m: float) -> np.ndarray:
    """Where each scan line enters and leaves the board: the first and last of ``index``'s
    returns of each ring in azimuth, kept only when the return beyond it on the ring (within
    two azimuth steps) is farther, or missing: a nearer one is an occluder (a hand), not the
    board's edge. Returns indices into the sweep, shape (E,)."""
    rng, az = coords[0], coords[1]
    out = []
    for r in np.unique(ring[index]):
        if r < 0:
            continue
        mine = index[ring[index] == r]
        if len(mine) < 2:
            continue
        a = az[mine]
        # Unwrap about the patch's own mean direction (a board across azimuth +-pi).
        ref = np.angle(np.mean(np.exp(1j * a)))
        rel = np.angle(np.exp(1j * (a - ref)))
        same = np.flatnonzero(ring == r)
        rel_all = np.angle(np.exp(1j * (az[same] - ref)))
        for end, sign in ((mine[np.argmin(rel)], -1.0), (mine[np.argmax(rel)], 1.0)):
            e = float(np.angle(np.exp(1j * (az[end] - ref))))
            beyond = same[(sign * (rel_all - e) > 0) & (sign * (rel_all - e) <= 2 * step_rad)]
            if len(beyond) and np.min(rng[beyond]) < rng[end] - FOREGROUND_SIGMAS * sigma_m:
                continue
            out.append(end)
    return np.array(out, dtype=np.int64)
