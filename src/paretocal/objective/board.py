"""The board's terms of the first objective, for a whole population of extrinsics at once.

Each frame where the image and the sweep both show the board gives two groups of residuals:

* **plane**: each LiDAR return on the board, taken into the camera frame, from the board's
  plane as its corners place it (m);
* **outline**: each return where a scan line enters or leaves the board, from the board's
  outline (the rectangle of its size about its corners' centre), measured in the board's
  plane (m).

Each residual ``r`` is divided by its group's noise scale ``sigma`` (:class:`BoardScene`'s
``sigma_plane_m`` and ``sigma_outline_m``, measured from the data) and costs

    truncation * rho(r / sigma) / rho(K),    rho(u) = sqrt(1 + u^2) - 1,  K = NOISE_BAND,

pixels, like an edge point's distance-transform value: ``rho`` is quadratic within the noise
and grows linearly beyond (a return off the board by many sigmas, an end hidden by a hand,
weighs like an edge point far from every edge, not quadratically more), and a residual of K
sigmas, the band beyond which it is no longer noise, costs what an edge point missing by the
whole truncation of the distance transform costs. A frame's board term is the mean over its
plane returns plus the mean over its outline returns, two groups beside the edges' depth and
intensity edges. The same cost, summed, is what the board's least squares minimise
(:func:`least_squares_loss`), so the board's own optimum and the objective's agree.

:func:`board_sums` evaluates a population in a numba kernel (parallel over candidates, a few
operations per return), :func:`board_sums_numpy` is its oracle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .objective import CalibrationObjective

try:  # numba is a hard dependency; the numpy oracle stays usable without it
    from numba import njit, prange

    HAVE_NUMBA = True
except Exception:  # pragma: no cover - exercised only where numba is broken
    HAVE_NUMBA = False

#: Residuals beyond this many noise sigmas are no longer noise: a board return this far off
#: costs what an edge point missing by the whole truncation of the distance transform costs.
NOISE_BAND = 3.0


def rho(u):
    """The robust cost of a residual of ``u`` noise sigmas: ``sqrt(1 + u^2) - 1``."""
    return np.sqrt(1.0 + np.square(u)) - 1.0


@dataclass(frozen=True, eq=False)
class BoardScene:
    """The board frames' observations as flat arrays.

    Attributes
    ----------
    frames : ndarray, shape (J,), int64
        Each board frame's index among the objective's frames.
    names : tuple of str, shape (J,)
        Their names.
    normal : ndarray, shape (J, 3)
        The board plane's unit normal in the camera frame (towards the camera).
    distance : ndarray, shape (J,)
        The camera's distance from the plane (m): ``normal . x + distance = 0`` on it.
    T_cam_board : ndarray, shape (J, 4, 4)
        The board's pose in the camera frame (its outline's frame; m).
    half_size : ndarray, shape (2,)
        Half the board's width and height (m).
    points : ndarray, shape (P, 3)
        The LiDAR returns on the boards, frame after frame (m, LiDAR frame).
    point_start : ndarray, shape (J + 1,), int64
        Frame j's returns are ``points[point_start[j]:point_start[j + 1]]``.
    ends : ndarray, shape (E, 3)
        The returns where scan lines enter and leave the boards (m, LiDAR frame).
    end_start : ndarray, shape (J + 1,), int64
    sigma_plane_m, sigma_outline_m : float
        The noise scales (m) of the plane and outline residuals.
    truncation_px : float
        The edges' distance-transform truncation (px): the board's cost scale.
    """

    frames: np.ndarray
    names: tuple
    normal: np.ndarray
    distance: np.ndarray
    T_cam_board: np.ndarray
    half_size: np.ndarray
    points: np.ndarray
    point_start: np.ndarray
    ends: np.ndarray
    end_start: np.ndarray
    sigma_plane_m: float
    sigma_outline_m: float
    truncation_px: float

    @property
    def n_boards(self) -> int:
        return len(self.frames)

    def select(self, boards) -> "BoardScene":
        """The scene of some of its boards (indices into its boards), in that order."""
        import dataclasses

        boards = np.asarray(boards, dtype=np.int64)

        def take(values, start):
            parts = [values[start[j]:start[j + 1]] for j in boards]
            sizes = [len(p) for p in parts]
            stacked = np.vstack(parts) if parts else values[:0]
            return stacked, np.r_[0, np.cumsum(sizes)].astype(np.int64)

        points, point_start = take(self.points, self.point_start)
        ends, end_start = take(self.ends, self.end_start)
        return dataclasses.replace(
            self, frames=self.frames[boards], names=tuple(self.names[j] for j in boards),
            normal=self.normal[boards], distance=self.distance[boards],
            T_cam_board=self.T_cam_board[boards], points=points, point_start=point_start,
            ends=ends, end_start=end_start)

    @property
    def scale_px(self) -> float:
        """The cost of one noise-normalised unit of ``rho`` (px): ``truncation / rho(K)``."""
        return float(self.truncation_px / rho(NOISE_BAND))


def plane_residuals(scene: BoardScene, T: np.ndarray) -> np.ndarray:
    """Each board return's distance from its frame's camera board plane (m), shape (C, P),
    for extrinsics ``T`` (C, 4, 4)."""
    j = np.repeat(np.arange(scene.n_boards), np.diff(scene.point_start))
    q = np.einsum("cik,pk->cpi", T[:, :3, :3], scene.points) + T[:, None, :3, 3]
    return np.einsum("cpi,pi->cp", q, scene.normal[j]) + scene.distance[j]


def outline_residuals(scene: BoardScene, T: np.ndarray) -> np.ndarray:
    """Each end return's distance from its board's outline in the board's plane (m), shape
    (C, E): the distance to the rectangle's nearest side, positive outside, negative inside."""
    j = np.repeat(np.arange(scene.n_boards), np.diff(scene.end_start))
    q = np.einsum("cik,ek->cei", T[:, :3, :3], scene.ends) + T[:, None, :3, 3]   # (C, E, 3)
    B = scene.T_cam_board[j]                                                     # (E, 4, 4)
    local = np.einsum("cei,eik->cek", q - B[None, :, :3, 3], B[:, :3, :3])       # board frame
    over = np.abs(local[..., :2]) - scene.half_size                               # (C, E, 2)
    outside = np.linalg.norm(np.maximum(over, 0.0), axis=-1)
    inside = np.minimum(np.max(over, axis=-1), 0.0)
    return outside + inside


def _group_means(v: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Means of ``v`` (C, P) over each frame's slice ``start[j]:start[j + 1]``, (C, J); 0 for
    an empty slice."""
    counts = np.diff(start)
    out = np.zeros((v.shape[0], len(counts)))
    for j, (a, b) in enumerate(zip(start[:-1], start[1:])):
        if b > a:
            out[:, j] = v[:, a:b].mean(axis=1)
    return out


def board_sums_numpy(scene: BoardScene, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's mean ``rho`` of its plane residuals and of its outline residuals, each
    (C, J), for extrinsics ``T`` (C, 4, 4) (the oracle of :func:`board_sums`)."""
    T = np.asarray(T, dtype=np.float64)
    p = rho(plane_residuals(scene, T) / scene.sigma_plane_m)
    o = rho(outline_residuals(scene, T) / scene.sigma_outline_m)
    return _group_means(p, scene.point_start), _group_means(o, scene.end_start)


if HAVE_NUMBA:
    @njit(parallel=True, cache=True, error_model="numpy")
    def _board_kernel(T, pts, pstart, normal, dist, ends, estart, Tb, half, sigma
                      ):  # pragma: no cover - compiled
        C, J = T.shape[0], normal.shape[0]
        sp, so = sigma[0], sigma[1]
        out_p = np.zeros((C, J))
        out_o = np.zeros((C, J))
        for c in prange(C):
            R = T[c, :3, :3]
            t = T[c, :3, 3]
            for j in range(J):
                # r = (R^T n) . p + n . t + d
                n0, n1, n2 = normal[j, 0], normal[j, 1], normal[j, 2]
                a0 = R[0, 0] * n0 + R[1, 0] * n1 + R[2, 0] * n2
                a1 = R[0, 1] * n0 + R[1, 1] * n1 + R[2, 1] * n2
                a2 = R[0, 2] * n0 + R[1, 2] * n1 + R[2, 2] * n2
                b = n0 * t[0] + n1 * t[1] + n2 * t[2] + dist[j]
                s = 0.0
                for i in range(pstart[j], pstart[j + 1]):
                    u = (a0 * pts[i, 0] + a1 * pts[i, 1] + a2 * pts[i, 2] + b) / sp
                    s += np.sqrt(1.0 + u * u) - 1.0
                k = pstart[j + 1] - pstart[j]
                out_p[c, j] = s / k if k > 0 else 0.0
                s = 0.0
                for i in range(estart[j], estart[j + 1]):
                    q0 = R[0, 0] * ends[i, 0] + R[0, 1] * ends[i, 1] + R[0, 2] * ends[i, 2] \
                        + t[0] - Tb[j, 0, 3]
                    q1 = R[1, 0] * ends[i, 0] + R[1, 1] * ends[i, 1] + R[1, 2] * ends[i, 2] \
                        + t[1] - Tb[j, 1, 3]
                    q2 = R[2, 0] * ends[i, 0] + R[2, 1] * ends[i, 1] + R[2, 2] * ends[i, 2] \
                        + t[2] - Tb[j, 2, 3]
                    x = abs(Tb[j, 0, 0] * q0 + Tb[j, 1, 0] * q1 + Tb[j, 2, 0] * q2) - half[0]
                    y = abs(Tb[j, 0, 1] * q0 + Tb[j, 1, 1] * q1 + Tb[j, 2, 1] * q2) - half[1]
                    ox, oy = max(x, 0.0), max(y, 0.0)
                    d = np.sqrt(ox * ox + oy * oy) + min(max(x, y), 0.0)
                    u = d / so
                    s += np.sqrt(1.0 + u * u) - 1.0
                k = estart[j + 1] - estart[j]
                out_o[c, j] = s / k if k > 0 else 0.0
        return out_p, out_o


def board_sums(scene: BoardScene, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`board_sums_numpy` by the numba kernel (parallel over the candidates)."""
    T = np.ascontiguousarray(np.asarray(T, dtype=np.float64)[:, :3, :4])
    if not HAVE_NUMBA:  # pragma: no cover
        return board_sums_numpy(scene, T)
    return _board_kernel(T, scene.points, scene.point_start, scene.normal, scene.distance,
                         scene.ends, scene.end_start, scene.T_cam_board,
                         np.asarray(scene.half_size, dtype=np.float64),
                         np.array([scene.sigma_plane_m, scene.sigma_outline_m], dtype=np.float64))


def board_terms(scene: BoardScene, T: np.ndarray, numpy: bool = False) -> dict[str, np.ndarray]:
    """The board's per-frame cost (px) and its parts for extrinsics ``T`` (C, 4, 4).

    Returns
    -------
    dict
        ``cost`` (C, J): ``truncation / rho(K)`` times the frame's mean ``rho`` of its plane
        residuals plus that of its outline residuals (px); ``plane`` and ``outline`` (C, J),
        those means.
    """
    p, o = (board_sums_numpy if numpy else board_sums)(scene, T)
    return {"cost": scene.scale_px * (p + o), "plane": p, "outline": o}


def residuals(scene: BoardScene, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every plane and outline residual at one extrinsic ``T`` (4, 4) in noise sigmas, shape
    (P + E,), and each one's weight, ``1 / (its frame's count of its group)``: the weighted sum
    of their ``rho`` is :func:`board_terms`' cost summed over the frames, over ``scale_px``."""
    T = np.asarray(T, dtype=np.float64)[None]
    u = np.concatenate([plane_residuals(scene, T)[0] / scene.sigma_plane_m,
                        outline_residuals(scene, T)[0] / scene.sigma_outline_m])
    w = np.concatenate([np.repeat(1.0 / np.maximum(np.diff(scene.point_start), 1),
                                  np.diff(scene.point_start)),
                        np.repeat(1.0 / np.maximum(np.diff(scene.end_start), 1),
                                  np.diff(scene.end_start))])
    return u, w


def least_squares_loss(weights: np.ndarray):
    """scipy's ``least_squares`` loss for residuals in noise sigmas: ``2 w rho(sqrt(z))``
    and its first two derivatives in ``z = u^2``, (3, m) (scipy's convention halves it)."""
    def loss(z):
        s = np.sqrt(1.0 + z)
        return np.stack([2.0 * weights * (s - 1.0), weights / s, -0.5 * weights / s ** 3])
    return loss


class BoardObjective(CalibrationObjective):
    """The edge objective with the board's terms added to the frames that show the board: what
    the search, the polish, the quality report and the verdict call on a board recording.

    Each board frame's term (px) is the edges' term plus :func:`board_terms`' cost; ``f1`` is
    the mean over all frames (frames without the board count their edges alone) plus the
    edges' sampling-error charge. ``n`` selects the edge points only: the board's terms cost
    the same at every ``n`` (a few operations per frame), so the cost objective is the edges'.
    Every other attribute is the edge objective's.

    Parameters
    ----------
    edges : CalibrationObjective
        The edge objective over every frame (kept as :attr:`edges`, the edges alone).
    board : BoardScene
        The board frames' observations (``frames`` index ``edges.scene``'s frames).
    """

    def __init__(self, edges: CalibrationObjective, board: BoardScene):
        # The edge objective's scene, settings, cost model and evaluator, shared.
        self.__dict__.update(vars(edges))
        self.evaluations = 0
        self.edges = edges
        self.board = board

    def board_cost(self, X: np.ndarray) -> np.ndarray:
        """The board's per-frame cost (px), shape (C, J), for candidates X (C, 7)."""
        T = self.transforms(np.atleast_2d(np.asarray(X, dtype=np.float64)))
        return board_terms(self.board, T)["cost"]

    def chamfer(self, X: np.ndarray, ucb_k: float | None = None) -> dict[str, np.ndarray]:
        """The edge objective's parts (:meth:`CalibrationObjective.chamfer`) with the board's
        cost added to ``f1`` and to its frames' ``per_frame``; ``board`` (C,) is the board's
        share of ``f1`` (px).

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        ucb_k : float, optional
            The edges' sampling-error multiplier for this call.
        """
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        out = dict(super().chamfer(X, ucb_k))
        cost = self.board_cost(X)
        per_frame = np.array(out["per_frame"], dtype=np.float64, copy=True)
        per_frame[:, self.board.frames] += cost
        share = cost.sum(axis=1) / per_frame.shape[1]
        out.update(per_frame=per_frame, f1=out["f1"] + share, board=share)
        return out
