"""Rigid-body geometry: ZYX Euler rotations, SE(3) algebra, the search correction, pose errors.

Conventions (docs/conventions.md section 1): ``T_cam_lidar`` maps LiDAR points into the camera frame,
and the search variables form a correction applied in the LiDAR frame,
``T = T_init @ D(x, y, z, yaw, pitch, roll)`` with ``D = [Rz(yaw) Ry(pitch) Rx(roll) | (x, y, z)]``.
Angles are in degrees in every public function; translations in metres.
All functions are batched over leading axes where the docstring says so.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError, first_line


def rotation_zyx(yaw_deg, pitch_deg, roll_deg) -> np.ndarray:
    """Rotation matrices ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``.

    Parameters
    ----------
    yaw_deg, pitch_deg, roll_deg : array_like, shape (...)
        Angles in degrees, broadcast together.

    Returns
    -------
    R : ndarray, shape (..., 3, 3)

    Examples
    --------
    >>> import numpy as np
    >>> from paretocal.geometry import rotation_zyx
    >>> R = rotation_zyx(90.0, 0.0, 0.0)        # yaw: x turns into y
    >>> print(np.round(R @ [1.0, 0.0, 0.0], 6) + 0.0)
    [0. 1. 0.]
    >>> rotation_zyx([0.0, 10.0, 20.0], 0.0, 0.0).shape
    (3, 3, 3)
    """
    y, p, r = np.broadcast_arrays(*(np.radians(np.asarray(a, dtype=np.float64))
                                    for a in (yaw_deg, pitch_deg, roll_deg)))
    cy, sy, cp, sp, cr, sr = np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    R = np.empty(y.shape + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def euler_zyx(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_zyx`: (yaw, pitch, roll) in degrees, shape (..., 3).

    Pitch is taken in [-90, 90] degrees.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices.

    Returns
    -------
    ndarray, shape (..., 3)
        Yaw, pitch and roll in degrees.

    Examples
    --------
    >>> import numpy as np
    >>> from paretocal.geometry import euler_zyx, rotation_zyx
    >>> print(np.round(euler_zyx(rotation_zyx(30.0, -20.0, 5.0)), 6))
    [ 30. -20.   5.]
    """
    R = np.asarray(R, dtype=np.float64)
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    return np.degrees(np.stack([yaw, pitch, roll], axis=-1))


def correction_matrix(params: np.ndarray) -> np.ndarray:
    """The correction ``D`` for search variables ``(x, y, z, yaw, pitch, roll)``.

    Parameters
    ----------
    params : array_like, shape (..., 6) or more columns
        Metres and degrees; columns beyond the sixth (such as ``n``) are ignored.

    Returns
    -------
    D : ndarray, shape (..., 4, 4)

    Examples
    --------
    The correction moves the LiDAR 10 cm along its x and turns it 1 degree in yaw; the
    extrinsic it gives is ``T_init @ D`` (:func:`apply_correction`), and
    :func:`correction_params` reads the six values back:

    >>> import numpy as np
    >>> from paretocal.geometry import correction_matrix, correction_params
    >>> D = correction_matrix([0.1, 0.0, 0.0, 1.0, 0.0, 0.0])
    >>> print(np.round(correction_params(D), 6) + 0.0)
    [0.1 0.  0.  1.  0.  0. ]
    """
    params = np.asarray(params, dtype=np.float64)
    D = np.zeros(params.shape[:-1] + (4, 4))
    D[..., :3, :3] = rotation_zyx(params[..., 3], params[..., 4], params[..., 5])
    D[..., :3, 3] = params[..., :3]
    D[..., 3, 3] = 1.0
    return D


def correction_params(D: np.ndarray) -> np.ndarray:
    """Inverse of :func:`correction_matrix`: ``(x, y, z, yaw, pitch, roll)``, shape (..., 6).

    Parameters
    ----------
    D : array_like, shape (..., 4, 4)
        Corrections (rigid transforms in the LiDAR frame).

    Returns
    -------
    ndarray, shape (..., 6)
        Translation in metres, then yaw, pitch and roll in degrees.
    """
    D = np.asarray(D, dtype=np.float64)
    return np.concatenate([D[..., :3, 3], euler_zyx(D[..., :3, :3])], axis=-1)


def apply_correction(T_init: np.ndarray, params: np.ndarray) -> np.ndarray:
    """``T_init @ D(params)`` for a batch of corrections, shape (..., 4, 4).

    Parameters
    ----------
    T_init : array_like, shape (4, 4)
        The initial extrinsic ``T_cam_lidar`` (m).
    params : array_like, shape (..., 6) or more columns
        Corrections ``(x, y, z, yaw, pitch, roll)`` in metres and degrees, applied in the LiDAR
        frame; columns beyond the sixth (such as ``n``) are ignored.

    Returns
    -------
    ndarray, shape (..., 4, 4)
        The corrected extrinsics.
    """
    return np.asarray(T_init, dtype=np.float64) @ correction_matrix(params)


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms, shape (..., 4, 4).

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Rigid transforms (rotation and translation in metres).

    Returns
    -------
    ndarray, shape (..., 4, 4)

    Examples
    --------
    >>> import numpy as np
    >>> from paretocal.geometry import apply_correction, invert
    >>> T = apply_correction(np.eye(4), [0.2, -0.1, 1.5, 30.0, 5.0, -2.0])
    >>> bool(np.allclose(invert(T) @ T, np.eye(4)))
    True"""
    T = np.asarray(T, dtype=np.float64)
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    Ti[..., 3, 3] = 1.0
    return Ti


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply rigid transforms to points: the one place a point changes frame.

    Parameters
    ----------
    T : ndarray, shape (..., 4, 4) or (..., 3, 4)
        One transform or a batch of them.
    points : ndarray, shape (N, 3+)
        Points in metres (columns beyond the third are ignored).

    Returns
    -------
    ndarray, shape (..., N, 3), float64
        The points under every transform of the batch.

    Examples
    --------
    One point under two transforms at once (a batch of 2):

    >>> import numpy as np
    >>> from paretocal.geometry import apply_correction, transform_points
    >>> T = apply_correction(np.eye(4), [[1.0, 0, 0, 0, 0, 0], [0, 0, 0, 90.0, 0, 0]])
    >>> print(np.round(transform_points(T, np.array([[1.0, 0.0, 0.0]])), 6) + 0.0)
    [[[2. 0. 0.]]
    <BLANKLINE>
     [[0. 1. 0.]]]
    """
    T = np.asarray(T, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)[:, :3]
    return p @ np.swapaxes(T[..., :3, :3], -1, -2) + T[..., None, :3, 3]


def rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Angle of rotation matrices in degrees, shape (...). Stable near 0 and 180 degrees.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices.

    Returns
    -------
    ndarray, shape (...)
        The angle of each rotation about its axis, in degrees, in [0, 180].
    """
    R = np.asarray(R, dtype=np.float64)
    # atan2(|axis * sin|, cos) is accurate near zero, where arccos((tr - 1) / 2) is not.
    s = 0.5 * np.linalg.norm(np.stack([R[..., 2, 1] - R[..., 1, 2],
                                       R[..., 0, 2] - R[..., 2, 0],
                                       R[..., 1, 0] - R[..., 0, 1]], axis=-1), axis=-1)
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.degrees(np.arctan2(s, c))


def pose_error(T_est: np.ndarray, T_ref: np.ndarray) -> dict[str, np.ndarray]:
    """Error of estimated extrinsics against a reference (docs/conventions.md section 1).

    Parameters
    ----------
    T_est : array_like, shape (..., 4, 4)
        Estimated extrinsics ``T_cam_lidar`` (m).
    T_ref : array_like, shape (4, 4)
        The reference ``T_cam_lidar`` (m).

    Returns
    -------
    dict
        ``rotation_deg``: angle of ``R_est^T R_ref``; ``translation_cm``: ``|t_est - t_ref|``.
        Per axis, in the LiDAR frame (the correction's own axes): ``x_lidar_cm``,
        ``y_lidar_cm``, ``z_lidar_cm``, ``yaw_deg``, ``pitch_deg``, ``roll_deg``, the correction
        that takes the reference to the estimate, ``T_est = T_ref @ D(...)`` (translation
        ``R_ref^T (t_est - t_ref)``, ZYX angles of ``R_ref^T R_est``). In the camera frame:
        ``x_cam_cm``, ``y_cam_cm``, ``z_cam_cm``, ``t_est - t_ref``. Each value has shape
        ``T_est.shape[:-2]``.

    Examples
    --------
    An estimate 2 cm off along the LiDAR's x and 0.5 degree off in yaw:

    >>> import numpy as np
    >>> from paretocal.geometry import apply_correction, pose_error
    >>> T_ref = apply_correction(np.eye(4), [0.0, -0.08, -0.27, -90.0, 0.0, -90.0])
    >>> e = pose_error(T_ref @ apply_correction(np.eye(4), [0.02, 0, 0, 0.5, 0, 0]), T_ref)
    >>> print(f"{e['rotation_deg']:.2f} deg, {e['translation_cm']:.2f} cm, "
    ...       f"x {e['x_lidar_cm']:.2f} cm, yaw {e['yaw_deg']:.2f} deg")
    0.50 deg, 2.00 cm, x 2.00 cm, yaw 0.50 deg
    """
    T_est = np.asarray(T_est, dtype=np.float64)
    T_ref = np.asarray(T_ref, dtype=np.float64)
    R_est, R_ref = T_est[..., :3, :3], T_ref[:3, :3]
    dR = np.swapaxes(R_est, -1, -2) @ R_ref
    dt = (T_est[..., :3, 3] - T_ref[:3, 3]) * 100.0
    ypr = euler_zyx(R_ref.T @ R_est)
    dl = dt @ R_ref                                      # R_ref^T dt, row-wise
    return {
        "rotation_deg": rotation_angle_deg(dR),
        "translation_cm": np.linalg.norm(dt, axis=-1),
        "x_lidar_cm": dl[..., 0], "y_lidar_cm": dl[..., 1], "z_lidar_cm": dl[..., 2],
        "yaw_deg": ypr[..., 0], "pitch_deg": ypr[..., 1], "roll_deg": ypr[..., 2],
        "x_cam_cm": dt[..., 0], "y_cam_cm": dt[..., 1], "z_cam_cm": dt[..., 2],
    }


def check_rigid(T, name: str, tol: float = 1e-4, key: str = "T_cam_lidar",
                orthonormalise: bool = True) -> np.ndarray:
    """Validate a 4x4 rigid transform read from a file and return it as float64.

    Raises :class:`InputError` naming the file ``name`` and the matrix ``key`` when the shape
    is wrong, values are not finite, the bottom row is not ``[0, 0, 0, 1]`` or the rotation
    block is not a proper rotation. A 3x4 matrix gets the bottom row added.

    Parameters
    ----------
    T : array_like, shape (4, 4) or (3, 4)
        The matrix as read (nested lists or an array; translation in metres).
    name : str
        The file it came from, for the error message.
    tol : float
        Largest ``|R^T R - I|`` accepted for the rotation block.
    key : str
        The matrix's name in the file, for the error message.
    orthonormalise : bool
        Return the rotation block re-orthonormalised (by SVD), so that the 6-7 significant
        digits of a file do not accumulate.

    Returns
    -------
    ndarray, shape (4, 4), float64
    """
    try:
        T = np.array(T, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        text = first_line(exc)
        if "inhomogeneous" in text or "sequence" in text:
            text = "rows of different lengths"
        raise InputError(f"{name}: {key} is not a numeric matrix ({text})") from None
    if T.shape == (3, 4):
        T = np.vstack([T, [0.0, 0.0, 0.0, 1.0]])
    if T.shape != (4, 4):
        raise InputError(f"{name}: {key} must be 4x4 (or 3x4), got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise InputError(f"{name}: {key} contains NaN or infinite values")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InputError(f"{name}: the last row of {key} must be [0, 0, 0, 1]")
    R = T[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):      # huge entries: err is inf, not a warning
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        det = float(np.linalg.det(R)) if np.isfinite(err) else float("nan")
    if not err <= tol or not det > 0:
        raise InputError(f"{name}: the rotation block of {key} is not a rotation matrix "
                         f"(|R^T R - I| = {err:.2g}, det = {det:.4f})")
    if not orthonormalise:
        return T
    # Re-orthonormalise so that 6-7 significant digits in a file do not accumulate.
    U, _, Vt = np.linalg.svd(R)
    T[:3, :3] = U @ Vt
    return T


def decalibrate(T_ref: np.ndarray, rot_deg: float, trans_m: float,
                rng: np.random.Generator | int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A decalibrated extrinsic and the correction that brings it back to ``T_ref``.

    The correction ``p = (x, y, z, yaw, pitch, roll)`` is drawn uniform per axis in
    ``+-trans_m`` (m) and ``+-rot_deg`` (deg), translations first; the start is
    ``T_init = T_ref @ D(p)^-1``, so the correction a calibration has to find, ``p``, lies in
    the box (the convention of ``paretocal perturb`` and the benchmarks).

    Parameters
    ----------
    T_ref : array_like, shape (4, 4)
        The extrinsic to decalibrate (``T_cam_lidar``, m).
    rot_deg : float
        Largest rotation per axis (deg).
    trans_m : float
        Largest translation per axis (m).
    rng : numpy.random.Generator or int or None
        The random generator, or a seed for one.

    Returns
    -------
    T_init : ndarray, shape (4, 4)
        The decalibrated extrinsic.
    p : ndarray, shape (6,)
        The correction from ``T_init`` to ``T_ref`` (m, deg): ``T_ref = T_init @ D(p)``.
    """
    rng = np.random.default_rng(rng)
    p = np.concatenate([rng.uniform(-trans_m, trans_m, 3), rng.uniform(-rot_deg, rot_deg, 3)])
    return np.asarray(T_ref, dtype=np.float64) @ invert(correction_matrix(p)), p
