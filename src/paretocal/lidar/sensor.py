"""Where the LiDAR is: its pose in the cloud's frame, estimated from one sweep.

Clouds are often stored in a vehicle frame, the sensor 1-2 m from the origin and slightly
tilted, and the file does not say where the sensor is. Ring recovery needs the sensor's own
frame (every laser sweeps a cone about the spinning axis, see :mod:`.rings`), so the pose is
estimated from the sweep's own structure, coarse to fine:

1. **Ground**: the dominant roughly horizontal plane near the origin (RANSAC on a seeded
   subsample, with as many planes as it takes to find a ground holding a small share of the
   returns, see :data:`GROUND_MIN_SHARE`). Its normal is the first guess of the spinning axis.
2. **Axis position, rough**: the downward lasers draw concentric circles on the ground about
   the foot of the axis; the centre that makes the histogram of ground distances sharpest is
   within a few decimetres of the axis (a ground sloped against the axis shifts each circle by
   ``d**2 / H`` times the slope, so this is only a start).
3. **Tilt**: seen from the right axis every laser keeps one elevation at every azimuth. Within a
   narrow band of horizontal distance (where a laser's height offset and the unknown sensor
   height shift every return of the band alike) the histogram of ``z / d`` of the off-ground
   returns is then a comb of sharp peaks, one per laser; a tilted axis smears each peak over
   the azimuths. Every tilt within :data:`MAX_TILT_DEG` is tried on a fine grid, the sharpest few
   refined on finer grids, the bins shrinking with the step.
4. **Height**: the far returns' ``z / d``, every band pooled, is sharpest at the height of the
   lasers' common origin.
5. **Line-model fit**: every laser's returns lie on a line ``z / d = a_k + h_k / d`` about the
   true axis (:mod:`.rings`). About an axis displaced by ``D`` (m) a laser's returns move off
   their line by ``a_k (D . u) / d`` (``u`` the azimuth's unit vector): far, near-horizontal
   returns hardly move. The fit starts with the returns beyond 40 m, finds their lines, labels
   every return with its nearest line and solves for the axis position and tilt by
   Gauss-Newton with each line's ``(a_k, h_k)`` eliminated in closed form (variable
   projection); then it takes in nearer returns stage by stage (their smear shrinks with the
   axis error) and finds the lines of the lasers that only hit near things, relabelling at
   every step. With the labels right the fit is exact to below a millimetre.
6. **Height convention**: the height along the axis only shifts every ``h_k`` alike, so the
   origin is put where the median ``h_k`` is zero (exact for sensors that compute every point
   from one origin; an HDL-64E's lasers sit at two heights 0.08 m apart, and its origin is
   where its maker puts it, 0.12-0.21 m below its lasers).

The yaw about the axis is left as in the cloud's frame (rings do not depend on it). The result
is judged by what it is for: the share of the returns that lie on the fitted lines
(:attr:`SensorPoseEstimate.explained`), and the rings recovered in the estimated frame
(:func:`.rings.recover_rings`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.ndimage import maximum_filter

from .rings import MIN_RING_POINTS, MIN_RINGS, extract_lines, nearest_line

#: The axis is searched within this distance (m) of the cloud's origin: vehicle frames put the
#: sensor on the roof or a bumper, within 3 m of the reference point of cars and trucks.
MAX_OFFSET_M = 4.0
#: ... and tilted at most this much (deg) from the ground's normal (mounts are level to a few
#: degrees; a vehicle pitches and rolls on the road by less than a degree).
MAX_TILT_DEG = 6.0
#: Tilt grid (deg): steps of 0.1 deg (below the closest ring spacing of real sensors, so that
#: one grid point lies within the comb's sharp peak), in tiles of +- TILT_SPAN_DEG that cover
#: every tilt within MAX_TILT_DEG.
TILT_STEP_DEG = 0.1
TILT_SPAN_DEG = 1.5
#: Local maxima of the first tilt grids refined further (the true tilt was among the first 4
#: on every sweep measured, and first on most).
TILT_CANDIDATES = 4
#: Ground plane: returns within this distance (m) of the plane are ground; the plane's normal
#: is within 30 deg of the cloud's z axis (the cloud's z points up, as in every vehicle and
#: sensor frame); the plane is searched among returns within 40 m (the road near the vehicle).
GROUND_TOL_M = 0.1
GROUND_MAX_SLOPE_DEG = 30.0
GROUND_NEAR_M = 40.0
#: RANSAC misses a ground holding GROUND_MIN_SHARE of the returns within GROUND_NEAR_M with
#: probability GROUND_MISS at most: the planes drawn (each through three random returns) are
#: as many as that takes, 13,490. Not a figure of one dataset: the road held 13-15 % of those
#: returns on PandaSet's street (hemmed in by queueing cars and facades), 21-26 % on aiMotive's
#: motorway and 27-34 % on the KITTI drive (frames 0, 5, 13 and 19 of each), and 8 % leaves a
#: margin below all of them. With the 300 planes drawn before, a road holding 13 % was missed
#: about half the time ((1 - 0.13**3)**300 = 0.52) and the cars' roofs taken for the ground.
GROUND_MIN_SHARE = 0.08
GROUND_MISS = 1e-3
RANSAC_ITERATIONS = int(np.ceil(np.log(GROUND_MISS) / np.log1p(-GROUND_MIN_SHARE ** 3)))
#: Every plane is counted on this many returns (a share of 8 % is then known to +-1.2 %, two
#: standard errors), the GROUND_FINALISTS best again on all of them; planes are counted
#: GROUND_BLOCK at a time (memory: 16 MB).
GROUND_SCORE_SAMPLE = 2000
GROUND_FINALISTS = 16
GROUND_BLOCK = 1024
#: Returns farther than this from the ground plane (m) are used for the elevation comb.
OFF_GROUND_M = 0.3
#: Fewer returns than this are no sweep of a multi-beam sensor (a 16-beam sensor returns about
#: 30000 per revolution); nothing is estimated from them.
MIN_SWEEP_POINTS = 2000
#: Subsample sizes (seeded): enough for every laser of a 128-beam sensor to hold hundreds of
#: returns in the line fit, small enough to keep the whole estimate within a few seconds.
SAMPLE = 60000
FIT_SAMPLE = 30000
COMB_SAMPLE = 16000
CIRCLE_SAMPLE = 10000
#: Horizontal distances (m) used by the tilt comb: beyond the vehicle, within the range where
#: returns are dense.
COMB_MIN_M = 6.0
COMB_MAX_M = 80.0
#: Band width in 1/d (1/m): a height error of 2 m shifts returns across a band by 0.001 in
#: z / d, one finest bin.
BAND_INV = 0.0005
#: Finest bin of z / d (0.06 deg), below the closest ring spacing of real sensors (~0.1 deg).
FINEST_BIN = 0.001
#: Ground-circle histogram bin (m): downward rings lie 0.15-1 m apart on the ground near a car;
#: ground returns within this distance (m) of the centre are used (the circles farther out
#: move most with a ground slope).
CIRCLE_BIN_M = 0.05
CIRCLE_MAX_M = 25.0
#: Returns used for the height comb: beyond this horizontal distance (m), where a laser's
#: height offset (< 0.4 m) moves z / d by less than the tilt comb's finest bin... times 20.
HEIGHT_MIN_M = 15.0
#: Stages of the line-model fit: returns beyond these horizontal distances (m). The first
#: stage's returns move off their lines by ``a D / d``: for the near-horizontal lasers
#: (|a| < 0.05) and an axis error D < 0.5 m that is < 0.0006 at 40 m, a fifth of the closest
#: ring spacing of real sensors (0.17 deg = 0.003); each stage halves the distance as the axis
#: error shrinks.
STAGE_MIN_M = (40.0, 20.0, 10.0, 5.0, 2.5, 1.0)
#: A return belongs to its nearest line when closer than this share of the gap between that
#: line and its neighbours (half the gap would be the border between them).
LABEL_GAP_SHARE = 0.3
#: Gauss-Newton steps per stage, and the step below which a stage has converged (m, rad).
FIT_ITERATIONS = 8
CONVERGED_M = 1e-4
CONVERGED_RAD = 1e-6
#: Largest step taken at once (m, rad): a step beyond it is scaled down (the labels of a
#: stage are only valid near its start).
MAX_STEP_M = 0.5
MAX_STEP_RAD = np.radians(1.0)
#: Candidates for new lines per stage (the Hough transform's memory grows with them).
NEW_LINE_SAMPLE = 15000
#: The estimate is trusted when at least this share of the returns lie on its lines (0.93 to
#: 0.99 on real sweeps in the right frame; below 0.3 about a wrong axis).
MIN_EXPLAINED = 0.8
#: Estimates from fresh subsamples before giving up (a failed one costs about a second).
ATTEMPTS = 3


@dataclass
class SensorPoseEstimate:
    """The estimated pose of the LiDAR in the cloud's frame.

    Attributes
    ----------
    pose : ndarray, shape (4, 4)
        cloud <- sensor: the axis position and height in the cloud's frame and the axis
        direction; yaw about the axis as in the cloud's frame.
    ground_normal : ndarray, shape (3,)
        Unit normal of the ground plane in the cloud's frame (pointing up).
    ground_height_m : float
        The sensor origin's height above the ground plane (m).
    tilt_deg : float
        Angle between the spinning axis and the ground's normal (deg).
    explained : float
        Share of the returns beyond 1 m of the axis that lie on the fitted lines (within
        :data:`LABEL_GAP_SHARE` of the gap to the neighbouring line).
    n_lines : int
        Lines of the fitted model (about one per laser; a laser's returns may be split
        between two lines).
    tan_elevation : ndarray, shape (n_lines,)
        ``a_k`` of the fitted lines in the estimated frame, top first.
    offset_m : ndarray, shape (n_lines,)
        ``h_k`` of the fitted lines (m).
    ok : bool
        The estimate explains the sweep (:data:`MIN_EXPLAINED`, and at least
        :data:`~paretocal.lidar.rings.MIN_RINGS` lines); when False, ``notes`` says why
        and the pose should not be used.
    notes : list of str
    """

    pose: np.ndarray
    ground_normal: np.ndarray
    ground_height_m: float
    tilt_deg: float
    explained: float
    n_lines: int
    tan_elevation: np.ndarray
    offset_m: np.ndarray
    ok: bool
    notes: list = field(default_factory=list)

    def to_sensor(self, points: np.ndarray) -> np.ndarray:
        """Points (N, 3+) of the cloud's frame in the estimated sensor frame, (N, 3+) float64
        (columns beyond the third kept)."""
        pts = np.array(points, dtype=np.float64)
        pts[:, :3] = (pts[:, :3] - self.pose[:3, 3]) @ self.pose[:3, :3]
        return pts

    def summary(self) -> dict:
        """JSON-ready description."""
        return {"ok": bool(self.ok),
                "position_m": [round(float(v), 4) for v in self.pose[:3, 3]],
                "axis": [round(float(v), 6) for v in self.pose[:3, 2]],
                "tilt_deg": round(float(self.tilt_deg), 3),
                "height_above_ground_m": round(float(self.ground_height_m), 3),
                "explained": round(float(self.explained), 4),
                "n_lines": int(self.n_lines),
                "notes": list(self.notes)}


# --- rough: ground, circle centre, tilt, height ---------------------------------------------------

def ground_plane(points: np.ndarray, rng: np.random.Generator, tol: float = GROUND_TOL_M,
                 iterations: int = RANSAC_ITERATIONS) -> tuple[np.ndarray, float] | None:
    """The dominant roughly horizontal plane (RANSAC): ``(normal, offset)`` with
    ``normal @ p = offset`` on the plane and the normal pointing up (+z), or None.

    All ``iterations`` planes through three random returns are drawn at once and counted on a
    subsample of :data:`GROUND_SCORE_SAMPLE` returns; the :data:`GROUND_FINALISTS` best are
    counted again on every return, and the best of them is refitted to its inliers (least
    squares). The default number of planes finds a ground holding :data:`GROUND_MIN_SHARE` of
    the returns but with probability :data:`GROUND_MISS`.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Metres.
    rng : numpy Generator
    tol : float
        Inlier distance (m).
    iterations : int
    """
    n = len(points)
    if n < 3:
        return None
    cos_max = np.cos(np.radians(GROUND_MAX_SLOPE_DEG))
    picks = rng.integers(0, n, size=(iterations, 3))
    a = points[picks[:, 0]]
    nrm = np.cross(points[picks[:, 1]] - a, points[picks[:, 2]] - a)
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-9
    nrm, a = nrm[ok] / length[ok, None], a[ok]
    nrm[nrm[:, 2] < 0] *= -1.0
    ok = nrm[:, 2] >= cos_max
    nrm, a = nrm[ok], a[ok]
    if len(nrm) == 0:
        return None
    off = np.einsum("ij,ij->i", nrm, a)
    sub = points if n <= GROUND_SCORE_SAMPLE else \
        points[np.sort(rng.choice(n, GROUND_SCORE_SAMPLE, replace=False))]
    count = np.empty(len(nrm))
    for i in range(0, len(nrm), GROUND_BLOCK):
        dist = sub @ nrm[i:i + GROUND_BLOCK].T - off[i:i + GROUND_BLOCK]
        count[i:i + GROUND_BLOCK] = np.count_nonzero(np.abs(dist) < tol, axis=0)
    final = np.argsort(-count, kind="stable")[:GROUND_FINALISTS]
    full = np.count_nonzero(np.abs(points @ nrm[final].T - off[final]) < tol, axis=0)
    if full.max() < 3:
        return None
    best = final[int(np.argmax(full))]
    # Least-squares refit on the inliers.
    nrm, off = nrm[best], off[best]
    inl = points[np.abs(points @ nrm - off) < tol]
    centre = inl.mean(axis=0)
    _, _, vt = np.linalg.svd(inl - centre, full_matrices=False)
    nrm = vt[2] if vt[2, 2] > 0 else -vt[2]
    if nrm[2] < cos_max:
        return None
    return nrm, float(nrm @ centre)


def _plane_basis(normal: np.ndarray) -> np.ndarray:
    """Rows e1, e2, n: an orthonormal basis whose third axis is ``normal``, shape (3, 3)."""
    n = normal / np.linalg.norm(normal)
    e1 = np.cross([0.0, 1.0, 0.0], n)
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(n, e1), n])


def _sharpness(keys: np.ndarray, frac: np.ndarray) -> float:
    """Sum of squared bin counts per point, with each point shared linearly between its bin
    and the next (a continuous function of the positions)."""
    if len(keys) == 0:
        return 0.0
    lo = keys.min()
    w = np.bincount(keys - lo, weights=1.0 - frac, minlength=int(keys.max() - lo) + 2)
    w += np.bincount(keys - lo + 1, weights=frac, minlength=len(w))[:len(w)]
    return float(np.einsum("i,i->", w, w)) / len(keys)


def circle_sharpness(ground_2d: np.ndarray, centre: np.ndarray,
                     bin_m: float = CIRCLE_BIN_M) -> float:
    """Sharpness of the histogram of distances from ``centre`` (2,) of ground returns (G, 2)."""
    d = np.hypot(ground_2d[:, 0] - centre[0], ground_2d[:, 1] - centre[1]) / bin_m
    k = np.floor(d).astype(np.int64)
    return _sharpness(k, d - k)


def ground_circle_centre(ground_2d: np.ndarray) -> np.ndarray:
    """Centre (2,) of the laser circles drawn on the ground by returns ``ground_2d`` (G, 2)
    (plane coordinates, m), searched within :data:`MAX_OFFSET_M` of the origin on grids from
    coarse to fine."""
    c = np.zeros(2)
    for span, step in ((MAX_OFFSET_M, 0.25), (0.375, 0.05), (0.075, 0.01)):
        grid = np.arange(-span, span + 0.5 * step, step)
        scores = np.array([[circle_sharpness(ground_2d, c + [u, v], max(CIRCLE_BIN_M, step / 2))
                            for u in grid] for v in grid])
        iv, iu = np.unravel_index(np.argmax(scores), scores.shape)
        c = c + [grid[iu], grid[iv]]
    return c


def comb_sharpness(points: np.ndarray, origin: np.ndarray, R: np.ndarray,
                   bin_te: float = FINEST_BIN) -> float:
    """Sharpness of the ``z / d`` comb of ``points`` (N, 3) seen from a sensor at ``origin``
    (3,) with axes ``R`` (3, 3, columns = sensor axes in the cloud's frame), band by band of
    1/d (see the module docstring)."""
    q = (points - origin) @ R
    d = np.hypot(q[:, 0], q[:, 1])
    ok = (d > COMB_MIN_M) & (d < COMB_MAX_M)
    if not ok.any():
        return 0.0
    te = q[ok, 2] / d[ok]
    band = np.floor(1.0 / d[ok] / BAND_INV).astype(np.int64)
    x = (te - te.min()) / bin_te
    k = np.floor(x).astype(np.int64)
    n_bins = int(k.max()) + 2
    return _sharpness((band - band.min()) * n_bins + k, x - k)


def _frame_about(z: np.ndarray) -> np.ndarray:
    """Axes (3, 3) with third column the unit vector ``z`` and first as close to the cloud's
    x as possible (the yaw is not observable from rings; it is kept as in the cloud)."""
    z = z / np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@njit(cache=True)
def _comb_scores(x0, cb, sb, first, gx, gy, size):  # pragma: no cover - compiled
    """Sharpness (len(gx), len(gy)) of the banded comb for every turn of the grids: return
    ``p`` lies at ``x0[p] - wx sb[p] + wy cb[p]`` bins from its band's first cell
    ``first[p]``, shared linearly between two cells. The sum of squared cell weights is kept
    as the returns are added (no pass over the cells), and only the cells touched are
    cleared."""
    n = len(x0)
    out = np.empty((len(gx), len(gy)))
    hist = np.zeros(size + 2)
    keys = np.empty(n, np.int64)
    for i in range(len(gx)):
        for j in range(len(gy)):
            ss = 0.0
            for p in range(n):
                x = x0[p] - gx[i] * sb[p] + gy[j] * cb[p]
                k = np.floor(x)
                w1 = x - k
                w0 = 1.0 - w1
                key = first[p] + np.int64(k)
                keys[p] = key
                v = hist[key]
                ss += w0 * (2.0 * v + w0)
                hist[key] = v + w0
                v = hist[key + 1]
                ss += w1 * (2.0 * v + w1)
                hist[key + 1] = v + w1
            for p in range(n):
                hist[keys[p]] = 0.0
                hist[keys[p] + 1] = 0.0
            out[i, j] = ss / max(n, 1)
    return out


def _comb_grid(te: np.ndarray, c: np.ndarray, s: np.ndarray, band: np.ndarray,
               grid: np.ndarray, bin_te: float) -> np.ndarray:
    """Sharpness (G, G) of the banded comb for every small turn ``(wx, wy)`` of ``grid`` (G,)
    (rad), with ``z / d`` changed by ``- wx sin(phi) + wy cos(phi)``.

    ``te, c, s, band``: ``z / d``, ``cos(phi)``, ``sin(phi)`` and band index (>= 0) per return,
    shapes (N,). The histogram cells of each band only span that band's values (plus the
    largest shift), which keeps the accumulator small.
    """
    if len(te) == 0:
        return np.zeros((len(grid), len(grid)))
    order = np.argsort(band, kind="stable")
    te, c, s, band = te[order], c[order], s[order], band[order]
    starts = np.flatnonzero(np.r_[True, band[1:] != band[:-1]])
    margin = 2.0 * float(np.abs(grid).max()) + 2.0 * bin_te
    lo = np.minimum.reduceat(te, starts) - margin
    width = np.floor((np.maximum.reduceat(te, starts) + margin - lo) / bin_te).astype(np.int64) + 2
    first = np.r_[0, np.cumsum(width)[:-1]]
    run = np.diff(np.r_[starts, len(te)])
    x0 = te / bin_te - np.repeat(lo / bin_te, run)
    g = np.asarray(grid, dtype=np.float64)
    return _comb_scores(x0, c / bin_te, s / bin_te, np.repeat(first, run).astype(np.int64),
                        g, g, int(width.sum()))


def _comb_view(comb: np.ndarray, origin: np.ndarray, R: np.ndarray):
    """``(te, cos, sin, band)`` of the returns between :data:`COMB_MIN_M` and
    :data:`COMB_MAX_M` from the axis, seen from a sensor at ``origin`` with axes ``R``."""
    q = (comb - origin) @ R
    d = np.hypot(q[:, 0], q[:, 1])
    ok = (d > COMB_MIN_M) & (d < COMB_MAX_M)
    band = np.floor(1.0 / d[ok] / BAND_INV).astype(np.int64)
    return q[ok, 2] / d[ok], q[ok, 0] / d[ok], q[ok, 1] / d[ok], band - (band.min() if
                                                                           len(band) else 0)


def _tilt_search(comb: np.ndarray, origin: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Sensor axes (3, 3) near ``R`` whose tilt makes the banded ``z / d`` comb of ``comb``
    (N, 3) seen from ``origin`` (3,) sharpest (module docstring, step 3).

    The comb is sharp only within about one ring spacing of the true tilt (0.1-0.4 deg), and
    its sharpness with coarse bins is dominated by road-like surfaces, so the first grid is
    already fine: :data:`TILT_STEP_DEG` steps with bins as wide as the smear a step leaves,
    over every tilt within :data:`MAX_TILT_DEG` of ``R``'s axis, in tiles of
    :data:`TILT_SPAN_DEG` about their own centres (each tile turns the returns by the
    small-angle change of ``z / d`` about its centre). The landscape has many local maxima
    (one per pair of lasers a wrong tilt lines up somewhere), and a search that only moves on
    while its best tilt lies on a grid's border stops at one of them: started 2 deg from the
    axis (the road's crossfall on PandaSet frame 00) it stopped 0.2-0.7 deg off. The
    :data:`TILT_CANDIDATES` sharpest local maxima of all tiles are refined on finer grids and
    the sharpest result is kept.
    """
    step = TILT_STEP_DEG
    grid = np.radians(np.arange(-TILT_SPAN_DEG, TILT_SPAN_DEG + 0.5 * step, step))
    n_tiles = int(np.ceil(MAX_TILT_DEG / (2.0 * TILT_SPAN_DEG)))
    centres = (np.arange(2 * n_tiles) - n_tiles + 0.5) * 2.0 * TILT_SPAN_DEG
    # Every other return: the first grids only have to rank the candidates.
    sub = comb[::2]
    found = []
    for tx in centres:
        for ty in centres:
            # Tiles reaching into the cone of MAX_TILT_DEG only.
            if np.hypot(max(abs(tx) - TILT_SPAN_DEG, 0.0),
                        max(abs(ty) - TILT_SPAN_DEG, 0.0)) > MAX_TILT_DEG:
                continue
            Rt = R @ _small_turn(np.radians(tx), np.radians(ty))
            te, c, s, band = _comb_view(sub, origin, Rt)
            if len(te) < MIN_RING_POINTS:
                continue
            scores = _comb_grid(te, c, s, band, grid, max(FINEST_BIN, np.radians(step)))
            peak = scores >= maximum_filter(scores, size=3, mode="nearest")
            for k in np.flatnonzero(peak.ravel()):
                found.append((float(scores.ravel()[k]),
                              Rt @ _small_turn(grid[k // len(grid)], grid[k % len(grid)])))
    if not found:
        return R
    found.sort(key=lambda v: -v[0])
    # The sharpest maxima more than 1.5 steps apart (tiles share their borders).
    cand: list[np.ndarray] = []
    for _score, Rc in found:
        if all(np.degrees(np.arccos(np.clip(Rc[:, 2] @ Ro[:, 2], -1.0, 1.0))) > 1.5 * step
               for Ro in cand):
            cand.append(Rc)
        if len(cand) == TILT_CANDIDATES:
            break
    best, best_R = -1.0, R
    for Rc in cand:
        score = -1.0
        for span, fine in ((1.5 * step, 0.3 * step), (0.3 * step, 0.1 * step)):
            g = np.radians(np.arange(-span, span + 0.5 * fine, fine))
            te, c, s, band = _comb_view(comb, origin, Rc)
            sc = _comb_grid(te, c, s, band, g, FINEST_BIN)
            ix, iy = np.unravel_index(np.argmax(sc), sc.shape)
            Rc = Rc @ _small_turn(g[ix], g[iy])
            score = float(sc[ix, iy])
        if score > best:
            best, best_R = score, Rc
    return best_R


def _height_search(far: np.ndarray, foot: np.ndarray, R: np.ndarray) -> float:
    """Height (m) along the axis ``R[:, 2]`` above ``foot`` (3,) that makes the pooled ``z / d``
    comb of the far returns ``far`` (N, 3) sharpest, 0 to 4 m (a roof mount's height)."""
    best_h, best_s = 1.5, -1.0
    for span, step, h0 in ((2.0, 0.05, 2.0), (0.1, 0.01, None), (0.01, 0.002, None)):
        centre = h0 if h0 is not None else best_h
        for h in np.arange(centre - span, centre + span + 0.5 * step, step):
            q = (far - foot - h * R[:, 2]) @ R
            x = q[:, 2] / np.hypot(q[:, 0], q[:, 1]) / FINEST_BIN
            k = np.floor(x).astype(np.int64)
            s = _sharpness(k, x - k)
            if s > best_s:
                best_h, best_s = float(h), s
    return best_h


# --- fine: the line model ------------------------------------------------------------------------

def _line_fit_terms(te: np.ndarray, inv: np.ndarray, lab: np.ndarray, n: int, w: np.ndarray):
    """Per-line weighted least squares ``te = a + h inv``: the sums needed to fit (and to
    project other columns on) each line's ``[1, inv]``."""
    s0 = np.bincount(lab, w, n)
    s1 = np.bincount(lab, w * inv, n)
    s2 = np.bincount(lab, w * inv * inv, n)
    det = s0 * s2 - s1 * s1
    # A line whose returns span no range of distances only has a level (h = 0).
    good = det > 1e-12 * np.maximum(s0, 1.0) ** 2
    return s0, s1, s2, det, good


def _solve_lines(v: np.ndarray, inv: np.ndarray, lab: np.ndarray, n: int, w: np.ndarray,
                 terms) -> tuple[np.ndarray, np.ndarray]:
    """Per-line ``(a, h)`` (n,) of the weighted least-squares fit of ``v`` on ``[1, inv]``."""
    s0, s1, s2, det, good = terms
    t0 = np.bincount(lab, w * v, n)
    t1 = np.bincount(lab, w * inv * v, n)
    safe = np.where(good, det, 1.0)
    a = np.where(good, (s2 * t0 - s1 * t1) / safe, t0 / np.maximum(s0, 1e-12))
    h = np.where(good, (s0 * t1 - s1 * t0) / safe, 0.0)
    return a, h


def _gauss_newton_step(P: np.ndarray, R: np.ndarray, o: np.ndarray, lab: np.ndarray,
                       n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One variable-projection Gauss-Newton step of the axis position and tilt.

    The residual of a return is ``te - a_k - h_k inv`` in the sensor frame ``(R, o)``; each
    line's ``(a_k, h_k)`` is eliminated in closed form (the Jacobian's columns are projected off
    each line's ``[1, inv]``). The parameters are the origin's move along the sensor's x and y
    (m) and small turns about them (rad); a move along the axis only shifts every ``h_k``.

    Parameters
    ----------
    P : ndarray, shape (M, 3)
        Labelled returns in the cloud's frame (m).
    R, o : ndarray, shapes (3, 3) and (3,)
        The current sensor axes (columns) and origin.
    lab : ndarray, shape (M,), int
        Line of each return, 0 .. n-1.
    n : int

    Returns
    -------
    R, o : the updated pose
    step : ndarray, shape (4,), the step taken
    """
    Q = (P - o) @ R
    d = np.hypot(Q[:, 0], Q[:, 1])
    te, inv = Q[:, 2] / d, 1.0 / d
    w = np.ones(len(P))
    for _ in range(2):
        terms = _line_fit_terms(te, inv, lab, n, w)
        a, h = _solve_lines(te, inv, lab, n, w, terms)
        r = te - a[lab] - h[lab] * inv
        # Huber weights: a few wrongly labelled returns must not steer the step.
        c = 3.0 * 1.4826 * np.median(np.abs(r)) + 1e-12
        w = np.minimum(1.0, c / np.maximum(np.abs(r), 1e-300))
    # d(te - h inv)/dq, then dq/d(parameters): q = Rw^T (Q - t), Rw^T ~ I - [w]x.
    g = (h[lab] - Q[:, 2]) / d ** 3
    dx, dy, dz = g * Q[:, 0], g * Q[:, 1], inv
    J = np.column_stack([-dx, -dy, dy * Q[:, 2] - dz * Q[:, 1], dz * Q[:, 0] - dx * Q[:, 2]])
    JP = np.empty_like(J)
    for j in range(4):
        aj, hj = _solve_lines(J[:, j], inv, lab, n, w, terms)
        JP[:, j] = J[:, j] - aj[lab] - hj[lab] * inv
    A = JP.T @ (w[:, None] * JP)
    b = JP.T @ (w * r)
    A += 1e-9 * max(np.trace(A), 1e-300) * np.eye(4)
    try:
        step = -np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return R, o, np.zeros(4)
    if not np.all(np.isfinite(step)):
        return R, o, np.zeros(4)
    scale = min(1.0, MAX_STEP_M / max(np.hypot(step[0], step[1]), 1e-300),
                MAX_STEP_RAD / max(np.hypot(step[2], step[3]), 1e-300))
    step = step * scale
    o = o + R @ np.array([step[0], step[1], 0.0])
    R = R @ _small_turn(step[2], step[3])
    return R, o, step


def _small_turn(wx: float, wy: float) -> np.ndarray:
    """Rotation (3, 3) by the vector (wx, wy, 0) rad (Rodrigues)."""
    w = np.array([wx, wy, 0.0])
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    k = w / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * K @ K


def _gaps(a: np.ndarray, h: np.ndarray, inv: float) -> np.ndarray:
    """Gap (n,) in z / d between each line and its nearest neighbour at 1/d = ``inv``."""
    at = a + h * inv
    order = np.argsort(at)
    g = np.diff(at[order])
    out = np.full(len(a), np.inf)
    out[order] = np.minimum(np.r_[np.inf, g], np.r_[g, np.inf])
    return out


def _label(te: np.ndarray, inv: np.ndarray, a: np.ndarray, h: np.ndarray):
    """Nearest line (M,) per return and whether it lies within :data:`LABEL_GAP_SHARE` of the
    gap to that line's neighbours, at the returns' typical distance."""
    if len(a) == 0:
        return np.zeros(len(te), dtype=np.int64), np.zeros(len(te), dtype=bool)
    lab, res = nearest_line(te, inv, a, h)
    gap = _gaps(a, h, float(np.median(inv)) if len(inv) else 0.0)
    return lab, res < LABEL_GAP_SHARE * np.minimum(gap, 1.0)[lab]


def fit_line_model(points: np.ndarray, R: np.ndarray, o: np.ndarray,
                   stages=STAGE_MIN_M) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Refine the axis position and tilt by the line model, far returns first (module
    docstring, step 5).

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Returns in the cloud's frame (m), a subsample of the sweep.
    R : ndarray, shape (3, 3)
        Starting sensor axes (columns, in the cloud's frame).
    o : ndarray, shape (3,)
        Starting sensor origin (m); its height must be within about 0.2 m (the lines' height
        offsets absorb the rest).
    stages : sequence of float
        Minimum horizontal distance (m) of the returns used, stage by stage.

    Returns
    -------
    R, o : ndarray, shapes (3, 3) and (3,)
        The refined pose (the origin moves only across the axis).
    a, h : ndarray, shape (n,)
        The lines ``z / d = a + h / d`` of the final frame.
    """
    a = np.zeros(0)
    h = np.zeros(0)
    for d_min in stages:
        for it in range(FIT_ITERATIONS):
            Q = (points - o) @ R
            d = np.hypot(Q[:, 0], Q[:, 1])
            use = d > d_min
            te, inv = Q[use, 2] / d[use], 1.0 / d[use]
            lab, inside = _label(te, inv, a, h)
            if it == 0:
                # Lasers seen only at this stage's distances: lines of the unexplained returns.
                cand = np.flatnonzero(~inside)
                if len(cand) >= MIN_RING_POINTS * 4:
                    if len(cand) > NEW_LINE_SAMPLE:
                        cand = cand[np.linspace(0, len(cand) - 1, NEW_LINE_SAMPLE).astype(int)]
                    new = extract_lines(te[cand], inv[cand])
                    if new:
                        a = np.r_[a, [v[0] for v in new]]
                        h = np.r_[h, [v[1] for v in new]]
                        lab, inside = _label(te, inv, a, h)
            counts = np.bincount(lab[inside], minlength=len(a))
            keep = counts >= MIN_RING_POINTS
            if keep.sum() < 3:
                break
            remap = np.full(len(a), -1)
            remap[keep] = np.arange(keep.sum())
            lab = remap[lab]
            sel = inside & (lab >= 0)
            a, h = a[keep], h[keep]
            R, o, step = _gauss_newton_step(points[use][sel], R, o, lab[sel], len(a))
            # The lines in the moved frame, refitted from the same labels.
            Q = (points[use][sel] - o) @ R
            dd = np.hypot(Q[:, 0], Q[:, 1])
            w = np.ones(len(dd))
            terms = _line_fit_terms(Q[:, 2] / dd, 1.0 / dd, lab[sel], len(a), w)
            a, h = _solve_lines(Q[:, 2] / dd, 1.0 / dd, lab[sel], len(a), w, terms)
            if np.hypot(step[0], step[1]) < CONVERGED_M and np.abs(step[2:]).max() < CONVERGED_RAD:
                break
    return R, o, a, h


# --- the estimate --------------------------------------------------------------------------------

def estimate_sensor_pose(points: np.ndarray,
                         rng: np.random.Generator | int | None = 0) -> SensorPoseEstimate | None:
    """Estimate the LiDAR's pose in the cloud's frame from one sweep (module docstring).

    The rough stages work on random subsamples, and an unlucky one can put the ground rings'
    centre in the wrong place; the line model then explains too little and the estimate is
    made again from fresh subsamples, up to :data:`ATTEMPTS` times (the best one is returned).

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        The sweep in the cloud's frame (metres), z roughly up; non-finite rows are ignored.
    rng : numpy Generator or seed
        Drives the subsamples and RANSAC: the same seed gives the same estimate.

    Returns
    -------
    SensorPoseEstimate, or None when the sweep gives no basis (fewer than
    :data:`MIN_SWEEP_POINTS` finite returns, or no ground plane to start from). An estimate
    whose lines do not explain the sweep comes back with ``ok`` False.
    """
    rng = np.random.default_rng(rng)
    best = None
    for _ in range(ATTEMPTS):
        est = _estimate_once(points, rng)
        if est is None or est.ok:
            return est
        if best is None or est.explained > best.explained:
            best = est
    return best


def _estimate_once(points: np.ndarray,
                   rng: np.random.Generator) -> SensorPoseEstimate | None:
    """One estimate from one set of subsamples (see :func:`estimate_sensor_pose`)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        return None
    pts = pts[:, :3]
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < MIN_SWEEP_POINTS:
        return None
    if len(pts) > SAMPLE:
        pts = pts[np.sort(rng.choice(len(pts), SAMPLE, replace=False))]
    near = pts[np.hypot(pts[:, 0], pts[:, 1]) < GROUND_NEAR_M]
    plane = ground_plane(near, rng)
    if plane is None:
        return None
    normal, offset = plane
    B = _plane_basis(normal)
    height = pts @ normal - offset
    notes: list[str] = []

    # 2. The centre of the ground circles (plane coordinates).
    ground = pts[(np.abs(height) < GROUND_TOL_M)]
    g2 = ground @ B[:2].T
    g2 = g2[np.hypot(g2[:, 0], g2[:, 1]) < CIRCLE_MAX_M]
    if len(g2) > CIRCLE_SAMPLE:
        g2 = g2[np.sort(rng.choice(len(g2), CIRCLE_SAMPLE, replace=False))]
    c = ground_circle_centre(g2) if len(g2) >= MIN_RING_POINTS else np.zeros(2)
    foot = B[:2].T @ c + offset * normal           # the axis' foot on the ground plane

    # 3. Tilt by the comb of the off-ground returns (a rough height: the bands absorb it).
    comb = pts[height > OFF_GROUND_M]
    if len(comb) > COMB_SAMPLE:
        comb = comb[np.sort(rng.choice(len(comb), COMB_SAMPLE, replace=False))]
    R = _frame_about(normal)
    if len(comb):
        R = _tilt_search(comb, foot + 1.5 * normal, R)

    # 4. Height along the axis.
    q = (comb - foot) @ R
    far = comb[np.hypot(q[:, 0], q[:, 1]) > HEIGHT_MIN_M]
    h0 = _height_search(far, foot, R) if len(far) >= MIN_RING_POINTS else 1.5
    o = foot + h0 * R[:, 2]

    # 5. The line model, far returns first.
    fit = pts if len(pts) <= FIT_SAMPLE else pts[np.sort(rng.choice(len(pts), FIT_SAMPLE,
                                                                     replace=False))]
    R, o, a, h = fit_line_model(fit, R, o)

    # 6. Height convention: the median line's height offset is zero.
    if len(h):
        shift = float(np.median(h))
        o = o + shift * R[:, 2]
        h = h - shift
    R = _frame_about(R[:, 2])
    Q = (fit - o) @ R
    d = np.hypot(Q[:, 0], Q[:, 1])
    use = d > STAGE_MIN_M[-1]
    explained = 0.0
    if len(a) and use.any():
        _, inside = _label(Q[use, 2] / d[use], 1.0 / d[use], a, h)
        explained = float(inside.mean())
    order = np.argsort(-(a + h / 10.0)) if len(a) else np.zeros(0, dtype=np.int64)
    ok = len(a) >= MIN_RINGS and explained >= MIN_EXPLAINED
    if not ok:
        notes.append(f"the fitted line model explains {100 * explained:.0f}% of the returns "
                     f"with {len(a)} lines (needs {100 * MIN_EXPLAINED:.0f}% and {MIN_RINGS}): "
                     "the sensor pose is not known")
    P = np.eye(4)
    P[:3, :3] = R
    P[:3, 3] = o
    tilt_deg = float(np.degrees(np.arccos(np.clip(R[:, 2] @ normal, -1.0, 1.0))))
    return SensorPoseEstimate(P, normal, float(o @ normal - offset), tilt_deg, explained,
                              len(a), a[order], h[order], ok, notes)
