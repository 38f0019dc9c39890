"""Per-frame features ready for the objective: visible at the initial guess, in a fixed order.

The first ``n`` points of the order are the ``n`` points a candidate uses, so solutions with
different ``n`` are nested and the cost of an evaluation grows with ``n``. The order is a seeded
random permutation stratified by feature group and by image cell (at the initial guess): any
prefix holds each group and each part of the image in proportion, so a small ``n`` is a
representative sample rather than a lucky or an unlucky one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera, in_image, project
from ..config import FeatureSettings, ObjectiveSettings
from ..geometry import invert, transform_points
from ..io.frame import Frame
from .image import ImageFeatures, image_features
from .lidar import GROUP_NAMES, LidarFeatures, lidar_features
from ..lidar.rings import Rings, recover_rings

CROP_EXTRA_PX = 150.0
#: Points projected at a time when a sweep is cropped to the view: the projection's float64
#: temporaries (about 80 bytes a point) then stay a few tens of MB however large the sweep.
CROP_BLOCK = 1 << 18


@dataclass(eq=False)
class FrameFeatures:
    """Everything the objective needs from one frame.

    Attributes
    ----------
    name : str
    camera : Camera
    image : ImageFeatures
    xyz : ndarray, shape (M, 3), float64
        Feature points in the LiDAR frame, in evaluation order (first ``n`` used).
    group : ndarray, shape (M,), int8
    weight : ndarray, shape (M,), float64
        Per-point weight in the objective.
    n_rings : int
    rings : dict, optional
        :meth:`Rings.summary` of the sweep (method, count, purity, notes).
    sampling_px : ndarray, shape (2,), optional
        How finely the LiDAR samples this camera's view (:func:`sampling_px`): the image
        distance in pixels between neighbouring returns along a ring and between neighbouring
        rings.
    """

    name: str
    camera: Camera
    image: ImageFeatures
    xyz: np.ndarray
    group: np.ndarray
    weight: np.ndarray
    n_rings: int
    rings: dict | None = None
    sampling_px: np.ndarray | None = None

    def split(self, holdout: float) -> tuple["FrameFeatures", "FrameFeatures"]:
        """The search part (the first points of the order) and a held-out tail.

        Because the order is stratified, the tail is a representative sample that the search
        never sees: it scores each solution's pose without the optimiser's selection bias.

        Parameters
        ----------
        holdout : float
            The share of the points held out, in [0, 1).

        Returns
        -------
        head, tail : FrameFeatures
        """
        m = len(self.xyz)
        cut = m - int(round(holdout * m))
        head = FrameFeatures(self.name, self.camera, self.image, self.xyz[:cut],
                             self.group[:cut], self.weight[:cut], self.n_rings, self.rings,
                             self.sampling_px)
        tail = FrameFeatures(self.name, self.camera, self.image, self.xyz[cut:],
                             self.group[cut:], self.weight[cut:], self.n_rings, self.rings,
                             self.sampling_px)
        return head, tail

    def counts(self) -> dict[str, int]:
        """Number of points per feature group."""
        return {g: int((self.group == i).sum()) for i, g in enumerate(GROUP_NAMES)}


def stratified_order(group: np.ndarray, cell: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A permutation whose prefixes hold every (group, cell) stratum in proportion.

    Each stratum's points get keys ``(rank + u) / size`` with a random rank order and
    ``u ~ U(0, 1)``; sorting all keys interleaves the strata evenly.

    Parameters
    ----------
    group : ndarray of int, shape (M,)
        Each point's feature group.
    cell : ndarray of int, shape (M,)
        Each point's image cell.
    rng : numpy.random.Generator
        The random generator (the order is seeded).

    Returns
    -------
    ndarray of int64, shape (M,)
        The permutation.
    """
    m = len(group)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    stratum = group.astype(np.int64) * (int(cell.max()) + 1) + cell
    perm = rng.permutation(m)
    s = stratum[perm]
    order_in = np.argsort(s, kind="stable")
    sizes = np.bincount(s)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    rank = np.empty(m, dtype=np.int64)
    rank[order_in] = np.arange(m) - starts[s[order_in]]
    key = (rank + rng.random(m)) / sizes[s]
    return perm[np.argsort(key, kind="stable")]


def sensor_points(frame: Frame) -> np.ndarray:
    """The frame's points in the LiDAR sensor's own frame, (N, 4) float64 (intensity kept).

    Ring geometry (ranges, azimuths, elevations) is about the sensor origin and spinning axis;
    clouds stored in a vehicle frame carry the sensor's pose (``Frame.sensor_pose``).
    """
    pts = np.asarray(frame.points, dtype=np.float64)
    if frame.sensor_pose is None:
        return pts
    out = pts.copy()
    out[:, :3] = transform_points(invert(frame.sensor_pose), pts)
    return out


def frame_rings(frame: Frame, features: FeatureSettings,
                rng: np.random.Generator | int | None = 0, model: Rings | None = None,
                view: np.ndarray | None = None) -> Rings:
    """The rings of a frame's sweep: the file's ring field when plausible, else recovered
    (see :func:`~paretocal.lidar.rings.recover_rings`; ``model``, an earlier sweep's rings
    of the same sensor, makes the recovery of an unordered sweep several times cheaper;
    ``view``, the returns features are taken from (:func:`view_mask`), is where the rings
    are judged)."""
    return recover_rings(sensor_points(frame), features.ring_method, ring_field=frame.ring,
                         rng=rng, source=str(frame.points_path), model=model, view=view)


def view_mask(frame: Frame, views, features: FeatureSettings) -> np.ndarray:
    """The returns of ``frame`` that features are taken from when seen by any of ``views``,
    pairs ``(Camera, T_cam_lidar)``: in front of the camera and within the margin
    :func:`prepare_frame` crops the sweep to. Shape (N,), bool."""
    mask = np.zeros(len(frame.points), dtype=bool)
    for camera, T in views:
        mask |= _near_view(frame.points, camera, T, features.z_min,
                           features.view_margin_px + CROP_EXTRA_PX)
    return mask


def frame_image_features(frame: Frame, features: FeatureSettings,
                         objective: ObjectiveSettings) -> ImageFeatures:
    """The image features of ``frame`` as a calibration with these settings computes them:
    Canny edges (:func:`~paretocal.features.image.edge_map`) and their truncated distance
    transform, with the frame's mask."""
    return image_features(
        frame.image, features.blur_sigma, features.canny_low, features.canny_high,
        objective.truncation_px, features.min_edge_px, mask=frame.mask,
        relative=features.canny_relative, equalize=features.equalize,
        noise_sigmas=features.canny_noise)


def prepare_frame(frame: Frame, T_init: np.ndarray, features: FeatureSettings,
                  objective: ObjectiveSettings, rng: np.random.Generator,
                  rings: Rings | None = None, image: ImageFeatures | None = None,
                  sampling: bool = True) -> FrameFeatures:
    """Extract, filter and order the features of one frame.

    Only feature points that project into the image grown by ``view_margin_px`` at ``T_init``
    are kept: the objective compares what both sensors see, and points far outside the view
    would reward poses that pull unseen structure into the image.

    Parameters
    ----------
    frame : Frame
        The image, the cloud, the camera and their optional fields.
    T_init : ndarray, shape (4, 4)
        The extrinsic ``T_cam_lidar`` (m) whose view chooses the points.
    features : FeatureSettings
        The ``features`` section of the settings.
    objective : ObjectiveSettings
        The ``objective`` section (which feature groups are used, the Canny and DT settings).
    rng : numpy.random.Generator
        The seeded generator of the points' order.
    rings : Rings, optional
        The sweep's rings (:func:`frame_rings`): saves recovering them again.
    image : ImageFeatures, optional
        The frame's image features with the same settings, from an earlier pass: saves
        computing them again (neither depends on the pose).
    sampling : bool
        Measure the LiDAR's sampling step in the image (the verdict's; a stage that only
        searches leaves it None).

    Returns
    -------
    FrameFeatures
        The feature points (M, 3) in the LiDAR frame (m), in their search order, with their
        groups and weights, and the image features.
    """
    img = image if image is not None else frame_image_features(frame, features, objective)
    # Rings come from the whole sweep; edges are then found only in the part of the sweep
    # near the view, a quarter of the points (a wider margin than the view's, so that no
    # neighbour of a kept point is lost). Edges are found in the sensor frame and mapped back.
    near = view_mask(frame, [(frame.camera, T_init)], features)
    if rings is None:
        rings = frame_rings(frame, features, rng, view=near)
    spacing = rings.spacing_deg()
    pts_s = sensor_points(frame)
    lf: LidarFeatures = lidar_features(
        pts_s[near], ring=rings.ring[near],
        ring_spacing_deg=float(np.nanmedian(spacing)) if np.isfinite(spacing).any() else None,
        ring_elevation_deg=rings.elevation_deg if rings.n_rings > 1 else None,
        time=None if frame.time is None else frame.time[near],
        sweep_s=None if frame.time is None else float(np.ptp(frame.time)),
        sky_edges=features.sky_edges,
        depth_jump_m=features.depth_jump_m, cross_ring=features.cross_ring,
        cross_jump_m=features.cross_jump_m, cross_jump_rel=features.cross_jump_rel,
        ground_tol_m=features.ground_tol_m,
        intensity_jump=features.intensity_jump, min_range_m=features.min_range_m,
        max_range_m=features.max_range_m,
        smooth_ratio=features.smooth_ratio if objective.contrast > 0 else 0.0,
        ring_method=features.ring_method, along_fraction=features.along_fraction,
        cross_fraction=features.cross_fraction, edge_support=features.edge_support,
        edge_contour=features.edge_contour, rng=rng)
    xyz_all = lf.xyz
    if frame.sensor_pose is not None:
        xyz_all = transform_points(frame.sensor_pose, xyz_all)
    keep = _wanted_groups(lf.group, objective)
    uv, z, _ = project(xyz_all, frame.camera, T_init, features.z_min)
    keep &= (z > features.z_min) & in_image(uv, frame.camera.width, frame.camera.height,
                                            features.view_margin_px)
    xyz, group, uv = xyz_all[keep], lf.group[keep], uv[keep]
    weight = point_weights(lf.strength[keep], group, features.edge_weight,
                           np.linalg.norm(lf.xyz[keep], axis=1))
    gx, gy = features.grid
    cu = np.clip((uv[:, 0] / frame.camera.width * gx).astype(np.int64), 0, gx - 1)
    cv = np.clip((uv[:, 1] / frame.camera.height * gy).astype(np.int64), 0, gy - 1)
    order = stratified_order(group, cv * gx + cu, rng)
    step = (sampling_px(pts_s[near], rings.ring[near], frame.camera, T_init, frame.sensor_pose,
                        features.z_min) if sampling else None)
    return FrameFeatures(frame.name, frame.camera, img, xyz[order], group[order], weight[order],
                         rings.n_rings, rings.summary(), step)


#: Rays are projected from this far (m): the image distance between neighbouring returns is
#: then that of their directions, whatever their ranges (translation does not matter at 1 km).
SAMPLING_RAY_M = 1000.0


def sampling_px(points: np.ndarray, ring: np.ndarray, camera: Camera, T: np.ndarray,
                sensor_pose: np.ndarray | None = None, z_min: float = 0.1) -> np.ndarray | None:
    """How finely the LiDAR samples the camera's view, in image pixels.

    An edge between two returns lies somewhere between their rays: the LiDAR cannot place it
    closer than this, in every frame alike, so it bounds the alignment a calibration from
    this rig can vouch for (:func:`paretocal.verdict.intervals`). Measured on the rays, not
    taken from a data sheet, so it holds for any beam layout, storage order and lens model.

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        Returns in the LiDAR sensor's frame (origin on the spinning axis).
    ring : ndarray, shape (N,)
        Ring per return (-1: none), rings numbered from the top.
    camera, T : Camera, ndarray (4, 4)
        The camera and ``T_cam_lidar`` the view is judged at.
    sensor_pose : ndarray (4, 4), optional
        The sensor's pose in the LiDAR frame ``T`` applies to (clouds in a vehicle frame).

    Returns
    -------
    ndarray, shape (2,), or None
        Median image distance (px) between the directions of neighbouring returns in view:
        along a ring (the azimuth step), and to the azimuth-nearest return of the next ring
        down (the beam spacing). None when the view holds too few returns on rings.
    """
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    r = np.linalg.norm(pts, axis=1)
    ok = (np.asarray(ring) >= 0) & (r > 0)
    if ok.sum() < 3:
        return None
    rays = pts[ok] / r[ok, None] * SAMPLING_RAY_M
    if sensor_pose is not None:
        rays = transform_points(sensor_pose, rays)
    uv, _, vis = project(rays, camera, T, z_min)
    vis &= in_image(uv, camera.width, camera.height, 0.0)
    rg = np.asarray(ring)[ok]
    psi = np.mod(np.arctan2(pts[ok, 1], pts[ok, 0]), 2.0 * np.pi)
    order = np.lexsort((psi, rg))
    rg, psi, uv, vis = rg[order], psi[order], uv[order], vis[order]
    same = (rg[1:] == rg[:-1]) & vis[1:] & vis[:-1]
    along = np.linalg.norm(uv[1:] - uv[:-1], axis=1)[same]
    pieces = []
    ids, start = np.unique(rg, return_index=True)
    end = np.r_[start[1:], len(rg)]
    for k in range(len(ids) - 1):
        if ids[k + 1] != ids[k] + 1:                # a ring missing in between
            continue
        a, b = slice(start[k], end[k]), slice(start[k + 1], end[k + 1])
        if end[k + 1] - start[k + 1] < 2:
            continue
        j = np.clip(np.searchsorted(psi[b], psi[a]), 1, end[k + 1] - start[k + 1] - 1)
        pa, pb = psi[b][j - 1], psi[b][j]
        j = np.where(np.abs(psi[a] - pa) < np.abs(pb - psi[a]), j - 1, j)
        m = vis[a] & vis[b][j]
        pieces.append(np.linalg.norm(uv[a][m] - uv[b][j][m], axis=1))
    across = np.concatenate(pieces) if pieces else np.empty(0)
    if len(along) < 3 or len(across) < 3:
        return None
    return np.array([np.median(along), np.median(across)])


def _near_view(points: np.ndarray, camera: Camera, T: np.ndarray, z_min: float,
               margin_px: float) -> np.ndarray:
    """Mask of the points in front of the camera that project into the image grown by
    ``margin_px``, computed block by block (see :data:`CROP_BLOCK`)."""
    near = np.empty(len(points), dtype=bool)
    for a in range(0, len(points), CROP_BLOCK):
        uv, z, _ = project(points[a:a + CROP_BLOCK], camera, T, z_min)
        near[a:a + CROP_BLOCK] = (z > z_min) & in_image(uv, camera.width, camera.height,
                                                        margin_px)
    return near


RANGE_BINS_M = np.array([5.0, 10.0, 20.0, 40.0])


def point_weights(strength: np.ndarray, group: np.ndarray, rule: str,
                  range_m: np.ndarray | None = None) -> np.ndarray:
    """Objective weight per point.

    ``none``: 1. ``sqrt_jump``: depth edges weighted by ``sqrt(jump / 1 m)`` (Levinson and
    Thrun's edge strength), capped at 3. ``depth_balanced``: within each feature group, every
    occupied range band (< 5, 5-10, 10-20, 20-40, > 40 m) carries the same total weight
    (capped at 4x a point's share), so that structure at one depth cannot outvote the near
    and far points that separate rotation from translation.
    """
    w = np.ones(len(strength))
    if rule == "sqrt_jump":
        from .lidar import DEPTH_EDGE

        d = group == DEPTH_EDGE
        w[d] = np.clip(np.sqrt(np.maximum(strength[d], 0.0)), 0.1, 3.0)
    elif rule == "depth_balanced":
        if range_m is None:
            raise ValueError("the depth_balanced weighting needs each point's range (range_m)")
        band = np.searchsorted(RANGE_BINS_M, range_m)
        for g in np.unique(group):
            sel = group == g
            counts = np.bincount(band[sel], minlength=len(RANGE_BINS_M) + 1)
            occupied = int((counts > 0).sum())
            share = sel.sum() / (occupied * np.maximum(counts, 1))
            w[sel] = np.clip(share[band[sel]], 0.25, 4.0)
    elif rule != "none":
        raise ValueError(f"unknown edge weighting {rule!r}")
    return w


def _wanted_groups(group: np.ndarray, objective: ObjectiveSettings) -> np.ndarray:
    """Groups with zero weight are dropped, so they cost nothing."""
    from .lidar import DEPTH_EDGE, INTENSITY_EDGE, SMOOTH

    want = np.zeros(3, dtype=bool)
    want[DEPTH_EDGE] = objective.w_edge > 0
    want[INTENSITY_EDGE] = objective.w_edge < 1
    want[SMOOTH] = objective.contrast > 0
    return want[group]
