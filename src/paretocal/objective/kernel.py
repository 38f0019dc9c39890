"""Per-point sums of the truncated distance-transform cost, for a whole population at once.

For every candidate c and frame f, the first ``n[c]`` points of frame f are projected with
``A[c, f] = K_f @ T_c[:3]``; a point in front of the camera and inside the image costs the
bilinear DT value at its pixel, any other point costs ``outside[f]``. The evaluators return the
per-group weighted sums of the cost and of its square, shape (C, F, G), from which the objective takes
means and sampling errors.

Two implementations give the same sums: a fused numba kernel (parallel over candidates, one pass
over the points, no temporaries) and a numpy fallback batched over candidates.
"""

from __future__ import annotations

import numpy as np

from .scene import N_GROUPS, Scene

try:  # numba is a hard dependency, but keep the numpy path usable if it fails to import
    import numba
    from numba import njit, prange

    HAVE_NUMBA = True
except Exception:  # pragma: no cover - exercised only where numba is broken
    HAVE_NUMBA = False

SERIAL_BELOW = 4  # batches of fewer candidates run on one thread (see sums_numba)


if HAVE_NUMBA:

    @njit(parallel=True, cache=True, fastmath=False)
    def _sums_numba(A, n, x, y, z, weight, group, point_start, dtq, dt_start, width, height,
                    outside_q, z_min, S1, S2, NIN):  # pragma: no cover - compiled
        # Frame-outer loop: all candidates read one frame's DT while it is hot in cache. The DT
        # is stored as uint16 (0.00015 px steps at a 10 px truncation): half the bytes of
        # float32, so a 1242 x 375 frame fits a 1 MB L2 cache; bilinear lookups were 55 % of
        # the time with float32. Costs are accumulated in DT units and scaled by the caller.
        C = A.shape[0]
        F = point_start.shape[0] - 1
        for f in range(F):
            w = width[f]
            h = height[f]
            umax = w - 1.0
            vmax = h - 1.0
            base = dt_start[f]
            out = outside_q[f]
            p0 = point_start[f]
            mf = point_start[f + 1] - p0
            for c in prange(C):
                a00, a01, a02, a03 = A[c, f, 0, 0], A[c, f, 0, 1], A[c, f, 0, 2], A[c, f, 0, 3]
                a10, a11, a12, a13 = A[c, f, 1, 0], A[c, f, 1, 1], A[c, f, 1, 2], A[c, f, 1, 3]
                a20, a21, a22, a23 = A[c, f, 2, 0], A[c, f, 2, 1], A[c, f, 2, 2], A[c, f, 2, 3]
                s10 = 0.0
                s11 = 0.0
                s12 = 0.0
                s20 = 0.0
                s21 = 0.0
                s22 = 0.0
                inside = 0
                for i in range(p0, p0 + min(n[c], mf)):
                    X = x[i]
                    Y = y[i]
                    Z = z[i]
                    zc = a20 * X + a21 * Y + a22 * Z + a23
                    d = out
                    if zc > z_min:
                        iz = 1.0 / zc
                        u = (a00 * X + a01 * Y + a02 * Z + a03) * iz
                        v = (a10 * X + a11 * Y + a12 * Z + a13) * iz
                        if u >= 0.0 and u <= umax and v >= 0.0 and v <= vmax:
                            x0 = min(int(u), w - 2)
                            y0 = min(int(v), h - 2)
                            fx = u - x0
                            fy = v - y0
                            k = base + y0 * w + x0
                            d00 = np.float64(dtq[k])
                            d01 = np.float64(dtq[k + 1])
                            d10 = np.float64(dtq[k + w])
                            d11 = np.float64(dtq[k + w + 1])
                            top = d00 + fx * (d01 - d00)
                            bot = d10 + fx * (d11 - d10)
                            d = top + fy * (bot - top)
                            inside += 1
                    wd = weight[i] * d
                    g = group[i]
                    if g == 0:
                        s10 += wd
                        s20 += wd * d
                    elif g == 1:
                        s11 += wd
                        s21 += wd * d
                    else:
                        s12 += wd
                        s22 += wd * d
                S1[c, f, 0] = s10
                S1[c, f, 1] = s11
                S1[c, f, 2] = s12
                S2[c, f, 0] = s20
                S2[c, f, 1] = s21
                S2[c, f, 2] = s22
                NIN[c, f] = inside


def _empty_sums(C: int, F: int):
    """Zeroed outputs of the evaluators: S1, S2 (C, F, G) float64 and n_in (C, F) int64."""
    return np.zeros((C, F, N_GROUPS)), np.zeros((C, F, N_GROUPS)), np.zeros((C, F), np.int64)


def sums_numba(scene: Scene, A: np.ndarray, n: np.ndarray):
    """Fused kernel. ``A``: (C, F, 3, 4) projections; ``n``: (C,) points per frame.

    Returns
    -------
    S1, S2 : ndarray, shape (C, F, G), float64
        Sums of the per-point cost (px) and of its square, per feature group.
    n_in : ndarray, shape (C, F), int64
        Points that landed in the image.
    """
    if not HAVE_NUMBA:  # pragma: no cover
        raise RuntimeError("numba is not available; use the numpy evaluator")
    C, F = A.shape[:2]
    S1, S2, NIN = _empty_sums(C, F)
    q = scene.dt_scale
    threads = numba.get_num_threads()
    if C < SERIAL_BELOW:
        # The kernel opens one parallel region per frame; for a handful of candidates (a local
        # search evaluating one pose at a time) their start-up and barriers cost more than the
        # work: one candidate on 5 frames took 1 ms on one thread, 8-20 ms on two.
        numba.set_num_threads(1)
    try:
        _sums_numba(np.ascontiguousarray(A, dtype=np.float64),
                    np.ascontiguousarray(n, dtype=np.int64), scene.x, scene.y, scene.z,
                    scene.weight, scene.group, scene.point_start, scene.dtq, scene.dt_start,
                    scene.width, scene.height, scene.outside.astype(np.float64) / q,
                    np.float64(scene.z_min), S1, S2, NIN)
    finally:
        numba.set_num_threads(threads)
    S1 *= q
    S2 *= q * q
    return S1, S2, NIN


def sums_numpy(scene: Scene, A: np.ndarray, n: np.ndarray, chunk_points: int = 4_000_000):
    """The same sums as :func:`sums_numba`, batched with numpy over candidates."""
    A = np.asarray(A, dtype=np.float64)
    n = np.asarray(n, dtype=np.int64)
    C, F = A.shape[:2]
    S1, S2, NIN = _empty_sums(C, F)
    for f in range(F):
        a, b = scene.point_start[f], scene.point_start[f + 1]
        m_all = b - a
        if m_all == 0:
            continue
        P = np.column_stack([scene.x[a:b], scene.y[a:b], scene.z[a:b],
                             np.ones(m_all, np.float32)]).astype(np.float64)
        grp = scene.group[a:b]
        wt = scene.weight[a:b].astype(np.float64)
        dtf = scene.frame_dt(f)
        w, h = int(scene.width[f]), int(scene.height[f])
        step = max(1, chunk_points // m_all)
        for c0 in range(0, C, step):
            Ac = A[c0:c0 + step, f]                                  # (c, 3, 4)
            H = np.einsum("cij,mj->cmi", Ac, P)                      # (c, m, 3)
            zc = H[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = H[..., 0] / zc
                v = H[..., 1] / zc
            used = np.arange(m_all)[None, :] < n[c0:c0 + step, None]
            ok = (zc > scene.z_min) & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
            us, vs = np.where(ok, u, 0.0), np.where(ok, v, 0.0)
            x0 = np.minimum(us.astype(np.int64), w - 2)
            y0 = np.minimum(vs.astype(np.int64), h - 2)
            fx, fy = us - x0, vs - y0
            top = dtf[y0, x0] + fx * (dtf[y0, x0 + 1] - dtf[y0, x0])
            bot = dtf[y0 + 1, x0] + fx * (dtf[y0 + 1, x0 + 1] - dtf[y0 + 1, x0])
            d = np.where(ok, top + fy * (bot - top), scene.outside[f])
            d = np.where(used, d, 0.0)
            for g in range(N_GROUPS):
                sel = grp == g
                S1[c0:c0 + step, f, g] = (d[:, sel] * wt[sel]).sum(axis=1)
                S2[c0:c0 + step, f, g] = (d[:, sel] ** 2 * wt[sel]).sum(axis=1)
            NIN[c0:c0 + step, f] = (ok & used).sum(axis=1)
    return S1, S2, NIN


def sums_kdtree(scene: Scene, edge_uv: list[np.ndarray], A: np.ndarray, n: np.ndarray):
    """Exact oracle: distances from a KD-tree over the edge pixels, candidate by candidate.

    ``edge_uv[f]`` is frame f's (E, 2) edge pixel list. The cost per point is
    ``min(distance, truncation)`` where the DT-based evaluators interpolate the same function.
    """
    from scipy.spatial import cKDTree

    A = np.asarray(A, dtype=np.float64)
    C, F = A.shape[:2]
    S1, S2, NIN = _empty_sums(C, F)
    for f in range(F):
        tree = cKDTree(edge_uv[f])
        a, b = scene.point_start[f], scene.point_start[f + 1]
        P = np.column_stack([scene.x[a:b], scene.y[a:b], scene.z[a:b]]).astype(np.float64)
        w, h = int(scene.width[f]), int(scene.height[f])
        for c in range(C):
            m = min(int(n[c]), b - a)
            H = P[:m] @ A[c, f, :, :3].T + A[c, f, :, 3]
            zc = H[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = H[:, :2] / zc[:, None]
            ok = ((zc > scene.z_min) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1)
                  & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1))
            d = np.full(m, scene.outside[f], dtype=np.float64)
            if ok.any():
                dist, _ = tree.query(uv[ok])
                d[ok] = np.minimum(dist, scene.truncation_px)
            g = scene.group[a:a + m]
            wt = scene.weight[a:a + m].astype(np.float64)
            S1[c, f] = np.bincount(g, weights=wt * d, minlength=N_GROUPS)
            S2[c, f] = np.bincount(g, weights=wt * d * d, minlength=N_GROUPS)
            NIN[c, f] = ok.sum()
    return S1, S2, NIN


def get_evaluator(name: str = "auto"):
    """The sums function for ``"numba"``, ``"numpy"`` or ``"auto"`` (numba when available)."""
    if name == "numpy" or (name == "auto" and not HAVE_NUMBA):
        return sums_numpy
    if name in ("numba", "auto"):
        if not HAVE_NUMBA:  # pragma: no cover
            raise RuntimeError("numba is not available; use --evaluator numpy")
        return sums_numba
    raise ValueError(f"unknown evaluator {name!r}")


def set_threads(k: int | None) -> None:
    """Limit the numba thread count (None leaves it at numba's default)."""
    if HAVE_NUMBA and k is not None:
        numba.set_num_threads(max(1, min(int(k), numba.config.NUMBA_NUM_THREADS)))
