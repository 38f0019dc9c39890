"""Per-point sums of the truncated distance-transform cost, for a whole population at once.

For every candidate c and frame f, the first ``n[c]`` points of frame f are moved into the
camera frame by ``T_c[:3]`` and projected through frame f's camera model (pinhole with or
without radial-tangential distortion, equidistant fisheye, Mei; :mod:`paretocal.camera`). A
point valid for the model whose bilinear lookup reads only usable pixels costs the bilinear DT
value at its pixel; any other point (behind the camera, beyond the lens's monotonic radius,
outside the image, or touching a masked pixel) costs ``outside[f]``. The evaluators return the
per-group weighted sums of the cost and of its square, shape (C, F, G), from which the objective
takes means and sampling errors.

Three implementations give the same sums: a fused numba kernel (parallel over candidates; each
block of 256 points is projected by one branch-free, vectorised loop into per-thread scratch,
then read, interpolated and summed in point order in three passes), a numpy fallback batched
over candidates, and a KD-tree oracle that measures exact distances to the edge pixels.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ..camera import (FISHEYE, MEI, P_CX, P_CY, P_FX, P_FY, P_K1, P_LIMIT, P_MODEL, P_P1, P_P2,
                      P_S1, P_SKEW, P_XI, P_ZS_MIN, PINHOLE_IDEAL, project)
from .scene import DT_MASKED, N_GROUPS, Scene

try:  # numba is a hard dependency, but keep the numpy path usable if it fails to import
    import numba
    from numba import njit, prange

    HAVE_NUMBA = True
except Exception:  # pragma: no cover - exercised only where numba is broken
    HAVE_NUMBA = False

SERIAL_BELOW = 4  # batches of fewer candidates run on one thread (see sums_numba)


#: Points a kernel pass projects at once: the projection of a block runs as one branch-free,
#: vectorised loop into per-thread scratch, then :func:`_lookup_sum` reads, interpolates and
#: sums the block in three passes.
BLOCK = 256

if HAVE_NUMBA:
    # error_model="numpy": a division by zero gives inf instead of raising, so numba emits no
    # check per division and LLVM vectorises the projection (2.5x faster on its own).

    @njit(cache=True, error_model="numpy", inline="always")
    def _footprint(u, v, ok, w, h, j, KB, FXB, FYB, OKB):  # pragma: no cover - compiled
        """Store the bilinear footprint of pixel (u, v) as entry j of the scratch: the flat
        index of its top-left pixel in the frame, the fractions, and whether the point counts:
        ``ok`` (valid for the camera model) and inside the w x h image. Points that do not
        count read pixel 0, harmlessly, so the loop has no branch."""
        ok = ok & (u >= 0.0) & (u <= w - 1.0) & (v >= 0.0) & (v <= h - 1.0)
        u = u if ok else 0.0
        v = v if ok else 0.0
        x0 = min(int(u), w - 2)
        y0 = min(int(v), h - 2)
        FXB[j] = u - x0
        FYB[j] = v - y0
        KB[j] = y0 * w + x0
        OKB[j] = ok

    @njit(cache=True, error_model="numpy", inline="always")
    def _camera_point(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, x, y,
                      z):  # pragma: no cover - compiled
        """A float32 LiDAR point in the camera frame (float64), by the rows ``r**`` of T[:3]."""
        X = np.float64(x)
        Y = np.float64(y)
        Z = np.float64(z)
        return (r00 * X + r01 * Y + r02 * Z + r03, r10 * X + r11 * Y + r12 * Z + r13,
                r20 * X + r21 * Y + r22 * Z + r23)

    @njit(cache=True, error_model="numpy")
    def pinhole_block(a00, a01, a02, a03, a10, a11, a12, a13, r20, r21, r22, r23, x, y, z,
                       w, h, z_min, KB, FXB, FYB, OKB):  # pragma: no cover - compiled
        """Project the points (x, y, z) (m,) through an ideal pinhole into the scratch: the rows
        ``a0*``, ``a1*`` of ``K @ T[:3]`` and the depth row ``r2*`` of ``T``. One division
        per point, no branch: the loop vectorises."""
        for j in range(x.shape[0]):
            X = np.float64(x[j])
            Y = np.float64(y[j])
            Z = np.float64(z[j])
            zc = r20 * X + r21 * Y + r22 * Z + r23
            iz = 1.0 / zc
            u = (a00 * X + a01 * Y + a02 * Z + a03) * iz
            v = (a10 * X + a11 * Y + a12 * Z + a13) * iz
            _footprint(u, v, zc > z_min, w, h, j, KB, FXB, FYB, OKB)

    @njit(cache=True, error_model="numpy")
    def radial_block(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, cam, x, y, z,
                      w, h, z_min, KB, FXB, FYB, OKB):  # pragma: no cover - compiled
        """:func:`pinhole_block` through a distorted pinhole or a Mei camera (``cam``: the
        frame's :meth:`Camera.kernel_params` row; ``r**``: ``T[:3]``), with the arithmetic of
        :meth:`Camera.project_camera_points`. Branch-free, so that it vectorises: every term
        is computed for every point (zero coefficients add exact zeros; a point not valid for
        the model is dropped by ``ok`` whatever its arithmetic gave)."""
        mei = int(cam[P_MODEL]) == MEI
        fx_, fy_, cx_, cy_, sk = cam[P_FX], cam[P_FY], cam[P_CX], cam[P_CY], cam[P_SKEW]
        xi = cam[P_XI]
        k1, k2, k3 = cam[P_K1], cam[P_K1 + 1], cam[P_K1 + 2]
        k4, k5, k6 = cam[P_K1 + 3], cam[P_K1 + 4], cam[P_K1 + 5]
        p1, p2 = cam[P_P1], cam[P_P2]
        s1, s2, s3, s4 = cam[P_S1], cam[P_S1 + 1], cam[P_S1 + 2], cam[P_S1 + 3]
        lim = cam[P_LIMIT]
        zs_min = cam[P_ZS_MIN]
        z_min2 = z_min * z_min
        for j in range(x.shape[0]):
            xc, yc, zc = _camera_point(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22,
                                       r23, x[j], y[j], z[j])
            n2 = xc * xc + yc * yc + zc * zc
            norm = np.sqrt(n2)
            ok = ((n2 > z_min2) & (zc > zs_min * norm)) if mei else zc > z_min
            den = zc + xi * norm if mei else zc
            iden = 1.0 / den
            xn = xc * iden
            yn = yc * iden
            r2 = xn * xn + yn * yn
            rad = ((1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
                   / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))))
            r4 = r2 * r2
            xy = xn * yn
            xd = xn * rad + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xn * xn) + s1 * r2 + s2 * r4
            yd = yn * rad + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xy + s3 * r2 + s4 * r4
            u = fx_ * xd + sk * yd + cx_
            v = fy_ * yd + cy_
            _footprint(u, v, ok & (r2 < lim), w, h, j, KB, FXB, FYB, OKB)

    @njit(cache=True, error_model="numpy")
    def fisheye_block(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, cam, x, y,
                       z, w, h, z_min, KB, FXB, FYB, OKB):  # pragma: no cover - compiled
        """:func:`pinhole_block` through an equidistant fisheye (arctan2 per point: scalar)."""
        fx_, fy_, cx_, cy_, sk = cam[P_FX], cam[P_FY], cam[P_CX], cam[P_CY], cam[P_SKEW]
        k1, k2, k3, k4 = cam[P_K1], cam[P_K1 + 1], cam[P_K1 + 2], cam[P_K1 + 3]
        lim = cam[P_LIMIT]
        z_min2 = z_min * z_min
        for j in range(x.shape[0]):
            xc, yc, zc = _camera_point(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22,
                                       r23, x[j], y[j], z[j])
            ok = False
            xd = 0.0
            yd = 0.0
            rho2 = xc * xc + yc * yc
            if rho2 + zc * zc > z_min2:
                rho = np.sqrt(rho2)
                theta = np.arctan2(rho, zc)
                if theta < lim:
                    t2 = theta * theta
                    td = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
                    sc = td / rho if rho > 0.0 else 0.0
                    xd = sc * xc
                    yd = sc * yc
                    ok = True
            u = fx_ * xd + sk * yd + cx_
            v = fy_ * yd + cy_
            _footprint(u, v, ok, w, h, j, KB, FXB, FYB, OKB)

    @njit(cache=True, error_model="numpy", inline="always")
    def project_block(row, r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, x, y, z,
                      w, h, z_min, KB, FXB, FYB, OKB):  # pragma: no cover - compiled
        """Project the points (x, y, z) (m,) by ``T[:3]`` (rows ``r**``) through the camera
        model of ``row`` (:meth:`Camera.kernel_params`) into the scratch: the ideal pinhole with
        K folded into the extrinsic (:func:`pinhole_block`), the equidistant fisheye
        (:func:`fisheye_block`), any other model (:func:`radial_block`)."""
        kind = int(row[P_MODEL])
        if kind == PINHOLE_IDEAL:
            fx_, fy_, cx_, cy_, sk = row[P_FX], row[P_FY], row[P_CX], row[P_CY], row[P_SKEW]
            # The first two rows of K @ T[:3].
            pinhole_block(fx_ * r00 + sk * r10 + cx_ * r20, fx_ * r01 + sk * r11 + cx_ * r21,
                          fx_ * r02 + sk * r12 + cx_ * r22, fx_ * r03 + sk * r13 + cx_ * r23,
                          fy_ * r10 + cy_ * r20, fy_ * r11 + cy_ * r21, fy_ * r12 + cy_ * r22,
                          fy_ * r13 + cy_ * r23, r20, r21, r22, r23, x, y, z, w, h, z_min, KB,
                          FXB, FYB, OKB)
        elif kind == FISHEYE:
            fisheye_block(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, row, x, y,
                          z, w, h, z_min, KB, FXB, FYB, OKB)
        else:
            radial_block(r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22, r23, row, x, y,
                         z, w, h, z_min, KB, FXB, FYB, OKB)

    @njit(cache=True, error_model="numpy")
    def _lookup_sum(dtq, base, w, KB, FXB, FYB, OKB, weight, out, masked, s1, s2,
                    inside):  # pragma: no cover - compiled
        """Add the block's bilinear DT values (DT units; ``out`` for points not ok or, when
        ``masked``, touching a masked pixel) times ``weight`` (m,) to ``s1``, their squares to
        ``s2``, in point order; count the points on usable pixels in ``inside``.

        Three passes, each at its own limit: the four reads of every point, packed into its
        index slot (scalar: this target has no fast gather; LLVM reads the two pixels of a
        row in one load); the bilinear values, branch-free (vectorised); the sums in point
        order. One loop doing all three ran at two thirds of the rate, bound by its scalar
        arithmetic.
        """
        m = weight.shape[0]
        # Unsigned indices: a signed one carries numba's negative-index wrap-around code.
        one = np.uint64(1)
        uw = np.uint64(w)
        uw1 = np.uint64(w + 1)
        for j in range(m):
            # Pixel 0 for a point that does not count: a harmless read.
            k = np.uint64(base + KB[j])
            KB[j] = (np.int64(dtq[k]) | (np.int64(dtq[k + one]) << 16)
                     | (np.int64(dtq[k + uw]) << 32) | (np.int64(dtq[k + uw1]) << 48))
        for j in range(m):
            p = KB[j]
            q00 = p & 0xFFFF
            q01 = (p >> 16) & 0xFFFF
            q10 = (p >> 32) & 0xFFFF
            q11 = (p >> 48) & 0xFFFF
            fx = FXB[j]
            fy = FYB[j]
            d00 = np.float64(q00)
            d10 = np.float64(q10)
            top = d00 + fx * (np.float64(q01) - d00)
            bot = d10 + fx * (np.float64(q11) - d10)
            d = top + fy * (bot - top)
            good = OKB[j]
            if masked:
                good = good & (max(max(q00, q01), max(q10, q11)) != DT_MASKED)
            inside += np.int64(good)
            FXB[j] = d if good else out
        for j in range(m):
            d = FXB[j]
            wd = weight[j] * d
            s1 += wd
            s2 += wd * d
        return s1, s2, inside

    @njit(parallel=True, cache=True, error_model="numpy")
    def _sums_numba(R, cam, n, x, y, z, weight, group_start, group_count, point_start, dtq,
                    dt_start, width, height, has_mask, outside_q, z_min, mount, mounted, S1, S2,
                    NIN, KS, FS, OS):  # pragma: no cover - compiled
        # Frame-outer loop: all candidates read one frame's DT while it is hot in cache. The DT
        # is stored as uint16 (0.00015 px steps at a 10 px truncation): half the bytes of
        # float32, so a 1242 x 375 frame fits a 1 MB L2 cache; bilinear lookups were 55 % of
        # the time with float32. Costs are accumulated in DT units and scaled by the caller.
        # Points are grouped (Scene.gx ...): each group's sums take one run of points, no
        # per-point branch on the group. The camera model is chosen once per block of points
        # (project_block): the ideal pinhole has K folded into the extrinsic (one division per
        # point, vectorised).
        C = R.shape[0]
        F = point_start.shape[0] - 1
        G = group_start.shape[1]
        for f in range(F):
            w = width[f]
            h = height[f]
            base = dt_start[f]
            out = outside_q[f]
            mf = point_start[f + 1] - point_start[f]
            masked = has_mask[f]
            row = cam[f]
            for c in prange(C):
                t = numba.get_thread_id()
                KB, FXB, FYB, OKB = KS[t], FS[t, 0], FS[t, 1], OS[t]
                r00, r01, r02, r03 = R[c, 0, 0], R[c, 0, 1], R[c, 0, 2], R[c, 0, 3]
                r10, r11, r12, r13 = R[c, 1, 0], R[c, 1, 1], R[c, 1, 2], R[c, 1, 3]
                r20, r21, r22, r23 = R[c, 2, 0], R[c, 2, 1], R[c, 2, 2], R[c, 2, 3]
                if mounted[f]:
                    # A camera of a rig calibrated at once: this frame sees mount @ T.
                    M = mount[f]
                    q00 = M[0, 0] * r00 + M[0, 1] * r10 + M[0, 2] * r20
                    q01 = M[0, 0] * r01 + M[0, 1] * r11 + M[0, 2] * r21
                    q02 = M[0, 0] * r02 + M[0, 1] * r12 + M[0, 2] * r22
                    q03 = M[0, 0] * r03 + M[0, 1] * r13 + M[0, 2] * r23 + M[0, 3]
                    q10 = M[1, 0] * r00 + M[1, 1] * r10 + M[1, 2] * r20
                    q11 = M[1, 0] * r01 + M[1, 1] * r11 + M[1, 2] * r21
                    q12 = M[1, 0] * r02 + M[1, 1] * r12 + M[1, 2] * r22
                    q13 = M[1, 0] * r03 + M[1, 1] * r13 + M[1, 2] * r23 + M[1, 3]
                    q20 = M[2, 0] * r00 + M[2, 1] * r10 + M[2, 2] * r20
                    q21 = M[2, 0] * r01 + M[2, 1] * r11 + M[2, 2] * r21
                    q22 = M[2, 0] * r02 + M[2, 1] * r12 + M[2, 2] * r22
                    q23 = M[2, 0] * r03 + M[2, 1] * r13 + M[2, 2] * r23 + M[2, 3]
                    r00, r01, r02, r03 = q00, q01, q02, q03
                    r10, r11, r12, r13 = q10, q11, q12, q13
                    r20, r21, r22, r23 = q20, q21, q22, q23
                m = min(n[c], mf)
                inside = 0
                for g in range(G):
                    a = group_start[f, g]
                    e = a + group_count[f, m, g]
                    s1 = 0.0
                    s2 = 0.0
                    for b in range(a, e, BLOCK):
                        bb = min(b + BLOCK, e)
                        project_block(row, r00, r01, r02, r03, r10, r11, r12, r13, r20, r21, r22,
                                      r23, x[b:bb], y[b:bb], z[b:bb], w, h, z_min, KB, FXB,
                                      FYB, OKB)
                        s1, s2, inside = _lookup_sum(dtq, base, w, KB, FXB, FYB, OKB,
                                                     weight[b:bb], out, masked, s1, s2, inside)
                    S1[c, f, g] = s1
                    S2[c, f, g] = s2
                NIN[c, f] = inside


def _empty_sums(C: int, F: int):
    """Zeroed outputs of the evaluators: S1, S2 (C, F, G) float64 and n_in (C, F) int64."""
    return np.zeros((C, F, N_GROUPS)), np.zeros((C, F, N_GROUPS)), np.zeros((C, F), np.int64)


def _rigid(T: np.ndarray) -> np.ndarray:
    """Candidate extrinsics (C, 4, 4) or (C, 3, 4) as their top rows, float64 (C, 3, 4)."""
    T = np.asarray(T, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] not in ((4, 4), (3, 4)):
        raise ValueError(f"candidate extrinsics must have shape (C, 4, 4) or (C, 3, 4), got "
                         f"{T.shape}")
    return np.ascontiguousarray(T[:, :3, :])


def sums_numba(scene: Scene, T: np.ndarray, n: np.ndarray):
    """Fused kernel.

    Parameters
    ----------
    scene : Scene
        The frames' feature points and distance transforms (:func:`build_scene`).
    T : ndarray, shape (C, 4, 4) or (C, 3, 4)
        Candidate extrinsics ``T_cam_lidar``.
    n : ndarray, shape (C,)
        Points per frame of each candidate.

    Returns
    -------
    S1, S2 : ndarray, shape (C, F, G), float64
        Sums of the per-point cost (px) and of its square, per feature group.
    n_in : ndarray, shape (C, F), int64
        Points that landed on usable pixels of the image.
    """
    if not HAVE_NUMBA:  # pragma: no cover
        raise RuntimeError("numba is not available; use the numpy evaluator")
    R = _rigid(T)
    n = np.ascontiguousarray(n, dtype=np.int64)
    C, F = len(R), scene.n_frames
    S1, S2, NIN = _empty_sums(C, F)
    q = scene.dt_scale
    threads = numba.get_num_threads()
    if C < SERIAL_BELOW:
        # The kernel opens one parallel region per frame; for a handful of candidates (a local
        # search evaluating one pose at a time) their start-up and barriers cost more than the
        # work: one candidate on 5 frames took 1 ms on one thread, 8-20 ms on two.
        numba.set_num_threads(1)
    perm = balanced_order(n, numba.get_num_threads())
    if perm is not None:
        R, n = R[perm], n[perm]
    # Per-thread scratch for a block's footprints (indexed by numba's thread id).
    T_ = max_threads()
    try:
        _sums_numba(R, scene.cam_params, n, scene.gx, scene.gy, scene.gz, scene.gweight,
                    scene.group_start, scene.group_count, scene.point_start, scene.dtq,
                    scene.dt_start, scene.width, scene.height, scene.has_mask,
                    scene.outside.astype(np.float64) / q, np.float64(scene.z_min), scene.mount,
                    scene.mounted, S1, S2, NIN, *block_scratch(T_))
    finally:
        numba.set_num_threads(threads)
    if perm is not None:
        # Each candidate's sums do not depend on the order: put them back in the caller's.
        S1[perm], S2[perm], NIN[perm] = S1.copy(), S2.copy(), NIN.copy()
    S1 *= q
    S2 *= q * q
    return S1, S2, NIN


def max_threads() -> int:
    """Numba's thread pool size: every thread id a parallel loop can run on is below it, so
    per-thread scratch has this many rows (the threads in use may be fewer)."""
    return int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]  # set at import


def block_scratch(threads: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-thread scratch of the fused kernel: footprints (threads, BLOCK + 8) int64, fractions
    (threads, 2, BLOCK + 8) float64, flags (threads, BLOCK + 64) bool, of which a block uses
    the first BLOCK. The unused tail of each row (64 bytes) keeps two threads' data out of
    one cache line (shared, a line moved between the cores on every block). C-contiguous, so
    that each row is a contiguous array to numba and its loops vectorise."""
    return (np.empty((threads, BLOCK + 8), np.int64), np.empty((threads, 2, BLOCK + 8)),
            np.empty((threads, BLOCK + 64), np.bool_))


def balanced_order(n: np.ndarray, threads: int) -> np.ndarray | None:
    """An order of the candidates (C,) in which the contiguous blocks a static parallel loop
    gives each of ``threads`` threads carry about the same number of points.

    A polish evaluates each solution's stencil together, solutions sorted by ``n``: in the
    caller's order one thread got the small ``n`` and the other the large (129 M points/s on
    two cores for 400 candidates of sorted ``n`` on 20 KITTI frames, 186 M dealt out like
    this). Sorting by ``n`` and dealing every ``threads``-th candidate to one block balances
    them; the sums are the same in any order. None when the caller's order is as good (one
    thread, fewer than two candidates per thread, or every candidate at the same ``n``).
    """
    if threads <= 1 or len(n) < 2 * threads or n.min() == n.max():
        return None
    order = np.argsort(n, kind="stable")
    return np.concatenate([order[t::threads] for t in range(threads)])


def _frame_points(scene: Scene, f: int) -> np.ndarray:
    """Frame f's points as float64 (M_f, 3), the values the kernel reads."""
    a, b = scene.point_start[f], scene.point_start[f + 1]
    return np.column_stack([scene.x[a:b], scene.y[a:b], scene.z[a:b]]).astype(np.float64)


def bilinear_usable(usable: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Whether the four pixels a bilinear lookup at in-image ``uv`` (..., 2) reads are all
    usable (``usable`` (H, W) bool), as the evaluators read them; shape (...)."""
    h, w = usable.shape
    x0 = np.minimum(uv[..., 0].astype(np.int64), w - 2)
    y0 = np.minimum(uv[..., 1].astype(np.int64), h - 2)
    return (usable[y0, x0] & usable[y0, x0 + 1] & usable[y0 + 1, x0]
            & usable[y0 + 1, x0 + 1])


def sums_numpy(scene: Scene, T: np.ndarray, n: np.ndarray, chunk_points: int = 4_000_000):
    """The same sums as :func:`sums_numba`, batched with numpy over candidates.

    Parameters
    ----------
    scene : Scene
        The frames' feature points and distance transforms.
    T : ndarray, shape (C, 4, 4) or (C, 3, 4)
        Candidate extrinsics ``T_cam_lidar``.
    n : ndarray, shape (C,)
        Points per frame of each candidate.
    chunk_points : int
        Largest number of projected points held at once (memory bound).

    Returns
    -------
    S1, S2 : ndarray, shape (C, F, G), float64
        Sums of the per-point cost (px) and of its square, per feature group.
    n_in : ndarray, shape (C, F), int64
        Points that landed on usable pixels of the image.
    """
    R = _rigid(T)
    n = np.asarray(n, dtype=np.int64)
    C, F = len(R), scene.n_frames
    S1, S2, NIN = _empty_sums(C, F)
    for f in range(F):
        a, b = scene.point_start[f], scene.point_start[f + 1]
        m_all = b - a
        if m_all == 0:
            continue
        Pt = _frame_points(scene, f).T.copy()                    # (3, m)
        cam = scene.cameras[f]
        Rf = R if cam.mount is None else cam.mounted(R)
        grp = scene.group[a:b]
        wt = scene.weight[a:b].astype(np.float64)
        dtf = scene.frame_dt(f)                                   # NaN on masked pixels
        w, h = int(scene.width[f]), int(scene.height[f])
        step = max(1, chunk_points // m_all)
        for c0 in range(0, C, step):
            Rc = Rf[c0:c0 + step]                                 # (c, 3, 4)
            X, Y, Z = (Rc[:, k, :3] @ Pt + Rc[:, k, 3:] for k in range(3))   # (c, m) each
            u, v, valid = cam.project_xyz(X, Y, Z, scene.z_min)
            used = np.arange(m_all)[None, :] < n[c0:c0 + step, None]
            with np.errstate(invalid="ignore"):
                ok = valid & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
            us, vs = np.where(ok, u, 0.0), np.where(ok, v, 0.0)
            x0 = np.minimum(us.astype(np.int64), w - 2)
            y0 = np.minimum(vs.astype(np.int64), h - 2)
            fx, fy = us - x0, vs - y0
            top = dtf[y0, x0] + fx * (dtf[y0, x0 + 1] - dtf[y0, x0])
            bot = dtf[y0 + 1, x0] + fx * (dtf[y0 + 1, x0 + 1] - dtf[y0 + 1, x0])
            d = top + fy * (bot - top)
            ok &= np.isfinite(d)                                  # a masked pixel was read
            d = np.where(ok, d, scene.outside[f])
            d = np.where(used, d, 0.0)
            for g in range(N_GROUPS):
                sel = grp == g
                S1[c0:c0 + step, f, g] = (d[:, sel] * wt[sel]).sum(axis=1)
                S2[c0:c0 + step, f, g] = (d[:, sel] ** 2 * wt[sel]).sum(axis=1)
            NIN[c0:c0 + step, f] = (ok & used).sum(axis=1)
    return S1, S2, NIN


def sums_kdtree(scene: Scene, edge_uv: list[np.ndarray], T: np.ndarray, n: np.ndarray):
    """Exact oracle: distances from a KD-tree over the edge pixels, candidate by candidate.

    The cost per point is ``min(distance, truncation)`` where the DT-based evaluators
    interpolate the same function; the projection and the masked-pixel rule are theirs.

    Parameters
    ----------
    scene : Scene
        The frames' feature points and distance transforms.
    edge_uv : list of ndarray, shape (E, 2)
        Per frame, the pixel coordinates of its image edges.
    T : ndarray, shape (C, 4, 4)
        Candidate extrinsics ``T_cam_lidar``.
    n : ndarray, shape (C,)
        Points per frame of each candidate.

    Returns
    -------
    S1, S2 : ndarray, shape (C, F, G), float64
        Sums of the per-point cost (px) and of its square, per feature group.
    n_in : ndarray, shape (C, F), int64
        Points that landed on usable pixels of the image.
    """
    from scipy.spatial import cKDTree

    R = _rigid(T)
    C, F = len(R), scene.n_frames
    S1, S2, NIN = _empty_sums(C, F)
    for f in range(F):
        tree = cKDTree(edge_uv[f]) if len(edge_uv[f]) else None
        a, b = scene.point_start[f], scene.point_start[f + 1]
        P = _frame_points(scene, f)
        cam = scene.cameras[f]
        usable = scene.frame_usable(f)
        w, h = int(scene.width[f]), int(scene.height[f])
        for c in range(C):
            m = min(int(n[c]), b - a)
            uv, _, _ = project(P[:m], cam, R[c], scene.z_min)
            valid = np.isfinite(uv[:, 0])
            with np.errstate(invalid="ignore"):
                ok = (valid & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1)
                      & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1))
            ok[ok] = bilinear_usable(usable, uv[ok])
            d = np.full(m, scene.outside[f], dtype=np.float64)
            if ok.any():
                dist = tree.query(uv[ok])[0] if tree is not None else np.inf
                d[ok] = np.minimum(dist, scene.truncation_px)
            g = scene.group[a:a + m]
            wt = scene.weight[a:a + m].astype(np.float64)
            S1[c, f] = np.bincount(g, weights=wt * d, minlength=N_GROUPS)
            S2[c, f] = np.bincount(g, weights=wt * d * d, minlength=N_GROUPS)
            NIN[c, f] = ok.sum()
    return S1, S2, NIN


def get_evaluator(name: str = "auto"):
    """The sums function for ``"numba"``, ``"numpy"`` or ``"auto"`` (numba when available).

    Parameters
    ----------
    name : {"auto", "numba", "numpy"}
        The evaluator (``--evaluator``).

    Returns
    -------
    callable
        :func:`sums_numba` or :func:`sums_numpy`.
    """
    if name == "numpy" or (name == "auto" and not HAVE_NUMBA):
        return sums_numpy
    if name in ("numba", "auto"):
        if not HAVE_NUMBA:  # pragma: no cover
            raise RuntimeError("numba is not available; use --evaluator numpy")
        return sums_numba
    raise ValueError(f"unknown evaluator {name!r}")


@contextmanager
def one_thread():
    """Evaluations in the block run on the calling thread alone (numba's thread count is a
    per-thread setting, restored on leaving)."""
    if not HAVE_NUMBA:  # pragma: no cover
        yield
        return
    k = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(k)


def set_threads(k: int | None) -> None:
    """Limit the numba thread count (None leaves it at numba's default)."""
    if HAVE_NUMBA and k is not None:
        numba.set_num_threads(max(1, min(int(k), max_threads())))
