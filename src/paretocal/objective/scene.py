"""The frames' features laid out as flat arrays for the evaluators.

Points are stored per coordinate as contiguous float32 arrays (frame after frame, each in its
evaluation order), distance transforms as one flat uint16 buffer; per-frame offsets index both.
Each frame's camera is kept whole (for the numpy evaluators) and as one row of parameters (for
the numba kernel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import N_PARAMS
from ..features.lidar import GROUP_NAMES
from ..features.prepare import FrameFeatures

N_GROUPS = len(GROUP_NAMES)
#: Quantised DT value of a masked pixel; real distances use 0 .. DT_MASKED - 1.
DT_MASKED = 65535


@dataclass(eq=False)
class Scene:
    """Flat arrays over F frames holding M points in all.

    Attributes
    ----------
    x, y, z : ndarray, shape (M,), float32
        Feature point coordinates in the LiDAR frame (metres).
    weight : ndarray, shape (M,), float32
        Per-point weight (1 unless edges are weighted by strength).
    group : ndarray, shape (M,), int8
    point_start : ndarray, shape (F + 1,), int64
        Frame f owns points ``point_start[f]:point_start[f + 1]``.
    dtq : ndarray, shape (sum H*W,), uint16
        Truncated distance transforms, row-major, frame after frame, in units of ``dt_scale``
        (truncation / 65534 px): the evaluators read half the bytes of float32. Masked pixels
        (``Frame.mask`` False) hold :data:`DT_MASKED`; a lookup that reads one counts as out
        of the image.
    dt_scale : float
    dt_start : ndarray, shape (F,), int64
    width, height : ndarray, shape (F,), int64
    outside : ndarray, shape (F,), float32
        Cost charged to a point that is not valid for the camera model, outside the image or
        on a masked pixel.
    K : ndarray, shape (F, 3, 3), float64
    has_mask : ndarray, shape (F,), bool
        Whether frame f has masked pixels (the kernel checks lookups only where it does).
    cameras : list of Camera
        Each frame's camera (the numpy evaluators project through it).
    cam_params : ndarray, shape (F, N_PARAMS), float64
        The same cameras as :meth:`Camera.kernel_params` rows, for the numba kernel.
    mount : ndarray, shape (F, 3, 4), float64
        The top rows of each frame's :attr:`Camera.mount` (identity without one): frame f is
        evaluated at ``mount[f] @ T`` for a candidate ``T``.
    mounted : ndarray, shape (F,), bool
        Whether frame f's camera has a mount (the kernel composes only where it does).
    group_prefix : ndarray, shape (F, max_points + 1, G, 2), float64
        ``group_prefix[f, k, g]`` = sum of the weights and of the squared weights of group g
        among the first k points of frame f (both equal the count when weights are 1).
    gx, gy, gz, gweight : ndarray, shape (M,), float32
        The same points and weights grouped: within each frame, group 0's points, then group
        1's, ..., each group in evaluation order. The kernel sums one group at a time, so the
        first ``n`` points of a frame are the first ``group_count[f, n, g]`` points of each
        group (the same points, summed in the same order: the same sums bit for bit), and no
        per-point branch picks the sum a point goes to.
    group_start : ndarray, shape (F, G), int64
        Where group g of frame f starts in the grouped arrays.
    group_count : ndarray, shape (F, max_points + 1, G), int32
        ``group_count[f, k, g]`` = points of group g among the first k points of frame f.
    z_min : float
    truncation_px : float
    names : list of str
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    weight: np.ndarray
    group: np.ndarray
    point_start: np.ndarray
    dtq: np.ndarray
    dt_scale: float
    dt_start: np.ndarray
    width: np.ndarray
    height: np.ndarray
    outside: np.ndarray
    K: np.ndarray
    group_prefix: np.ndarray
    z_min: float
    truncation_px: float
    names: list[str]
    cameras: list
    cam_params: np.ndarray
    has_mask: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    gz: np.ndarray
    gweight: np.ndarray
    group_start: np.ndarray
    group_count: np.ndarray
    mount: np.ndarray
    mounted: np.ndarray

    @property
    def n_frames(self) -> int:
        return len(self.point_start) - 1

    @property
    def points_per_frame(self) -> np.ndarray:
        """Feature points held by each frame, shape (F,)."""
        return np.diff(self.point_start)

    def points_used(self, n) -> np.ndarray:
        """Points evaluated over all frames for ``n`` points per frame (shape of ``n``).

        Parameters
        ----------
        n : array_like of int, shape (...)
            Points per frame (each frame contributes at most the points it has).

        Returns
        -------
        ndarray of int64, shape (...)
        """
        n = np.asarray(n, dtype=np.int64)
        return np.minimum(n[..., None], self.points_per_frame).sum(axis=-1)

    def group_weights(self, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sums of weights and of squared weights of each group among the first ``n`` points
        of each frame, each of shape (C, F, G).

        Parameters
        ----------
        n : ndarray of int, shape (C,)
            Points per frame of each candidate.

        Returns
        -------
        W1, W2 : ndarray, shape (C, F, G)
        """
        n = np.asarray(n, dtype=np.int64)
        m = np.minimum(n[:, None], self.points_per_frame[None, :])
        pref = self.group_prefix[np.arange(self.n_frames)[None, :], m]
        return pref[..., 0], pref[..., 1]

    def _frame_q(self, f: int) -> np.ndarray:
        h, w, s = int(self.height[f]), int(self.width[f]), int(self.dt_start[f])
        return self.dtq[s:s + h * w].reshape(h, w)

    def frame_dt(self, f: int) -> np.ndarray:
        """The distance transform of frame f as the evaluators see it, float64 (H, W) in px;
        NaN on masked pixels.

        Parameters
        ----------
        f : int
            The frame's index.
        """
        q = self._frame_q(f)
        return np.where(q == DT_MASKED, np.nan, q * self.dt_scale)

    def frame_usable(self, f: int) -> np.ndarray:
        """Frame f's usable (unmasked) pixels, bool (H, W).

        Parameters
        ----------
        f : int
            The frame's index.
        """
        return self._frame_q(f) != DT_MASKED

    def frame_xyz(self, f: int) -> np.ndarray:
        """Frame f's points, shape (M_f, 3) float32, in the LiDAR frame (m).

        Parameters
        ----------
        f : int
            The frame's index.
        """
        a, b = self.point_start[f], self.point_start[f + 1]
        return np.column_stack([self.x[a:b], self.y[a:b], self.z[a:b]])

    @property
    def nbytes_static(self) -> int:
        """Bytes of the arrays every evaluation reads regardless of n (the DTs)."""
        return int(self.dtq.nbytes)


def build_scene(frames: list[FrameFeatures], z_min: float = 0.1, outside: str = "mean") -> Scene:
    """Lay out prepared frames for evaluation.

    Parameters
    ----------
    frames : list of FrameFeatures
        The frames' features (:func:`paretocal.features.prepare_frame`), points in their
        search order.
    z_min : float
        The smallest depth (pinhole) or range (fisheye, Mei) of a valid point (m).
    outside : {"mean", "truncation"}
        The charge for a point out of view: ``"mean"`` charges the frame's mean truncated DT (a
        point out of view costs what a point dropped at random costs, so neither pushing points
        out nor pulling unseen points in pays on average); ``"truncation"`` charges the full
        truncation distance.

    Returns
    -------
    Scene
    """
    counts = np.array([len(f.xyz) for f in frames], dtype=np.int64)
    point_start = np.concatenate([[0], np.cumsum(counts)])
    xyz = np.vstack([f.xyz for f in frames]) if counts.sum() else np.zeros((0, 3))
    group = (np.concatenate([f.group for f in frames]) if counts.sum()
             else np.zeros(0, np.int8)).astype(np.int8)
    sizes = np.array([f.image.dt.size for f in frames], dtype=np.int64)
    dt_start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    trunc = frames[0].image.truncation_px
    masks = [getattr(f.image, "mask", None) for f in frames]
    out = np.array([_mean_dt(f.image, m) if outside == "mean" else trunc
                    for f, m in zip(frames, masks)], dtype=np.float32)
    scale = trunc / (DT_MASKED - 1)
    dtq = []
    for f, m in zip(frames, masks):
        q = np.rint(f.image.dt.astype(np.float64).ravel() / scale).clip(0, DT_MASKED - 1)
        q = q.astype(np.uint16)
        if m is not None:
            q[~np.asarray(m, dtype=bool).ravel()] = DT_MASKED
        dtq.append(q)
    cameras = [f.camera for f in frames]
    for cam, f in zip(cameras, frames):
        if (cam.height, cam.width) != f.image.dt.shape:
            raise ValueError(f"frame {f.name}: the camera is {cam.width}x{cam.height} but the "
                             f"distance transform {f.image.dt.shape[1]}x{f.image.dt.shape[0]}")
    weight = (np.concatenate([f.weight for f in frames]) if counts.sum()
              else np.zeros(0)).astype(np.float32)
    maxm = int(counts.max()) if len(counts) else 0
    prefix = np.zeros((len(frames), maxm + 1, N_GROUPS, 2))
    for i, f in enumerate(frames):
        w = f.weight.astype(np.float32).astype(np.float64)
        onehot = np.eye(N_GROUPS)[f.group]
        prefix[i, 1:len(f.xyz) + 1, :, 0] = np.cumsum(onehot * w[:, None], axis=0)
        prefix[i, 1:len(f.xyz) + 1, :, 1] = np.cumsum(onehot * (w * w)[:, None], axis=0)
        prefix[i, len(f.xyz) + 1:] = prefix[i, len(f.xyz)]
    x, y, z = (np.ascontiguousarray(xyz[:, k], dtype=np.float32) for k in range(3))
    order, group_start, group_count = _grouped(group, point_start)
    return Scene(
        x=x, y=y, z=z, weight=weight, group=group, point_start=point_start,
        dtq=np.concatenate(dtq) if dtq else np.zeros(0, np.uint16),
        dt_scale=scale, dt_start=dt_start,
        width=np.array([f.image.dt.shape[1] for f in frames], dtype=np.int64),
        height=np.array([f.image.dt.shape[0] for f in frames], dtype=np.int64),
        outside=out, K=np.stack([np.asarray(f.camera.K, dtype=np.float64) for f in frames]),
        group_prefix=prefix, z_min=float(z_min), truncation_px=float(trunc),
        names=[f.name for f in frames], cameras=cameras,
        has_mask=np.array([m is not None and not np.all(m) for m in masks], dtype=bool),
        cam_params=np.ascontiguousarray(np.stack([c.kernel_params() for c in cameras]))
        if cameras else np.zeros((0, N_PARAMS)),
        gx=x[order], gy=y[order], gz=z[order], gweight=weight[order], group_start=group_start,
        group_count=group_count,
        mount=np.ascontiguousarray(np.stack([(np.eye(4) if c.mount is None else c.mount)[:3]
                                             for c in cameras]) if cameras
                                   else np.zeros((0, 3, 4))),
        mounted=np.array([c.mount is not None for c in cameras], dtype=bool))


def _grouped(group: np.ndarray, point_start: np.ndarray):
    """The grouped layout of :class:`Scene`: the order (M,) that groups each frame's points
    (stable: evaluation order within a group), ``group_start`` (F, G) and ``group_count``
    (F, max_points + 1, G)."""
    F = len(point_start) - 1
    counts = np.diff(point_start)
    maxm = int(counts.max()) if F else 0
    order = np.empty(len(group), dtype=np.int64)
    start = np.zeros((F, N_GROUPS), dtype=np.int64)
    count = np.zeros((F, maxm + 1, N_GROUPS), dtype=np.int32)
    for f in range(F):
        a, b = point_start[f], point_start[f + 1]
        g = group[a:b].astype(np.int64)
        order[a:b] = a + np.argsort(g, kind="stable")
        sizes = np.bincount(g, minlength=N_GROUPS)
        start[f] = a + np.concatenate([[0], np.cumsum(sizes)[:-1]])
        count[f, 1:b - a + 1] = np.cumsum(np.eye(N_GROUPS, dtype=np.int32)[g], axis=0)
        count[f, b - a + 1:] = count[f, b - a]
    return order, start, count


def _mean_dt(image, mask) -> float:
    """Mean truncated DT over the usable pixels (the whole image without a mask)."""
    if mask is None:
        return float(image.mean_dt)
    usable = np.asarray(mask, dtype=bool)
    if not usable.any():
        return float(image.truncation_px)
    return float(image.dt[usable].mean(dtype=np.float64))
