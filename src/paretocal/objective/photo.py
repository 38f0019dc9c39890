"""Photo-consistency across frames: a second objective that shares no feature with the edges.

A rig that moves sees each part of the scene from several places. With the right extrinsic, a
LiDAR point placed in the world by the LiDAR's own odometry lands on the same surface in every
image that sees it, so the images agree on its intensity; with a wrong one it lands on different
surfaces and they disagree. The cost of a candidate extrinsic is the mean, over the map's points,
of the variance of the image intensities at the point across the frames that see it. It needs no
edge, no intensity from the LiDAR and no single image to match the cloud: only motion (Ishikawa et
al., ICRA 2024, call it the intensity variance cost).

Three things keep a wrong pose from winning by seeing less, or by a change of exposure:

* each point counts by the texture where it lands (samples on sky or a blank wall tell nothing
  and weigh nearly nothing), and the cost is shrunk towards what unrelated pixels cost
  (:data:`UNSEEN_COST`) as if :data:`PRIOR_POINTS` more points had disagreed: a pose that
  pushes the map out of view, behind the camera or into the sky keeps only a few points and
  cannot win on their agreement;
* the map is the part of the sweeps that the frames see at a view pose (the initial
  extrinsic), with a margin, so that the cost does not reward a pose for seeing more;
* the images are normalised per frame (median and spread), so an exposure change between frames
  is not a disagreement.

Occlusion: in each frame a point counts only when no map point of its z-buffer cell lies
nearer by more than :data:`OCCLUSION_REL` of its range (the cells sized so that a surface's
points cover them, :func:`occlusion_cell_px`); otherwise it would read the occluder there.

The evaluator is a numba kernel over the whole population (parallel over candidates; each frame
projects blocks of points through the camera model with the edge kernel's projection blocks), and
a plain numpy version of the same arithmetic serves as its oracle.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import Camera, project
from ..geometry import invert, transform_points

try:
    import numba
    from numba import njit, prange

    from .kernel import BLOCK, block_scratch, max_threads, project_block

    HAVE_NUMBA = True
except Exception:  # pragma: no cover - exercised only where numba is broken
    HAVE_NUMBA = False

#: What a point seen by fewer than two frames costs: the variance of two unrelated samples of
#: a unit-variance image (the images are normalised), so that leaving the view never pays.
UNSEEN_COST = 1.0
#: The cost is shrunk towards :data:`UNSEEN_COST` as if this many points (at the images' mean
#: texture) had been seen and disagreed: a pose that sees only a handful of points (pitched
#: into the sky) cannot win on their agreement, while one that sees thousands is barely moved.
PRIOR_POINTS = 1000.0


@dataclass
class PhotoScene:
    """The map and the images the photo-consistency cost reads.

    Attributes
    ----------
    xyz : ndarray, shape (N, 3), float32
        Map points in the first sweep's LiDAR frame (m).
    to_sweep : ndarray, shape (K, 4, 4)
        Per frame, the map frame into that sweep's LiDAR frame (the inverse of its odometry pose).
    images : ndarray, shape (sum of H*W,), float32
        The frames' grey images, normalised (median 0, robust spread 1), flattened one after the
        other.
    texture : ndarray, shape (sum of H*W,), float32
        Per pixel, the local gradient magnitude of the normalised image (:func:`texture`): what
        a sample there can tell about alignment.
    image_start : ndarray, shape (K,), int64
    width, height : ndarray, shape (K,), int64
    cam_params : ndarray, shape (K, P)
        :meth:`~paretocal.camera.Camera.kernel_params` per frame.
    cameras : list of Camera
    z_min : float
    """

    xyz: np.ndarray
    to_sweep: np.ndarray
    images: np.ndarray
    texture: np.ndarray
    image_start: np.ndarray
    width: np.ndarray
    height: np.ndarray
    cam_params: np.ndarray
    cameras: list
    z_min: float = 0.5

    @property
    def n_frames(self) -> int:
        return len(self.to_sweep)

    def image(self, k: int, texture: bool = False) -> np.ndarray:
        """Frame k's normalised image (or its texture), shape (H, W), float32."""
        a = self.image_start[k]
        flat = self.texture if texture else self.images
        return flat[a:a + self.width[k] * self.height[k]].reshape(self.height[k], self.width[k])


def normalised_grey(image: np.ndarray) -> np.ndarray:
    """Grey image (H, W) float32 with median 0 and a robust spread of 1 (the 25-75 %
    interquartile range over 1.349, a normal's standard deviation): a gain or an offset between
    frames leaves it unchanged."""
    g = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    g = g.astype(np.float32)
    q25, q50, q75 = np.percentile(g, [25, 50, 75])
    spread = (q75 - q25) / 1.349
    return ((g - q50) / (spread if spread > 0 else 1.0)).astype(np.float32)


#: A point is hidden in a frame when a map point in the same cell of the image lies nearer than
#: this share of its range: the near side of a depth step is what the camera sees there.
OCCLUSION_REL = 0.1
#: The occlusion cells hold about this many map points each where the map covers the image
#: (the cell side follows from the map's size and the image's, :func:`occlusion_cell_px`).
POINTS_PER_CELL = 3.0


def occlusion_cell_px(n_points: int, width: int, height: int) -> int:
    """Side (px) of the z-buffer's cells: about :data:`POINTS_PER_CELL` map points per cell if
    the map covered the image, so that a surface's points hide what lies behind them."""
    return max(1, int(np.ceil(np.sqrt(width * height * POINTS_PER_CELL / max(n_points, 1)))))


#: Gaussian sigma (px) over which the gradient magnitude is averaged into a pixel's texture.
TEXTURE_SIGMA_PX = 2.0


def texture(grey: np.ndarray) -> np.ndarray:
    """Local texture (H, W) float32: the gradient magnitude of ``grey`` (Sobel, per pixel)
    averaged over :data:`TEXTURE_SIGMA_PX`. Sky and blank walls read near zero."""
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    return cv2.GaussianBlur(np.sqrt(gx * gx + gy * gy), (0, 0), TEXTURE_SIGMA_PX)


def build_photo_scene(clouds, poses: np.ndarray, images, cameras: list[Camera], *,
                      view: np.ndarray | None = None, margin: float = 0.3,
                      max_points: int = 60_000, min_range_m: float = 2.0,
                      max_range_m: float = 40.0, rng: np.random.Generator | int | None = 0,
                      z_min: float = 0.5) -> PhotoScene:
    """The map (sweeps placed by their odometry poses, a seeded sample of ``max_points``) and the
    normalised images.

    Parameters
    ----------
    clouds : sequence of ndarray, shape (N_k, 3+)
        Each frame's sweep in its LiDAR frame (m).
    poses : ndarray, shape (K, 4, 4)
        Each sweep's pose in the first sweep's frame (``LidarOdometry.poses``).
    images : sequence of ndarray
        Each frame's image.
    cameras : list of Camera
    view : ndarray, shape (4, 4), optional
        ``T_cam_lidar`` the map is chosen at: only points that at least two frames see there,
        in their image grown by ``margin`` (a share of its width and height), are kept.
    max_points : int
        Map points kept (a uniform sample over the sweeps).
    min_range_m, max_range_m : float
        Returns used, by range from their own sweep's origin: the nearest are the vehicle and
        its mounts, the farthest move too little between frames to tell poses apart.
    rng : Generator or seed
    """
    if any(c.mount is not None for c in cameras):
        raise ValueError("build_photo_scene: cameras with a mount (a rig calibrated at once) "
                         "are not supported")
    rng = np.random.default_rng(rng)
    parts = []
    for pts, P in zip(clouds, poses):
        p = np.asarray(pts, dtype=np.float64)[:, :3]
        r = np.linalg.norm(p, axis=1)
        p = p[(r > min_range_m) & (r < max_range_m)]
        parts.append(transform_points(P, p))
    xyz = np.vstack(parts)
    to_sweep = np.array([invert(P) for P in poses])
    if view is not None:
        seen = np.zeros(len(xyz), np.int64)
        for Q, cam in zip(to_sweep, cameras):
            uv, _, ok = project(xyz, cam, np.asarray(view, np.float64) @ Q, z_min)
            mu, mv = margin * cam.width, margin * cam.height
            seen += (ok & (uv[:, 0] > -mu) & (uv[:, 0] < cam.width + mu)
                     & (uv[:, 1] > -mv) & (uv[:, 1] < cam.height + mv))
        xyz = xyz[seen >= 2]
    if len(xyz) > max_points:
        xyz = xyz[np.sort(rng.choice(len(xyz), max_points, replace=False))]
    grey = [normalised_grey(im) for im in images]
    h = np.array([g.shape[0] for g in grey], np.int64)
    w = np.array([g.shape[1] for g in grey], np.int64)
    start = np.r_[0, np.cumsum(h * w)[:-1]].astype(np.int64)
    return PhotoScene(xyz=np.ascontiguousarray(xyz, np.float32),
                      to_sweep=to_sweep,
                      images=np.concatenate([g.ravel() for g in grey]),
                      texture=np.concatenate([texture(g).ravel() for g in grey]),
                      image_start=start,
                      width=w, height=h,
                      cam_params=np.vstack([c.kernel_params() for c in cameras]),
                      cameras=list(cameras), z_min=float(z_min))


def _frame_transforms(scene: PhotoScene, T: np.ndarray) -> np.ndarray:
    """(C, K, 3, 4): candidate ``T_cam_lidar`` (C, 4, 4) composed with each frame's map-to-sweep
    transform, the map into each frame's camera."""
    T = np.asarray(T, dtype=np.float64)
    return np.ascontiguousarray(np.einsum("cij,kjl->ckil", T, scene.to_sweep)[:, :, :3, :])


def _cost_from_sums(S1, S2, N, W, tau):
    """Per candidate (S1, S2, N, W: (C, M) per-point sums of the intensity, its square, the
    frames that saw the point and the texture there; ``tau`` the images' mean texture):
    ``cost``, the texture-weighted mean over the points seen by at least two frames of their
    intensity variance across those frames (a point's weight its mean texture: samples on sky
    or a blank wall tell nothing, so they neither help nor harm a pose), shrunk towards
    :data:`UNSEEN_COST` as if :data:`PRIOR_POINTS` points of weight ``tau`` had cost that;
    ``coverage``, the share of points seen by at least two frames; ``variance_seen``, the
    unweighted mean variance over those."""
    seen = N >= 2
    n = np.maximum(N, 1)
    var = np.maximum(S2 / n - (S1 / n) ** 2, 0.0) * n / np.maximum(N - 1, 1)
    wt = np.where(seen, W / n, 0.0)
    w0 = PRIOR_POINTS * tau
    cost = ((wt * var).sum(axis=1) + w0 * UNSEEN_COST) / (wt.sum(axis=1) + w0)
    return {"cost": cost, "coverage": seen.mean(axis=1),
            "variance_seen": np.where(seen, var, 0.0).sum(axis=1)
            / np.maximum(seen.sum(axis=1), 1),
            "point_weight": wt, "point_variance": np.where(seen, var, 0.0), "prior": w0}


def _sample(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear samples of img (H, W) at (u, v) inside it, as the kernel computes them."""
    h, w = img.shape
    x0 = np.minimum(u.astype(np.int64), w - 2)
    y0 = np.minimum(v.astype(np.int64), h - 2)
    fx, fy = u - x0, v - y0
    i00 = img[y0, x0].astype(np.float64)
    i10 = img[y0 + 1, x0].astype(np.float64)
    top = i00 + fx * (img[y0, x0 + 1] - i00)
    bot = i10 + fx * (img[y0 + 1, x0 + 1] - i10)
    return top + fy * (bot - top)


def _visible(pc: np.ndarray, uv: np.ndarray, ok: np.ndarray, w: int, h: int,
             m: int) -> np.ndarray:
    """Points (camera frame ``pc`` (M, 3), pixels ``uv``, valid ``ok``) not hidden by a nearer
    point of their z-buffer cell (:data:`OCCLUSION_REL`), as the kernel decides it."""
    cell = occlusion_cell_px(m, w, h)
    cw = (w - 1) // cell + 1
    uu = np.where(ok, uv[:, 0], 0.0)
    vv = np.where(ok, uv[:, 1], 0.0)
    x0 = np.minimum(uu.astype(np.int64), w - 2)
    y0 = np.minimum(vv.astype(np.int64), h - 2)
    idx = (y0 // cell) * cw + x0 // cell
    d = np.linalg.norm(pc, axis=1)
    zb = np.full(((h - 1) // cell + 1) * cw, np.inf)
    np.minimum.at(zb, idx[ok], d[ok])
    return ok & (d * (1.0 - OCCLUSION_REL) <= zb[idx])


def photo_cost_numpy(scene: PhotoScene, T: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`photo_cost` in plain numpy (the oracle of the kernel)."""
    M = _frame_transforms(scene, T)
    C, K = M.shape[:2]
    m = len(scene.xyz)
    S1, S2, W = np.zeros((C, m)), np.zeros((C, m)), np.zeros((C, m))
    N = np.zeros((C, m), np.int64)
    pts = scene.xyz.astype(np.float64)
    for k in range(K):
        img, tex = scene.image(k), scene.image(k, texture=True)
        h, w = img.shape
        for c in range(C):
            T4 = np.vstack([M[c, k], [0.0, 0.0, 0.0, 1.0]])
            uv, _, ok = project(pts, scene.cameras[k], T4, scene.z_min)
            ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
            ok &= _visible(pts @ M[c, k, :, :3].T + M[c, k, :, 3], uv, ok, w, h, m)
            val = _sample(img, uv[ok, 0], uv[ok, 1])
            S1[c, ok] += val
            S2[c, ok] += val * val
            W[c, ok] += _sample(tex, uv[ok, 0], uv[ok, 1])
            N[c, ok] += 1
    return _cost_from_sums(S1, S2, N, W, float(np.mean(scene.texture)))


if HAVE_NUMBA:

    @njit(parallel=True, cache=True, error_model="numpy")
    def _photo_numba(M, cam, x, y, z, img, tex, img_start, width, height, cell_px, z_min, S1,
                     S2, N, W, KS, FS, OS, PK, PF, PD, ZB):  # pragma: no cover - compiled
        # Per candidate and frame, two passes: project every point (blocks through the lens
        # model, footprints and ranges kept per thread) filling a z-buffer of cells with the
        # nearest range; then sample the points no nearer point of their cell hides.
        C, K = M.shape[0], M.shape[1]
        m = x.shape[0]
        for c in prange(C):
            t = numba.get_thread_id()
            KB, FXB, FYB, OKB = KS[t], FS[t, 0], FS[t, 1], OS[t]
            pk, pfx, pfy, pd, zb = PK[t], PF[t, 0], PF[t, 1], PD[t], ZB[t]
            for k in range(K):
                w = width[k]
                h = height[k]
                cell = cell_px[k]
                cw = (w - 1) // cell + 1
                ncell = ((h - 1) // cell + 1) * cw
                for q in range(ncell):
                    zb[q] = np.inf
                base = img_start[k]
                row = cam[k]
                r00, r01, r02, r03 = M[c, k, 0, 0], M[c, k, 0, 1], M[c, k, 0, 2], M[c, k, 0, 3]
                r10, r11, r12, r13 = M[c, k, 1, 0], M[c, k, 1, 1], M[c, k, 1, 2], M[c, k, 1, 3]
                r20, r21, r22, r23 = M[c, k, 2, 0], M[c, k, 2, 1], M[c, k, 2, 2], M[c, k, 2, 3]
                for b in range(0, m, BLOCK):
                    bb = min(b + BLOCK, m)
                    project_block(row, r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23,
                                  x[b:bb], y[b:bb], z[b:bb], w, h, z_min, KB, FXB, FYB, OKB)
                    for j in range(bb - b):
                        i = b + j
                        X = np.float64(x[i])
                        Y = np.float64(y[i])
                        Z = np.float64(z[i])
                        xc = r00 * X + r01 * Y + r02 * Z + r03
                        yc = r10 * X + r11 * Y + r12 * Z + r13
                        zc = r20 * X + r21 * Y + r22 * Z + r23
                        kb = KB[j]
                        pk[i] = kb if OKB[j] else -1
                        pfx[i] = FXB[j]
                        pfy[i] = FYB[j]
                        d = np.sqrt(xc * xc + yc * yc + zc * zc)
                        pd[i] = d
                        if OKB[j]:
                            q = ((kb // w) // cell) * cw + (kb % w) // cell
                            if d < zb[q]:
                                zb[q] = d
                for i in range(m):
                    kb = pk[i]
                    if kb < 0:
                        continue
                    q = ((kb // w) // cell) * cw + (kb % w) // cell
                    if pd[i] * (1.0 - OCCLUSION_REL) > zb[q]:
                        continue
                    p = base + kb
                    fx = pfx[i]
                    fy = pfy[i]
                    top = img[p] + fx * (img[p + 1] - img[p])
                    bot = img[p + w] + fx * (img[p + w + 1] - img[p + w])
                    v = top + fy * (bot - top)
                    S1[c, i] += v
                    S2[c, i] += v * v
                    N[c, i] += 1
                    top = tex[p] + fx * (tex[p + 1] - tex[p])
                    bot = tex[p + w] + fx * (tex[p + w + 1] - tex[p + w])
                    W[c, i] += top + fy * (bot - top)


def photo_cost(scene: PhotoScene, T: np.ndarray) -> dict[str, np.ndarray]:
    """The photo-consistency cost of candidate extrinsics, all in one call.

    Parameters
    ----------
    scene : PhotoScene
    T : ndarray, shape (C, 4, 4)
        Candidate ``T_cam_lidar``.

    Returns
    -------
    dict
        ``cost`` (C,): the texture-weighted mean over the map's points seen by at least two
        frames of the variance of the normalised intensities across those frames, shrunk
        towards :data:`UNSEEN_COST` (lower is better; :func:`_cost_from_sums`);
        ``coverage`` (C,): the share of points seen by at least two frames;
        ``variance_seen`` (C,): the unweighted mean variance over those points;
        ``point_weight``, ``point_variance`` (C, N): each map point's weight and variance (0
        where fewer than two frames see it) and ``prior``, the shrinkage's weight, so that
        ``cost = (sum(weight * variance) + prior * UNSEEN_COST) / (sum(weight) + prior)``.
    """
    if not HAVE_NUMBA:  # pragma: no cover
        return photo_cost_numpy(scene, T)
    M = _frame_transforms(scene, T)
    C, m = len(M), len(scene.xyz)
    S1, S2, W = np.zeros((C, m)), np.zeros((C, m)), np.zeros((C, m))
    N = np.zeros((C, m), np.int64)
    x, y, z = (np.ascontiguousarray(scene.xyz[:, i]) for i in range(3))
    threads = max_threads()
    cell = np.array([occlusion_cell_px(m, w, h) for w, h in zip(scene.width, scene.height)],
                    np.int64)
    cells = int(max(((h - 1) // c + 1) * ((w - 1) // c + 1)
                    for w, h, c in zip(scene.width, scene.height, cell)))
    _photo_numba(M, scene.cam_params, x, y, z, scene.images, scene.texture, scene.image_start,
                 scene.width, scene.height, cell, np.float64(scene.z_min), S1, S2, N, W,
                 *block_scratch(threads), np.empty((threads, m), np.int64),
                 np.empty((threads, 2, m)), np.empty((threads, m)), np.empty((threads, cells)))
    return _cost_from_sums(S1, S2, N, W, float(np.mean(scene.texture)))
