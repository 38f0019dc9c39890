"""Camera models and the projection of LiDAR points, batched over points and extrinsics.

Three models, each the usual formulation of its name:

``pinhole``
    OpenCV's radial-tangential ("plumb_bob" / "rational_polynomial") model. With normalised
    coordinates ``x = X / Z``, ``y = Y / Z`` and ``r2 = x^2 + y^2``::

        radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
        xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2
        yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2

    ``D = k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]`` in OpenCV's order (the sensor
    tilt ``tx ty`` must be zero); no ``D`` or all zeros is the ideal pinhole.
``fisheye``
    OpenCV's equidistant (Kannala-Brandt) model: ``theta`` the angle from the optical axis,
    ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``,
    ``(xd, yd) = theta_d (X, Y) / sqrt(X^2 + Y^2)``; ``D = k1 k2 k3 k4``.
``mei``
    The unified omnidirectional model (Mei and Rives 2007): ``Xs = X / |X|``,
    ``x = Xs_x / (Xs_z + xi)``, ``y = Xs_y / (Xs_z + xi)``, then the radial-tangential step
    above with ``D = k1 k2 p1 p2 [k3]``.

All then apply ``K``: ``u = fx xd + s yd + cx``, ``v = fy yd + cy``. Pixels follow
docs/conventions.md section 1: ``(u, v)`` with the origin at the centre of the top-left pixel,
so a point is in the image when ``0 <= u <= width - 1`` and ``0 <= v <= height - 1``.

A point is *valid* when it is in the model's domain: farther than ``z_min`` (along the optical
axis for the pinhole, in range for the others) and where the model is one-to-one. A distortion
polynomial turns back beyond some radius: points past it fold back into the image at the wrong
place, so the largest radius (or angle) where the radial map is still increasing is found once,
from D, when the camera is made, and points beyond it are invalid. For the Mei model the sphere
projection also turns back where ``Xs_z < -1 / xi`` (``xi > 1``) and is undefined where
``Xs_z + xi <= 0``. Tangential terms are not considered for that limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.polynomial import polynomial as npoly

from .geometry import check_rigid, transform_points

MODELS = ("pinhole", "fisheye", "mei")

#: Model ids in :meth:`Camera.kernel_params` (column :data:`P_MODEL`).
PINHOLE_IDEAL, PINHOLE_RADTAN, FISHEYE, MEI = 0, 1, 2, 3

# Columns of the per-camera parameter row read by the evaluation kernel.
P_MODEL, P_FX, P_FY, P_CX, P_CY, P_SKEW, P_XI = 0, 1, 2, 3, 4, 5, 6
P_K1 = 7            # k1..k6 in columns 7..12
P_P1, P_P2 = 13, 14
P_S1 = 15           # s1..s4 in columns 15..18
P_LIMIT = 19        # r2 limit (pinhole, mei) or theta limit (fisheye); inf when unbounded
P_ZS_MIN = 20       # mei: a ray is valid when Xs_z > this
N_PARAMS = 21

#: Default minimum depth (m) of a valid point.
Z_MIN = 0.1

_FISHEYE_D = 4
_MEI_D = (4, 5)
_PINHOLE_D = (4, 5, 8, 12, 14)
#: Samples of the radial map used to start its inversion (see :meth:`Camera.unproject`).
_TABLE = 4096
#: Largest normalised radius searched when the radial map never turns back (89.99994 deg).
_R_HUGE = 1e6
#: Most steps of an inversion: from the table's start Newton needs two or three; a radial map
#: that saturates (so the table spans a huge radius) falls back on bisection, one bit a step.
_NEWTON_STEPS = 64


#: The largest Mei (unified) ``xi``, the distance of the projection centre from the unit
#: sphere's centre: about 1 for catadioptric mirrors, up to about 3 for fisheye lenses. A value
#: a hundred times a real lens's is a typing error (1e300 overflowed the arithmetic).
MAX_XI = 100.0


@dataclass(frozen=True, eq=False)
class Camera:
    """A camera's intrinsics: ``K``, image size and lens model.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Intrinsic matrix in pixels, last row ``[0, 0, 1]`` (a skew ``K[0, 1]`` is honoured).
    width, height : int
        Image size in pixels.
    model : {"pinhole", "fisheye", "mei"}
        Lens model (see the module docstring).
    D : sequence of float, optional
        Distortion coefficients in the model's order; stored as a tuple (``()`` for none).
    xi : float
        Mei mirror parameter, finite and ``>= 0`` (ignored by the other models).
    mount : array_like, shape (4, 4), optional
        For cameras of one rig calibrated at once (one extrinsic shared by all): this camera's
        pose relative to the camera whose ``T_cam_lidar`` is estimated, ``X_this = mount @
        X_that``; :func:`project` applies ``mount @ T_cam_lidar``. None (the default): this
        camera is the one estimated.

    Notes
    -----
    Frozen, hashed and compared by identity (the arrays make value equality ambiguous).
    ``r_limit`` is the normalised radius (pinhole, mei: on the undistorted plane) or the angle
    in radians (fisheye) where the radial map stops increasing; ``inf`` when it never does.
    """

    K: np.ndarray
    width: int
    height: int
    model: str = "pinhole"
    D: tuple | None = None
    xi: float = 0.0
    mount: np.ndarray | None = field(default=None, repr=False)
    r_limit: float = field(init=False, repr=False)
    _coeffs: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        K = np.array(self.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ValueError(f"K must be a finite 3x3 matrix, got {K!r}")
        if not np.allclose(K[2], [0, 0, 1]) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[1, 0] != 0:
            raise ValueError("K must have positive focal lengths, K[1, 0] = 0 and last row "
                             "[0, 0, 1]")
        K.setflags(write=False)
        model = str(self.model)
        if model not in MODELS:
            raise ValueError(f"camera model {model!r} is not one of {', '.join(MODELS)}")
        D = () if self.D is None else tuple(float(d) for d in np.ravel(self.D))
        if not all(np.isfinite(D)):
            raise ValueError(f"D must be finite, got {D}")
        xi = float(self.xi)
        if not np.isfinite(xi) or xi < 0:
            raise ValueError(f"xi must be a finite number >= 0, got {self.xi!r}")
        if xi > MAX_XI:
            raise ValueError(f"xi must be at most {MAX_XI:g}, got {self.xi!r}")
        if self.mount is not None:
            mount = check_rigid(self.mount, "camera", key="mount")
            mount.setflags(write=False)
            object.__setattr__(self, "mount", mount)
        c = np.zeros(14)              # k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty (OpenCV order)
        if model == "pinhole":
            if D and len(D) not in _PINHOLE_D:
                raise ValueError(f"a pinhole D holds 4, 5, 8, 12 or 14 coefficients, got {len(D)}")
            c[:len(D)] = D
            if np.any(c[12:]):
                raise ValueError("the tilted-sensor coefficients tx, ty of D are not supported "
                                 "(they must be zero)")
            if not np.any(c):
                D = ()
        elif model == "fisheye":
            if D and len(D) != _FISHEYE_D:
                raise ValueError(f"a fisheye D holds the 4 coefficients k1..k4, got {len(D)}")
            c[:len(D)] = D                 # k1..k4 in the first four slots for this model
        else:
            if D and len(D) not in _MEI_D:
                raise ValueError(f"a Mei D holds k1, k2, p1, p2[, k3], got {len(D)}")
            c[:len(D)] = D
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "D", D)
        object.__setattr__(self, "xi", xi)
        object.__setattr__(self, "_coeffs", c)
        object.__setattr__(self, "r_limit", _monotonic_limit(model, c))

    # --- the model's constants ---------------------------------------------------------------

    @property
    def ideal(self) -> bool:
        """True for a pinhole without distortion (projection is ``K @ X / Z``)."""
        return self.model == "pinhole" and not self.D

    @property
    def kind(self) -> int:
        """The kernel's model id: PINHOLE_IDEAL, PINHOLE_RADTAN, FISHEYE or MEI."""
        if self.model == "pinhole":
            return PINHOLE_IDEAL if self.ideal else PINHOLE_RADTAN
        return FISHEYE if self.model == "fisheye" else MEI

    @property
    def zs_min(self) -> float:
        """Mei: the smallest ``Xs_z`` (exclusive) of a valid ray, ``-min(xi, 1 / xi)``."""
        if self.xi == 0.0:
            return 0.0
        return -min(self.xi, 1.0 / self.xi)

    def _radtan(self):
        """``k1..k6, p1, p2, s1..s4`` for the radial-tangential step."""
        c = self._coeffs
        return (c[0], c[1], c[4], c[5], c[6], c[7]), (c[2], c[3]), tuple(c[8:12])

    def kernel_params(self) -> np.ndarray:
        """The camera as one float64 row of :data:`N_PARAMS` values for the numba kernel."""
        p = np.zeros(N_PARAMS)
        p[P_MODEL] = self.kind
        p[P_FX], p[P_FY] = self.K[0, 0], self.K[1, 1]
        p[P_CX], p[P_CY], p[P_SKEW] = self.K[0, 2], self.K[1, 2], self.K[0, 1]
        p[P_XI] = self.xi
        if self.model == "fisheye":
            p[P_K1:P_K1 + 4] = self._coeffs[:4]
            p[P_LIMIT] = self.r_limit
        else:
            (k, pp, s) = self._radtan()
            p[P_K1:P_K1 + 6] = k
            p[P_P1], p[P_P2] = pp
            p[P_S1:P_S1 + 4] = s
            p[P_LIMIT] = self.r_limit ** 2
        p[P_ZS_MIN] = self.zs_min
        return p

    def to_dict(self) -> dict:
        """JSON-ready description: ``model``, ``K``, ``D``, ``xi``, ``width``, ``height``
        (and ``mount`` when set)."""
        d = {"model": self.model, "K": self.K.tolist(), "D": list(self.D or ()), "xi": self.xi,
             "width": self.width, "height": self.height}
        if self.mount is not None:
            d["mount"] = self.mount.tolist()
        return d

    def mounted(self, T_cam_lidar: np.ndarray) -> np.ndarray:
        """The extrinsic(s) this camera projects with: ``mount @ T_cam_lidar`` for any batch
        (..., 4, 4) or (..., 3, 4) (``T_cam_lidar`` itself without a mount).

        Parameters
        ----------
        T_cam_lidar : ndarray, shape (..., 4, 4) or (..., 3, 4)
            Extrinsics (LiDAR -> the camera the mount is relative to; m).

        Returns
        -------
        ndarray
            The extrinsics of this camera, of ``T_cam_lidar``'s shape.
        """
        return T_cam_lidar if self.mount is None else compose_mount(self.mount, T_cam_lidar)

    # --- projection --------------------------------------------------------------------------

    def project_camera_points(self, Xc: np.ndarray, z_min: float = Z_MIN
                              ) -> tuple[np.ndarray, np.ndarray]:
        """Project points given in the camera frame.

        Parameters
        ----------
        Xc : ndarray, shape (..., 3)
            Points in the camera frame (x right, y down, z forward), metres.
        z_min : float
            Pinhole: the smallest depth ``Z`` (exclusive) of a valid point. Fisheye and Mei
            (which see behind the image plane): the smallest range ``|X|``.

        Returns
        -------
        uv : ndarray, shape (..., 2), float64
            Pixel coordinates; NaN where the point is not valid.
        valid : ndarray of bool, shape (...)
            The point is in the model's domain (see the module docstring); whether it lands
            inside the image is :func:`in_image`'s business.
        """
        Xc = np.asarray(Xc, dtype=np.float64)
        u, v, valid = self.project_xyz(Xc[..., 0], Xc[..., 1], Xc[..., 2], z_min)
        uv = np.stack([u, v], axis=-1)
        uv[~valid] = np.nan
        return uv, valid

    def project_xyz(self, X: np.ndarray, Y: np.ndarray, Z: np.ndarray, z_min: float = Z_MIN
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project_camera_points` on separate coordinate arrays, for batched callers.

        Parameters
        ----------
        X, Y, Z : ndarray, shape (...)
            Camera-frame coordinates in metres, all of one shape.
        z_min : float

        Returns
        -------
        u, v : ndarray, shape (...), float64
            Pixel coordinates, meaningless (not NaN-filled) where ``valid`` is False.
        valid : ndarray of bool, shape (...)
        """
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if self.model == "pinhole":
                valid = Z > z_min
                iz = 1.0 / Z
                x, y = X * iz, Y * iz
                if not self.ideal:
                    r2 = x * x + y * y
                    valid &= r2 < self.r_limit ** 2
                    x, y = self._distort(x, y, r2)
            elif self.model == "fisheye":
                rho2 = X * X + Y * Y
                rho = np.sqrt(rho2)
                theta = np.arctan2(rho, Z)
                valid = (rho2 + Z * Z > z_min * z_min) & (theta < self.r_limit)
                t2 = theta * theta
                k1, k2, k3, k4 = self._coeffs[:4]
                theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
                scale = np.where(rho > 0, theta_d / rho, 0.0)
                x, y = scale * X, scale * Y
            else:
                n2 = X * X + Y * Y + Z * Z
                norm = np.sqrt(n2)
                # Xs_z > zs_min and Xs / (Xs_z + xi) written without dividing by |X| first.
                valid = (n2 > z_min * z_min) & (Z > self.zs_min * norm)
                iden = 1.0 / (Z + self.xi * norm)
                x, y = X * iden, Y * iden
                r2 = x * x + y * y
                valid &= r2 < self.r_limit ** 2
                x, y = self._distort(x, y, r2)
            u = self.K[0, 0] * x + self.K[0, 1] * y + self.K[0, 2]
            v = self.K[1, 1] * y + self.K[1, 2]
            valid &= np.isfinite(u) & np.isfinite(v)
        return u, v, valid

    def _distort(self, x, y, r2):
        """The radial-tangential step on normalised coordinates (arrays of one shape)."""
        (k1, k2, k3, k4, k5, k6), (p1, p2), (s1, s2, s3, s4) = self._radtan()
        r4 = r2 * r2
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xy = x * y
        xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * xy + s3 * r2 + s4 * r4
        return xd, yd

    def _distort_jacobian(self, x, y):
        """``(xd, yd)`` and the 2x2 Jacobian ``d(xd, yd) / d(x, y)`` as four arrays."""
        (k1, k2, k3, k4, k5, k6), (p1, p2), (s1, s2, s3, s4) = self._radtan()
        r2 = x * x + y * y
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        R = num / den
        dR = (dnum * den - num * dden) / (den * den)           # d radial / d r2
        ts_x = s1 + 2 * s2 * r2                                 # d(s1 r2 + s2 r2^2) / d r2
        ts_y = s3 + 2 * s4 * r2
        xd, yd = self._distort(x, y, r2)
        a = R + 2 * x * x * dR + 2 * p1 * y + 6 * p2 * x + 2 * x * ts_x
        b = 2 * x * y * dR + 2 * p1 * x + 2 * p2 * y + 2 * y * ts_x
        c = 2 * x * y * dR + 2 * p1 * x + 2 * p2 * y + 2 * x * ts_y
        d = R + 2 * y * y * dR + 6 * p1 * y + 2 * p2 * x + 2 * y * ts_y
        return xd, yd, a, b, c, d

    # --- unprojection ------------------------------------------------------------------------

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Unit rays of pixels: the inverse of :meth:`project_camera_points`.

        Parameters
        ----------
        uv : ndarray, shape (..., 2)
            Pixel coordinates.

        Returns
        -------
        ndarray, shape (..., 3), float64
            Unit direction in the camera frame of the valid point that projects to each pixel;
            NaN for pixels no valid point reaches (beyond the monotonic limit, or outside the
            model's domain). The distortion is inverted iteratively (a monotonic 1-D
            inversion of the radial map, then Newton steps on the full model) to machine
            precision.
        """
        uv = np.asarray(uv, dtype=np.float64)
        fx, s, cx = self.K[0]
        fy, cy = self.K[1, 1], self.K[1, 2]
        yd = (uv[..., 1] - cy) / fy
        xd = (uv[..., 0] - cx - s * yd) / fx
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if self.model == "fisheye":
                theta_d = np.hypot(xd, yd)
                theta, ok = self._invert_radial(theta_d)
                sin_t = np.sin(theta)
                scale = np.where(theta_d > 0, sin_t / theta_d, 0.0)
                ray = np.stack([scale * xd, scale * yd, np.cos(theta)], axis=-1)
            else:
                if self.ideal:
                    x, y, ok = xd, yd, np.ones(xd.shape, bool)
                else:
                    x, y, ok = self._undistort(xd, yd)
                if self.model == "pinhole":
                    ray = np.stack([x, y, np.ones_like(x)], axis=-1)
                    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
                else:
                    r2 = x * x + y * y
                    disc = 1 + (1 - self.xi ** 2) * r2
                    ok &= disc >= 0
                    fac = (self.xi + np.sqrt(np.maximum(disc, 0.0))) / (1 + r2)
                    ray = np.stack([fac * x, fac * y, fac - self.xi], axis=-1)
        ok &= np.isfinite(ray).all(axis=-1)
        ray[~ok] = np.nan
        # Only rays the forward model accepts (the round trip is what makes it an inverse).
        _, valid = self.project_camera_points(np.where(ok[..., None], ray, 0.0), z_min=0.0)
        ray[~valid] = np.nan
        return ray

    def _radial(self, r):
        """The radial map and its derivative: ``g(r) = r radial(r^2)`` (pinhole, mei) or
        ``theta_d(theta)`` (fisheye), for r >= 0."""
        c = self._coeffs
        s = r * r
        if self.model == "fisheye":
            k1, k2, k3, k4 = c[:4]
            g = r * (1 + s * (k1 + s * (k2 + s * (k3 + s * k4))))
            dg = 1 + s * (3 * k1 + s * (5 * k2 + s * (7 * k3 + s * 9 * k4)))
            return g, dg
        (k1, k2, k3, k4, k5, k6), _, _ = self._radtan()
        num = 1 + s * (k1 + s * (k2 + s * k3))
        den = 1 + s * (k4 + s * (k5 + s * k6))
        dnum = k1 + s * (2 * k2 + 3 * k3 * s)
        dden = k4 + s * (2 * k5 + 3 * k6 * s)
        g = r * num / den
        dg = num / den + 2 * s * (dnum * den - num * dden) / (den * den)
        return g, dg

    def _invert_radial(self, rd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The radius r in ``[0, r_limit)`` with ``g(r) = rd``, and where one exists."""
        top = self.r_limit
        if not np.isfinite(top):
            # g increases without turning back: grow the table until it covers the input.
            need = float(np.nanmax(rd, initial=0.0))
            top = 1.0
            while self._radial(np.array(top))[0] < need and top < _R_HUGE:
                top *= 2.0
        r_tab = np.linspace(0.0, top, _TABLE + 1)
        g_tab = self._radial(r_tab)[0]
        shape = np.shape(rd)
        rd = np.ravel(rd)
        ok = np.isfinite(rd) & (rd >= 0) & (rd < g_tab[-1])
        rr = np.where(ok, rd, 0.0)
        i = np.clip(np.searchsorted(g_tab, rr, side="right") - 1, 0, _TABLE - 1)
        lo, hi = r_tab[i], r_tab[i + 1]
        g_lo, g_hi = g_tab[i], g_tab[i + 1]
        r = lo + (hi - lo) * np.where(g_hi > g_lo, (rr - g_lo) / (g_hi - g_lo), 0.0)
        # Newton steps kept inside the bracket (bisection when a step would leave it), on the
        # radii not yet converged.
        act = np.flatnonzero(ok)
        lo, hi = lo[act], hi[act]
        for _ in range(_NEWTON_STEPS):
            if not act.size:
                break
            ra = r[act]
            g, dg = self._radial(ra)
            f = g - rr[act]
            lo = np.where(f <= 0, ra, lo)
            hi = np.where(f > 0, ra, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = ra - f / dg
            inside = (step >= lo) & (step <= hi) & np.isfinite(step)
            new = np.where(inside, step, 0.5 * (lo + hi))
            r[act] = new
            busy = np.abs(new - ra) > 4e-16 * np.maximum(1.0, ra)
            act, lo, hi = act[busy], lo[busy], hi[busy]
        return r.reshape(shape), ok.reshape(shape)

    def _undistort(self, xd: np.ndarray, yd: np.ndarray):
        """Normalised undistorted ``(x, y)`` with ``distort(x, y) = (xd, yd)``, and where one
        exists inside the monotonic radius."""
        rd = np.hypot(xd, yd)
        r, ok = self._invert_radial(rd)
        scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
        x, y = xd * scale, yd * scale
        (p1, p2), s = self._radtan()[1:]
        if p1 or p2 or any(s):
            # Newton on the full model from the radial solution, on the points not converged.
            shape = x.shape
            x, y = x.ravel().copy(), y.ravel().copy()
            xdf, ydf = np.ravel(xd), np.ravel(yd)
            act = np.flatnonzero(ok.ravel())
            for _ in range(_NEWTON_STEPS):
                if not act.size:
                    break
                xa, ya = x[act], y[act]
                fx, fy, a, b, c, d = self._distort_jacobian(xa, ya)
                ex, ey = fx - xdf[act], fy - ydf[act]
                with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                    det = a * d - b * c
                    dx = (d * ex - b * ey) / det
                    dy = (a * ey - c * ex) / det
                x[act], y[act] = xa - dx, ya - dy
                busy = np.isfinite(dx) & (np.abs(dx) + np.abs(dy)
                                          > 1e-15 * np.maximum(1.0, np.abs(xa)))
                act = act[busy]
            x, y = x.reshape(shape), y.reshape(shape)
            with np.errstate(invalid="ignore", over="ignore"):
                fx, fy = self._distort(x, y, x * x + y * y)
                ok &= np.hypot(fx - xd, fy - yd) < 1e-12
        with np.errstate(invalid="ignore", over="ignore"):
            ok &= x * x + y * y < self.r_limit ** 2
        return x, y, ok

    @cached_property
    def valid_pixels(self) -> np.ndarray:
        """Pixels some valid point projects to, (height, width) bool (read-only, cached).

        All True for an ideal pinhole; False where the lens model cannot be inverted (beyond
        the radius where the distortion folds back), which read_frame masks automatically.
        """
        if self.ideal:
            out = np.ones((self.height, self.width), dtype=bool)
        else:
            v, u = np.mgrid[0:self.height, 0:self.width].astype(np.float64)
            out = np.isfinite(self.unproject(np.stack([u, v], axis=-1))).all(axis=-1)
        out.setflags(write=False)
        return out


def _smallest_positive_root(coeffs: np.ndarray) -> float:
    """The smallest positive real root of a polynomial (coefficients low to high), or inf."""
    c = np.trim_zeros(np.asarray(coeffs, dtype=np.float64), "b")
    if len(c) < 2:
        return np.inf
    try:
        # A subnormal leading coefficient (e.g. D = [0, 0, 0, 0, 5e-324]) overflows the
        # companion matrix; its roots lie at infinity, which is what is meant.
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            roots = npoly.polyroots(c)
    except np.linalg.LinAlgError:  # pragma: no cover - only for degenerate coefficient sets
        return np.inf
    roots = roots[np.isfinite(roots)]
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))].real
    real = real[real > 0]
    return float(real.min()) if len(real) else np.inf


def _monotonic_limit(model: str, c: np.ndarray) -> float:
    """Where the radial map stops increasing: a normalised radius (pinhole, mei) or an angle in
    radians (fisheye, at most pi); inf when it increases everywhere.

    The derivative of the radial map is a polynomial in ``s = r^2`` (for the rational pinhole
    model, the numerator of the derivative, with the denominator's zeros as poles); its
    smallest positive root is the limit.
    """
    if model == "fisheye":
        k1, k2, k3, k4 = c[:4]
        s = _smallest_positive_root(np.array([1.0, 3 * k1, 5 * k2, 7 * k3, 9 * k4]))
        return float(min(np.sqrt(s), np.pi))
    k1, k2, k3, k4, k5, k6 = c[0], c[1], c[4], c[5], c[6], c[7]
    num = np.array([1.0, k1, k2, k3])
    den = np.array([1.0, k4, k5, k6])
    # d/dr [r num(s) / den(s)] has the sign of (num + 2 s num') den - 2 s num den'.
    a = npoly.polymul([1.0, 3 * k1, 5 * k2, 7 * k3], den)
    b: np.ndarray = npoly.polymul(npoly.polymul([0.0, 2.0], num), npoly.polyder(den))
    s = min(_smallest_positive_root(npoly.polysub(a, b)), _smallest_positive_root(den))
    return float(np.sqrt(s))


def project(points: np.ndarray, camera: Camera, T_cam_lidar: np.ndarray,
            z_min: float = Z_MIN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project LiDAR points into the image through the camera's model.

    The one projection of LiDAR points used by the features, the objective's oracles, the
    decision, the depth map and the figures (the numba kernels and the page's script repeat
    its arithmetic and are tested against it).

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        LiDAR points in metres (columns beyond the third are ignored).
    camera : Camera
    T_cam_lidar : ndarray, shape (4, 4), or a batch (..., 4, 4) or (..., 3, 4)
        (the camera's ``mount`` applies on top).
    z_min : float
        Minimum depth (pinhole) or range (fisheye, Mei) in metres of a valid point.

    Returns
    -------
    uv : ndarray, shape (..., N, 2)
        Pixel coordinates (NaN where the point is not valid for the model).
    z : ndarray, shape (..., N)
        Depth along the optical axis in metres.
    visible : ndarray of bool, shape (..., N)
        Valid for the model and inside the image.

    Examples
    --------
    A point 10 m ahead of a camera whose optical axis is the LiDAR's x (``T_cam_lidar``
    maps LiDAR x, y, z to camera z, -x, -y) lands on the principal point; one 1 m to its
    left, 100 px (f / 10) left of it:

    >>> import numpy as np
    >>> from paretocal.camera import Camera, project
    >>> cam = Camera(K=[[1000.0, 0, 640], [0, 1000.0, 360], [0, 0, 1]], width=1280, height=720)
    >>> T = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    >>> uv, z, visible = project(np.array([[10.0, 0, 0], [10.0, 1.0, 0]]), cam, T)
    >>> print(uv, z, visible)
    [[640. 360.]
     [540. 360.]] [10. 10.] [ True  True]
    """
    Xc = transform_points(camera.mounted(T_cam_lidar), points)
    uv, valid = camera.project_camera_points(Xc, z_min)
    visible = valid & in_image(uv, camera.width, camera.height)
    return uv, Xc[..., 2], visible


def compose_mount(mount: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``mount @ T`` for a (4, 4) ``mount`` and any batch ``T`` (..., 4, 4) or (..., 3, 4);
    the result has ``T``'s shape.

    Parameters
    ----------
    mount : ndarray, shape (4, 4)
        A camera's pose relative to another camera of the rig (m).
    T : array_like, shape (..., 4, 4) or (..., 3, 4)
        Extrinsics of that other camera (m).

    Returns
    -------
    ndarray, float64
        ``mount @ T``, of ``T``'s shape.
    """
    T = np.asarray(T, dtype=np.float64)
    out = T.copy()
    out[..., :3, :3] = mount[:3, :3] @ T[..., :3, :3]
    out[..., :3, 3] = T[..., :3, 3] @ mount[:3, :3].T + mount[:3, 3]
    return out


def in_image(uv: np.ndarray, width: int, height: int, margin: float = 0.0) -> np.ndarray:
    """Mask of pixel coordinates (..., 2) inside the image grown by ``margin`` pixels (NaN: no).

    Parameters
    ----------
    uv : ndarray, shape (..., 2)
        Pixel coordinates (u, v) (docs/conventions.md section 1); NaN for invalid points.
    width, height : int
        The image's size (px).
    margin : float
        Pixels by which the image is grown on every side.

    Returns
    -------
    ndarray of bool, shape (...)
    """
    u, v = uv[..., 0], uv[..., 1]
    with np.errstate(invalid="ignore"):
        return ((u >= -margin) & (u <= width - 1 + margin)
                & (v >= -margin) & (v <= height - 1 + margin))
