"""The checkerboard in the image: its inner corners, its pose through the camera's lens model,
its plane and its outline.

Corners are searched on the image as taken, then, for a lens that distorts, on a perspective
view of its centre (a pinhole of the same focal length, the image resampled through the lens
model), whose corners are mapped back through the model. Each view is tried with OpenCV's
detectors in turn, each with a purpose measured on the LCE-Calib recordings (44 frames of a
1280 x 720 camera with k1 = -0.44, the board's squares 19-37 px):

1. ``findChessboardCornersSB`` (``EXHAUSTIVE | ACCURACY | NORMALIZE_IMAGE``) on the full image:
   20 of 44 frames, corners to about 0.1 px;
2. the same on the image halved (``INTER_AREA``): a further 21 (its kernels expect squares a
   little smaller than these);
3. ``findChessboardCorners`` (adaptive threshold): a further 2;
4. the same after a local contrast equalisation (CLAHE): the last, an overexposed board seen at
   a grazing angle.

The corners of the later steps are refined by ``cornerSubPix`` on the full image, in a window of
a quarter of the corners' spacing (it never reaches the next corner). A grid is accepted as the
board only when its pose through the lens model places every corner within
:data:`MAX_RMS_PX` and the squares it implies alternate in brightness as a checkerboard's do
(:data:`MIN_ORDERED`): a grid offset by half a square, or another pattern's, fails both.

The pose is found on the corners' rays (:meth:`paretocal.camera.Camera.unproject`), turned so
that their mean is the optical axis of an ideal pinhole (a wide lens's rays up to 90 deg off its
axis stay finite there), by OpenCV's planar solver (IPPE), then refined by least squares on the
pixels through the lens model itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from ..camera import Camera
from ..io.board import Board

#: OpenCV's sector-based detector, with every flag that helps on real images.
SB_FLAGS = (cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE)
#: OpenCV's classic detector.
CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
#: A grid whose pose through the lens model leaves a larger RMS corner residual (px) is not the
#: board: the corners are found to a fraction of a pixel (0.03-0.64 px on the 44 LCE-Calib
#: frames), a grid of wrong points (half a square off, another pattern) misses by pixels.
MAX_RMS_PX = 1.0
#: Share of (dark, light) square pairs, by the pattern's colour parity, whose image brightness
#: must be ordered as the pattern says (the dark one darker). Every pair was ordered on all 44
#: LCE-Calib frames, an overexposed board at a grazing angle included; a glare on one square of
#: 63 still leaves 97 %.
MIN_ORDERED = 0.9
#: Contrast-limited equalisation of the last try (OpenCV's defaults but a clip of 3).
CLAHE_CLIP = 3.0
CLAHE_TILES = (8, 8)
#: ``cornerSubPix`` stops after this many iterations or a move below this (px).
SUBPIX_ITERS = 50
SUBPIX_EPS = 0.01


@dataclass(frozen=True, eq=False)
class BoardView:
    """The board as one image shows it (:func:`find_board`).

    Attributes
    ----------
    corners_uv : ndarray, shape (N, 2)
        The inner corners in the image as taken (px), in :meth:`Board.corners_m` order (or
        that order turned half a turn: a checkerboard with an odd number of squares both ways
        looks the same turned).
    T_cam_board : ndarray, shape (4, 4)
        The board's pose: board frame (origin at its centre, x along its width, y along its
        height, z its normal towards the camera) to camera frame (m).
    rms_px : float
        RMS distance of the corners from their projection at the pose (px).
    ordered : float
        Share of (dark, light) square pairs whose brightness is ordered as the pattern says.
    method : str
        The detector that found the corners (``sb``, ``sb-half``, ``classic``,
        ``classic-clahe``), ``+perspective`` when on the perspective view.
    outline_cam : ndarray, shape (4, 3)
        The board's four outer corners in the camera frame (m).
    """

    corners_uv: np.ndarray
    T_cam_board: np.ndarray
    rms_px: float
    ordered: float
    method: str
    outline_cam: np.ndarray

    @property
    def normal(self) -> np.ndarray:
        """The board plane's unit normal in the camera frame, towards the camera, shape (3,)."""
        return self.T_cam_board[:3, 2].copy()

    @property
    def distance_m(self) -> float:
        """The camera's distance from the board plane (m): ``normal . x + distance_m = 0``
        on the plane."""
        return float(-self.normal @ self.T_cam_board[:3, 3])

    @property
    def centre_cam(self) -> np.ndarray:
        """The board's centre in the camera frame, shape (3,) (m)."""
        return self.T_cam_board[:3, 3].copy()

    def to_dict(self) -> dict:
        """For result.json: the detector, the fit, the pose's centre, normal and distance."""
        return {"method": self.method, "rms_px": round(self.rms_px, 3),
                "ordered": round(self.ordered, 3),
                "centre_cam_m": [round(float(v), 4) for v in self.centre_cam],
                "normal_cam": [round(float(v), 5) for v in self.normal],
                "distance_m": round(self.distance_m, 4)}


def find_board(image: np.ndarray, camera: Camera, board: Board) -> BoardView | None:
    """The board in one image, or None when no grid passes the checks.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W), uint8
        The image as taken (BGR, or grey).
    camera : Camera
        Its lens model.
    board : Board

    Returns
    -------
    BoardView or None
    """
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    for uv, method in _candidates(gray, camera, board):
        pose = board_pose(uv, camera, board)
        if pose is None:
            continue
        T, rms = pose
        if not rms <= MAX_RMS_PX:
            continue
        ordered = square_order(gray, camera, board, T)
        if ordered < MIN_ORDERED:
            continue
        outline = board.outline_m() @ T[:3, :3].T + T[:3, 3]
        return BoardView(corners_uv=uv, T_cam_board=T, rms_px=rms, ordered=ordered,
                         method=method, outline_cam=outline)
    return None


def _candidates(gray: np.ndarray, camera: Camera, board: Board):
    """The grids the detectors find, in the cascade's order, as ``(corners (N, 2) px in the
    image as taken, method)``: on the image, then (a lens that distorts) on its perspective
    view, mapped back. A later detector runs only when the grids before it failed the
    checks."""
    yield from _detect(gray, board, "")
    if camera.ideal:
        return
    view, K_view = perspective_view(gray, camera)
    for uv, method in _detect(view, board, "+perspective"):
        back = _from_view(uv, K_view, camera)
        if np.all(np.isfinite(back)):
            yield _subpix(gray, back), method


def _detect(gray: np.ndarray, board: Board, suffix: str):
    """The board's pattern in ``gray`` from each detector of the cascade that finds one, in
    turn: ``(corners (N, 2) px, method)``."""
    pattern = board.inner
    clahe = cv2.createCLAHE(CLAHE_CLIP, CLAHE_TILES)
    for name, img in (("classic", gray), ("classic-clahe", None)):
        img = clahe.apply(gray) if img is None else img
        ok, c = cv2.findChessboardCorners(img, pattern, flags=CLASSIC_FLAGS)
        if ok:
            yield _subpix(gray, c.reshape(-1, 2).astype(np.float64)), name + suffix
    half = cv2.resize(gray, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    ok, c = cv2.findChessboardCornersSB(half, pattern, flags=SB_FLAGS)
    if ok:
        # A pixel of the halved image covers pixels 2i and 2i + 1: its centre is 2i + 0.5.
        uv = 2.0 * c.reshape(-1, 2).astype(np.float64) + 0.5
        yield _subpix(gray, uv), "sb-half" + suffix
    ok, c = cv2.findChessboardCornersSB(gray, pattern, flags=SB_FLAGS)
    if ok:
        yield c.reshape(-1, 2).astype(np.float64), "sb" + suffix


def _subpix(gray: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Corners refined by ``cornerSubPix`` in a window of a quarter of their smallest spacing
    (at least 2 px): the window never reaches a neighbouring corner."""
    d = np.linalg.norm(uv[:, None] - uv[None], axis=2)
    d[d == 0] = np.inf
    half = max(2, int(np.nanmin(d) / 4))
    out = cv2.cornerSubPix(gray, uv.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1),
                           (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, SUBPIX_ITERS,
                            SUBPIX_EPS))
    return out.reshape(-1, 2).astype(np.float64)


def perspective_view(gray: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The image seen by an ideal pinhole of the camera's size and focal length looking along
    its optical axis, resampled through the lens model (pixels no valid ray reaches are black).

    Returns
    -------
    view : ndarray, shape (H, W), uint8
    K_view : ndarray, shape (3, 3)
        The pinhole's intrinsics.
    """
    h, w = gray.shape[:2]
    f = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    K_view = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([(u - K_view[0, 2]) / f, (v - K_view[1, 2]) / f, np.ones_like(u)], axis=-1)
    uv, valid = camera.project_camera_points(rays)
    uv[~valid] = -1.0
    view = cv2.remap(gray, uv[..., 0].astype(np.float32), uv[..., 1].astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return view, K_view


def _from_view(uv_view: np.ndarray, K_view: np.ndarray, camera: Camera) -> np.ndarray:
    """Pixels of :func:`perspective_view` mapped back into the image as taken (NaN: none)."""
    rays = np.column_stack([(uv_view[:, 0] - K_view[0, 2]) / K_view[0, 0],
                            (uv_view[:, 1] - K_view[1, 2]) / K_view[1, 1],
                            np.ones(len(uv_view))])
    return camera.project_camera_points(rays)[0]


def _rotation_to_z(m: np.ndarray) -> np.ndarray:
    """A rotation taking the unit vector ``m`` to the z axis, shape (3, 3)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(m, z)
    s, c = float(np.linalg.norm(v)), float(m @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    V = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + V + V @ V * ((1.0 - c) / s ** 2)


def _pose_matrix(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(p[:3])[0]
    T[:3, 3] = p[3:]
    return T


def board_pose(uv: np.ndarray, camera: Camera, board: Board) -> tuple[np.ndarray, float] | None:
    """The board's pose from its corners in the image, through the lens model.

    Parameters
    ----------
    uv : ndarray, shape (N, 2)
        The inner corners (px), in :meth:`Board.corners_m` order.
    camera : Camera
    board : Board

    Returns
    -------
    (T_cam_board (4, 4), rms_px) or None
        The pose with the board's z axis towards the camera, and the RMS corner residual (px);
        None when a corner's ray is not valid for the model or the solver fails.
    """
    obj = board.corners_m()
    rays = camera.unproject(uv)
    if not np.all(np.isfinite(rays)):
        return None
    mean = rays.mean(axis=0)
    Rv = _rotation_to_z(mean / np.linalg.norm(mean))
    r = rays @ Rv.T
    if np.any(r[:, 2] <= 0):
        return None
    xy = r[:, :2] / r[:, 2:]
    ok, rvec, tvec = cv2.solvePnP(obj, xy, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    R = Rv.T @ cv2.Rodrigues(rvec)[0]
    t = Rv.T @ tvec.ravel()

    def residual(p):
        T = _pose_matrix(p)
        px, valid = camera.project_camera_points(obj @ T[:3, :3].T + T[:3, 3])
        return np.where(valid[:, None], px - uv, 1e3).ravel()

    fit = least_squares(residual, np.r_[cv2.Rodrigues(R)[0].ravel(), t], method="lm")
    T = _pose_matrix(fit.x)
    if T[:3, 2] @ T[:3, 3] > 0:
        # The board's normal towards the camera: a half turn about the board's x axis (the
        # corners' order along y reverses, which the plane and the outline do not see).
        T[:3, 1:3] *= -1.0
    rms = float(np.sqrt(np.mean(np.sum(fit.fun.reshape(-1, 2) ** 2, axis=1))))
    return T, rms


def square_order(gray: np.ndarray, camera: Camera, board: Board, T: np.ndarray) -> float:
    """How well the image at pose ``T`` shows the board as described: the share of (dark,
    light) square pairs ordered as the pattern says, or, when lower, the share of samples of
    the white margin that are light on its least light side (0 to 1).

    The image is smoothed by a Gaussian of a quarter of the smallest square's side (so the
    value at a square's centre is the square's, not a speck's) and read at the projected
    centre of every square; the colour parity whose median is darker is taken as the dark
    squares (the pattern's first square is either). The margin is read halfway across it, in
    line with each outer square: a grid that is part of a larger board (a board described with
    too few squares) has squares there on one side at least, not white. A margin narrower than
    a quarter of a square is not read.
    """
    centres, parity = board.square_centres_m()
    margin = min(board.margin_m)
    rims = _margin_samples(board) if margin >= board.square_m / 4 else np.zeros((0, 3))
    pts = np.vstack([centres, rims])
    uv, valid = camera.project_camera_points(pts @ T[:3, :3].T + T[:3, 3])
    inside = valid & (uv[:, 0] >= 0) & (uv[:, 0] <= gray.shape[1] - 1) & \
        (uv[:, 1] >= 0) & (uv[:, 1] <= gray.shape[0] - 1)
    sq = inside[:len(centres)]
    if sq.sum() < 4:
        return 0.0
    spacing = np.linalg.norm(np.diff(uv[:len(centres)][sq], axis=0), axis=1)
    sigma = max(0.5, float(np.min(spacing[spacing > 0], initial=4.0)) / 4.0)
    smooth = cv2.GaussianBlur(gray.astype(np.float32), (0, 0), sigma)
    val = np.full(len(pts), np.nan, dtype=np.float32)
    val[inside] = cv2.remap(smooth, uv[inside, 0].astype(np.float32)[None],
                            uv[inside, 1].astype(np.float32)[None], cv2.INTER_LINEAR)[0]
    sq_val = val[:len(centres)]
    a, b = sq_val[sq & (parity == 0)], sq_val[sq & (parity == 1)]
    if not len(a) or not len(b):
        return 0.0
    dark, light = (a, b) if np.median(a) < np.median(b) else (b, a)
    ordered = float(np.mean(dark[:, None] < light[None, :]))
    if not len(rims):
        return ordered
    mid = 0.5 * (float(np.median(dark)) + float(np.median(light)))
    rim_val, side = val[len(centres):], _margin_sides(board)
    shares = [float(np.mean(rim_val[seen] > mid)) for k in range(4)
              if (seen := (side == k) & np.isfinite(rim_val)).any()]
    return min([ordered] + shares)


def _margin_samples(board: Board) -> np.ndarray:
    """Points halfway across the margin in line with each outer square, side by side (bottom,
    right, top, left in the board's frame), shape (2 (sx + sy), 3) (m)."""
    sx, sy = board.squares
    s = board.square_m
    mx, my = board.margin_m
    x = (np.arange(sx) - (sx - 1) / 2.0) * s
    y = (np.arange(sy) - (sy - 1) / 2.0) * s
    ex, ey = sx * s / 2.0 + mx / 2.0, sy * s / 2.0 + my / 2.0
    rows = [np.column_stack([x, np.full(sx, -ey)]), np.column_stack([np.full(sy, ex), y]),
            np.column_stack([x, np.full(sx, ey)]), np.column_stack([np.full(sy, -ex), y])]
    xy = np.vstack(rows)
    return np.column_stack([xy, np.zeros(len(xy))])


def _margin_sides(board: Board) -> np.ndarray:
    """The side (0 to 3) of each of :func:`_margin_samples`' points."""
    sx, sy = board.squares
    return np.repeat(np.arange(4), [sx, sy, sx, sy])
