"""The extrinsic from the board alone, with no initial guess: a closed form from the boards'
planes, then least squares over the board's residuals.

Each frame where both sensors see the board gives its plane twice: ``n_c . x + d_c = 0`` in the
camera frame (from its corners) and ``n_l . p + d_l = 0`` in the LiDAR frame (from its returns),
normals towards the sensors. A point ``p`` of the plane maps to ``x = R p + t``, so
``n_c = R n_l`` and ``n_c . t = d_l - d_c``. The rotation is the one that best takes the LiDAR's
normals to the camera's (Kabsch: the SVD of their cross-covariance), the translation the
least-squares solution of the distances. Both need boards turned differently:

* the rotation about the boards' mean normal is fixed only by how far the normals spread from
  it (all boards parallel leave it free);
* the translation along a direction no normal leans towards is fixed by nothing.

:func:`conditioning` says how well each is fixed, in words and figures, from the normals'
scatter and the per-frame misfits. :func:`refine` then minimises the board's residuals
(:func:`paretocal.objective.board.residuals`: every return on the plane, every scan
line's ends on the outline) by robust least squares over the six-degree-of-freedom
correction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..geometry import apply_correction, correction_params
from ..objective.board import BoardScene, least_squares_loss, residuals

#: A rotation or translation whose standard error from the closed form exceeds these (deg, m)
#: is not fixed by the board poses: the verdict's limits on a usable interval (1 deg, 10 cm)
#: halved, since an interval is about two standard errors.
FREE_DEG = 0.5
FREE_M = 0.05


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation R (3, 3) minimising ``sum |R a_j - b_j|^2`` for unit vectors a, b (J, 3)."""
    H = a.T @ b
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    return Vt.T @ D @ U.T


def closed_form(n_lidar: np.ndarray, d_lidar: np.ndarray, n_cam: np.ndarray,
                d_cam: np.ndarray) -> np.ndarray:
    """``T_cam_lidar`` (4, 4) from the boards' planes in both sensors.

    Parameters
    ----------
    n_lidar, n_cam : ndarray, shape (J, 3)
        Unit normals towards each sensor.
    d_lidar, d_cam : ndarray, shape (J,)
        Each sensor's distance from the plane (m).
    """
    R = kabsch(n_lidar, n_cam)
    t = np.linalg.lstsq(n_cam, d_lidar - d_cam, rcond=None)[0]
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def misfit(T: np.ndarray, n_lidar: np.ndarray, d_lidar: np.ndarray, n_cam: np.ndarray,
           d_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's normal misfit (deg) and distance misfit (m) at ``T``, shape (J,) each."""
    Rn = n_lidar @ T[:3, :3].T
    ang = np.degrees(np.arccos(np.clip(np.sum(Rn * n_cam, axis=1), -1.0, 1.0)))
    dist = n_cam @ T[:3, 3] + d_cam - d_lidar
    return ang, dist


@dataclass(frozen=True)
class Conditioning:
    """How well the board poses fix the extrinsic (:func:`conditioning`).

    Attributes
    ----------
    spread_deg : float
        The RMS angle of the boards' normals from their mean (deg).
    rotation_se_deg : float
        Standard error of the rotation about the boards' mean normal (deg), from the normals'
        misfit and spread; the other two rotation axes are fixed by every board.
    weak_axis_cam : tuple of float, shape (3,)
        The translation direction the boards fix least, in the camera frame.
    translation_se_m : float
        Standard error of the translation along it (m).
    boards : int
        Frames used.
    notes : tuple of str
        What is not fixed, in words (empty when everything is).
    """

    spread_deg: float
    rotation_se_deg: float
    weak_axis_cam: tuple
    translation_se_m: float
    boards: int
    notes: tuple = ()

    @property
    def ok(self) -> bool:
        return not self.notes

    def to_dict(self) -> dict:
        return {"boards": self.boards, "spread_deg": round(self.spread_deg, 2),
                "rotation_se_deg": round(self.rotation_se_deg, 3),
                "weak_axis_cam": [round(float(v), 3) for v in self.weak_axis_cam],
                "translation_se_cm": round(100 * self.translation_se_m, 2),
                "notes": list(self.notes)}


def axis_words(v: np.ndarray) -> str:
    """A camera-frame direction in words: its nearest camera axis when within 30 deg."""
    v = np.asarray(v, dtype=np.float64) / np.linalg.norm(v)
    names = ("the camera's horizontal axis (x)", "the camera's vertical axis (y)",
             "the camera's optical axis (z)")
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) >= np.cos(np.radians(30.0)):
        return names[k]
    return "the camera-frame direction (" + ", ".join(f"{c:.2f}" for c in v) + ")"


def conditioning(T: np.ndarray, n_lidar: np.ndarray, d_lidar: np.ndarray, n_cam: np.ndarray,
                 d_cam: np.ndarray, min_boards: int = 3) -> Conditioning:
    """How well the board poses fix the extrinsic: the normals' spread, the standard errors of
    the rotation about their mean and of the translation along the least fixed direction,
    from the frames' misfits at ``T``, and what is free in words.

    A rotation ``w`` turns a normal by ``|w x n|``; summed over the frames that is
    ``J (1 - w^T N w)`` with ``N`` the normals' mean outer product: least about ``N``'s first
    eigenvector (the mean normal), by ``1 - lambda_1`` (the normals' spread, squared). Each
    frame's normal misfit (the RMS over the frames) then gives the rotation's standard error
    about it; likewise each frame's distance misfit through ``N``'s smallest eigenvalue for the
    translation.
    """
    J = len(n_cam)
    N = n_cam.T @ n_cam / max(J, 1)
    lam, vec = np.linalg.eigh(N)                    # ascending
    ang, dist = misfit(T, n_lidar, d_lidar, n_cam, d_cam)
    dof = max(J - 3, 1)
    s_ang = np.radians(float(np.sqrt(np.sum(ang ** 2) / dof)))
    s_dist = float(np.sqrt(np.sum(dist ** 2) / dof))
    spread = float(np.sqrt(max(1.0 - lam[2], 0.0)))
    rot_se = np.degrees(s_ang / max(spread * np.sqrt(J), 1e-12))
    t_se = s_dist / max(np.sqrt(J * max(lam[0], 0.0)), 1e-12)
    notes = []
    if J < min_boards:
        notes.append(f"the board is seen by both sensors in {J} frame(s); the closed form "
                     f"needs {min_boards} with the board turned differently")
    if rot_se > FREE_DEG:
        notes.append(f"the board poses leave the rotation about {axis_words(vec[:, 2])} "
                     f"free (the boards' normals spread {np.degrees(spread):.1f} deg, "
                     f"+-{rot_se:.2g} deg): tilt the board differently between frames")
    if t_se > FREE_M:
        notes.append(f"the board poses leave the translation along {axis_words(vec[:, 0])} "
                     f"free (+-{100 * t_se:.2g} cm): tilt the board towards that direction in "
                     "some frames")
    return Conditioning(spread_deg=float(np.degrees(spread)), rotation_se_deg=float(rot_se),
                        weak_axis_cam=tuple(float(v) for v in vec[:, 0]),
                        translation_se_m=float(t_se), boards=J, notes=tuple(notes))


def refine(scene: BoardScene, T0: np.ndarray, max_nfev: int = 100) -> np.ndarray:
    """``T_cam_lidar`` (4, 4) minimising the board's cost (:func:`paretocal.objective.board.
    board_terms` summed over the frames) from ``T0``, by robust least squares over the
    correction ``T0 @ D(x, y, z, yaw, pitch, roll)``."""
    _, w = residuals(scene, T0)

    def fun(p):
        return residuals(scene, apply_correction(T0, p))[0]

    fit = least_squares(fun, np.zeros(6), loss=least_squares_loss(w), max_nfev=max_nfev)
    return apply_correction(T0, fit.x)


def leave_one_out(scene: BoardScene, T: np.ndarray) -> np.ndarray:
    """The correction (m, deg) from ``T`` that the board's cost prefers without each frame,
    shape (J, 6), each by one Gauss-Newton step of the robust least squares from ``T`` (the
    frames' jackknife)."""
    J = scene.n_boards
    h = np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3])
    u0, w = residuals(scene, T)
    jac = np.empty((len(u0), 6))
    for k in range(6):
        p = np.zeros(6)
        p[k] = h[k]
        jac[:, k] = (residuals(scene, apply_correction(T, p))[0] - u0) / h[k]
    # The robust loss as weights (iteratively reweighted least squares): rho'(u^2) w.
    irls = w / np.sqrt(1.0 + u0 ** 2)
    frame = np.concatenate([np.repeat(np.arange(J), np.diff(scene.point_start)),
                            np.repeat(np.arange(J), np.diff(scene.end_start))])
    out = np.zeros((J, 6))
    for j in range(J):
        keep = frame != j
        sw = np.sqrt(irls[keep])
        out[j] = -np.linalg.lstsq(jac[keep] * sw[:, None], u0[keep] * sw, rcond=None)[0]
    return out


def correction_of(T: np.ndarray, T_from: np.ndarray) -> np.ndarray:
    """The correction (m, deg) with ``T = T_from @ D``, shape (6,)."""
    return correction_params(np.linalg.solve(T_from, T))
