"""The frames as the objective needs them: the initial extrinsic, the LiDAR located in its cloud,
the laser rings of every sweep, motion during the sweeps compensated, and what the input files
offered (result.json ``inputs``)."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from .config import Settings
from .errors import InputError
from .features.prepare import frame_rings, view_mask
from .lidar.rings import MIN_PURITY, MIN_RINGS, Rings
from .geometry import invert
from .io.frame import Frame

log = logging.getLogger(__name__)


def resolve_init(frames: list[Frame], T_init: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The initial extrinsic and the reference: ``--init`` wins; the dataset's is the fallback.

    The reference is returned only when an initial guess was given independently of it, so the
    reported error is never trivially zero.
    """
    T_ref = frames[0].T_ref
    if T_ref is not None and any(f.T_ref is None or not np.allclose(f.T_ref, T_ref, atol=1e-9)
                                 for f in frames):
        log.warning("frames carry different reference extrinsics; the first frame's is used")
    if T_init is None:
        if T_ref is None:
            raise InputError("no initial extrinsic: the source has no T_cam_lidar; pass --init")
        return T_ref.copy(), None
    return np.asarray(T_init, dtype=np.float64), T_ref


@dataclasses.dataclass(frozen=True)
class MotionReport:
    """What :func:`compensate_motion` did with the sweeps' motion.

    Attributes
    ----------
    compensated : bool
        Whether the sweeps were de-skewed.
    reason : str or None
        Why not, in words.
    speed_mps, speed_spread_mps : float or None
        The estimated speed (m/s) and its spread over the pairs; None when nothing was
        estimated.
    v_mps : tuple of float, shape (3,), or None
        The velocity in the LiDAR frame (m/s).
    yaw_rate_dps : float or None
        The turn rate (deg/s).
    observable_xyz : tuple of bool, shape (3,), or None
        The axes the scan-to-scan registration constrains.
    median_share_xyz : tuple of float, shape (3,), or None
        Each axis's median share of the translation information.
    time_offset_s : float or None
        The time offset applied to the sweeps' centre times (s).
    skew_m : float or None
        How far the sensor moves during the longest sweep (m).
    max_shift_m : float or None
        The largest displacement the de-skew applied to a point (m).
    """

    compensated: bool
    reason: str | None = None
    speed_mps: float | None = None
    speed_spread_mps: float | None = None
    v_mps: tuple | None = None
    yaw_rate_dps: float | None = None
    observable_xyz: tuple | None = None
    median_share_xyz: tuple | None = None
    time_offset_s: float | None = None
    skew_m: float | None = None
    max_shift_m: float | None = None

    def to_dict(self) -> dict:
        """As ``result.json``'s ``motion`` writes it: the estimate's figures (when there is
        one), then whether it was applied, and why not or how far it moved a point."""
        out: dict = {}
        if self.speed_mps is not None:
            out.update(speed_mps=self.speed_mps, speed_spread_mps=self.speed_spread_mps,
                       v_mps=list(self.v_mps or ()), yaw_rate_dps=self.yaw_rate_dps,
                       observable_xyz=list(self.observable_xyz or ()),
                       median_share_xyz=list(self.median_share_xyz or ()),
                       time_offset_s=self.time_offset_s, skew_m=self.skew_m)
        out["compensated"] = bool(self.compensated)
        if self.reason is not None:
            out["reason"] = self.reason
        if self.max_shift_m is not None:
            out["max_shift_m"] = self.max_shift_m
        return out


def compensate_motion(frames: list[Frame], settings: Settings) -> tuple[list[Frame], MotionReport]:
    """De-skew every sweep to its image time with ego-motion estimated from the sequence.

    A spinning LiDAR on a moving vehicle stores each point at its own time (a 10 Hz sweep at
    30 m/s spans 3 m); the image is exposed at one time. When every cloud has per-point time,
    the twist is estimated by registering consecutive sweeps (:func:`paretocal.lidar.motion.
    estimate_motion`) and each sweep is expressed at its centre time plus
    ``settings.motion.time_offset_s``. The motion is applied only when the registration
    constrains it along every axis; otherwise the sweeps stay as recorded and the returned
    record says why.

    Returns
    -------
    frames : list of Frame
        De-skewed copies (points in the same order), or the input frames.
    info : MotionReport
    """
    import dataclasses

    from .lidar.motion import estimate_motion
    from .lidar.trajectory import deskew, sweep_centre

    m = settings.motion
    if m.deskew == "off":
        return frames, MotionReport(False, "de-skewing is off (motion.deskew)")
    times = [f.time for f in frames if f.time is not None]
    if len(times) < len(frames):
        return frames, MotionReport(False, "the clouds carry no per-point time: motion during a "
                                           "sweep is not compensated (a moving vehicle's clouds "
                                           "are skewed)")
    if len(frames) < 2:
        return frames, MotionReport(False, "one frame: ego-motion needs a sequence of sweeps")
    order = np.argsort([float(np.median(t)) for t in times], kind="stable")
    clouds = [(np.asarray(frames[k].points[:, :3], dtype=np.float64), times[k])
              for k in order]
    try:
        est = estimate_motion(clouds, per_frame=m.per_frame, points=m.points,
                                 seed=settings.search.seed)
    except ValueError as exc:
        return frames, MotionReport(False, f"ego-motion estimate failed: {exc}")
    sweep = max(float(np.ptp(t)) for t in times)
    info = MotionReport(
        False, speed_mps=round(float(est.speed), 3),
        speed_spread_mps=round(float(est.speed_spread), 3),
        v_mps=tuple(round(float(v), 3) for v in est.twist.v),
        yaw_rate_dps=round(float(np.degrees(est.twist.w[2])), 3),
        observable_xyz=tuple(bool(v) for v in est.observable),
        median_share_xyz=tuple(round(float(v), 4) for v in np.median(est.share, axis=0)),
        time_offset_s=m.time_offset_s, skew_m=round(float(est.speed) * sweep, 3))
    if not est.compensable:
        axes = "".join(a for a, ok in zip("xyz", est.observable) if not ok)
        return frames, dataclasses.replace(
            info, reason=f"ego-motion is not observable along {axes} (the scene does not "
                         "constrain scan-to-scan registration there): not compensated")
    out = list(frames)
    shift = 0.0
    for j, k in enumerate(order):
        f = frames[k]
        t_ref = sweep_centre(times[k]) + m.time_offset_s
        xyz = deskew(f.points[:, :3], times[k], t_ref, est.frame_motion(j))
        shift = max(shift, float(np.max(np.linalg.norm(xyz - f.points[:, :3], axis=1))))
        pts = f.points.copy()
        pts[:, :3] = xyz
        out[k] = dataclasses.replace(f, points=np.ascontiguousarray(pts, dtype=np.float32))
    info = dataclasses.replace(info, compensated=True, max_shift_m=round(shift, 3))
    log.info("de-skewed %d sweeps: %.2f m/s, largest shift %.2f m", len(frames), est.speed,
             shift)
    return out, info


def warn_unlocated(frames: list[Frame], info: dict) -> None:
    """Tell the user when the LiDAR's pose is needed and could not be found (``info`` from
    :func:`locate_lidar`); called after the input checks so that bad input reads one line."""
    if info.get("source") != "unknown":
        return
    log.warning("%s: the returns do not lie on rings about the cloud's origin and the LiDAR's "
                "pose could not be estimated (%s); rings and edges are taken about the cloud's "
                "origin and may be poor: give lidar_pose in calib.yaml", frames[0].points_path,
                info.get("reason", ""))


def locate_lidar(frames: list[Frame],
                 settings: Settings) -> tuple[list[Frame], dict, Rings | None]:
    """The LiDAR's pose in the clouds' frame: given, not needed, or estimated from a sweep.

    Ring geometry is taken about the sensor's own origin and axis. A pose in calib.yaml
    (``lidar_pose``) is used as given; a cloud with a ring field, or whose rings fit the line
    model about its own origin, needs none. Otherwise (a cloud stored in a vehicle frame) the
    pose is estimated from the first sweep
    (:func:`~paretocal.lidar.sensor.estimate_sensor_pose`) and, when the rings fit the line
    model in the estimated frame, given to every frame (one rig, one mount).

    Returns
    -------
    frames : list of Frame
        With ``sensor_pose`` set when it was estimated.
    info : dict
        ``source``: "calib.yaml", "ring field", "cloud origin", "estimated" or "unknown",
        with the estimate's summary and the rings' purity where they were checked.
    first_rings : Rings or None
        The first frame's rings about the pose returned, when they were recovered here (for
        :func:`sweep_rings`, which then need not recover them again).
    """
    import dataclasses

    from .lidar.sensor import estimate_sensor_pose

    if any(f.sensor_pose is not None for f in frames):
        return frames, {"source": "calib.yaml"}, None
    if settings.features.ring_method in ("field", "scan", "elevation"):
        return frames, {"source": "cloud origin", "note": "ring method "
                        f"{settings.features.ring_method!r} asked for"}, None
    first = frames[0]
    if first.ring is not None:
        return frames, {"source": "ring field"}, None
    rng = np.random.default_rng(np.random.SeedSequence([settings.search.seed, 2]))
    here = frame_rings(first, settings.features, rng)
    if here.purity >= MIN_PURITY and here.n_rings >= MIN_RINGS:
        return frames, {"source": "cloud origin", "purity": round(float(here.purity), 4)}, here
    est = estimate_sensor_pose(first.points, rng)
    if est is None or not est.ok:
        why = "no ground plane to start from" if est is None else "; ".join(est.notes)
        return frames, {"source": "unknown", "purity_at_origin": round(float(here.purity), 4),
                        "estimate": None if est is None else est.summary(), "reason": why}, here
    moved = [dataclasses.replace(f, sensor_pose=est.pose) for f in frames]
    there = frame_rings(moved[0], settings.features, rng)
    info = {"source": "estimated", "estimate": est.summary(),
            "purity_at_origin": round(float(here.purity), 4),
            "purity": round(float(there.purity), 4), "n_rings": int(there.n_rings)}
    if there.purity < MIN_PURITY or there.n_rings < MIN_RINGS:
        info.update(source="unknown", reason="the rings do not fit the line model in the "
                    "estimated frame either")
        return frames, info, here
    p = est.pose[:3, 3]
    log.info("%s: the LiDAR's pose was estimated from the sweep: at (%.2f, %.2f, %.2f) m in "
             "the cloud's frame, axis tilted %.2f deg (%d rings, purity %.3f); give "
             "lidar_pose in calib.yaml to set it", first.points_path, p[0], p[1], p[2],
             est.tilt_deg, there.n_rings, there.purity)
    return moved, info, there


def sweep_rings(frames: list[Frame], settings: Settings,
                first: Rings | None = None, views=None) -> list[Rings]:
    """The rings of every frame's sweep (see :func:`~paretocal.features.prepare.frame_rings`);
    :func:`warn_rings` tells the user about the implausible ones.

    One sensor keeps its lasers' lines from sweep to sweep: once a sweep's rings were found
    by the line search and are plausible, the next sweeps are labelled with its line model
    first (measured on the KITTI drive in firing and random order: 0.4 s a sweep instead of
    1.5-2.7 s, every point on its true ring as before); a sweep the model does not fit is
    searched afresh. ``first``: the first frame's rings when already known (from
    :func:`locate_lidar`). ``views``: pairs ``(Camera, T_cam_lidar)`` the features will be
    taken at; each sweep's rings are then judged on the returns near those views
    (:func:`~paretocal.features.prepare.view_mask`): a sweep motion-compensated into one
    frame fits its lasers' cones only near the time it was compensated to, which is the time
    of the camera's view."""
    seq = np.random.SeedSequence([settings.search.seed, 1])
    out, model = [], None
    for k, (f, child) in enumerate(zip(frames, seq.spawn(len(frames)))):
        view = None if views is None else view_mask(f, views, settings.features)
        r = (first if k == 0 and first is not None else
             frame_rings(f, settings.features, np.random.default_rng(child), model, view))
        if r.method == "lines" and r.n_rings >= MIN_RINGS and r.purity >= MIN_PURITY:
            model = r
        out.append(r)
    return out


def warn_rings(frames: list[Frame], rings: list[Rings]) -> None:
    """One warning per ring problem (not per frame), naming a file and what to do.

    Rings that do not fit the line model (purity below
    :data:`~paretocal.lidar.rings.MIN_PURITY`) are still used, but a wrong ring structure
    makes depth edges noise. Called once the scene is known to be usable, so that a bad-input
    error is the only line the user sees.
    """
    notes = sorted({n for r in rings for n in r.notes})
    for n in notes[:3]:
        log.warning("%s", n)
    bad = [(f, r) for f, r in zip(frames, rings) if r.purity < MIN_PURITY]
    if bad:
        f, r = bad[0]
        hint = ("the cloud is not in the sensor's own frame: give the LiDAR's pose "
                "(lidar_pose in calib.yaml)" if f.sensor_pose is None else
                "check lidar_pose in calib.yaml")
        log.warning("%s: laser rings do not fit a spinning LiDAR (%d rings, %.0f %% of the "
                    "returns on their ring's cone; %d of %d frames like this); depth edges "
                    "will be unreliable; %s", f.points_path, r.n_rings, 100 * r.purity,
                    len(bad), len(frames), hint)


@dataclasses.dataclass(frozen=True)
class RingBrief:
    """The laser rings recovered in one sweep, in brief.

    Attributes
    ----------
    method : str
        How they were recovered (``"field"``, ``"scan"``, ``"elevation"``, ``"lines"``; see
        :func:`paretocal.features.prepare.frame_rings`).
    n_rings : int
        How many rings.
    purity : float
        The share of the returns near the view that lie on their ring's cone (0 to 1, to 4
        decimals).
    """

    method: str
    n_rings: int
    purity: float

    def to_dict(self) -> dict:
        """``{"method", "n_rings", "purity"}``, as result.json writes a sweep's rings."""
        return {"method": self.method, "n_rings": self.n_rings, "purity": self.purity}

    @classmethod
    def from_dict(cls, doc: dict) -> "RingBrief":
        """The brief read back from its :meth:`to_dict` form (or a fuller ring summary,
        :meth:`paretocal.lidar.rings.Rings.summary`, whose other keys it ignores)."""
        return cls(method=str(doc["method"]), n_rings=int(doc["n_rings"]),
                   purity=float(doc["purity"]))


@dataclasses.dataclass(frozen=True)
class InputsReport:
    """What the inputs offered (:func:`describe_inputs`; result.json ``inputs``).

    Attributes
    ----------
    point_fields : dict
        The point-cloud fields that gave intensity, ring and time, as the reader named them
        (its notes taken out, into :attr:`notes`).
    notes : tuple of str
        The reader's notes over every frame, sorted, each once.
    camera_model : str
        The first frame's camera model (``"pinhole"``, ``"fisheye"``, ...).
    lidar_pose : ndarray, shape (4, 4), or None
        The first frame's LiDAR pose in its cloud's frame (m); None when the clouds are in
        the LiDAR's frame.
    mask : bool
        Whether the first frame has an image mask.
    lidar_pose_source : dict or None
        Where the LiDAR pose came from (:func:`locate_lidar`); None when not given (and then
        not written).
    rings : tuple of (str, RingBrief) or None
        Each frame's name and its sweep's rings; None when not given (and then not written).
    """

    point_fields: dict
    notes: tuple[str, ...]
    camera_model: str
    lidar_pose: np.ndarray | None
    mask: bool
    lidar_pose_source: dict | None = None
    rings: tuple[tuple[str, RingBrief], ...] | None = None

    def to_dict(self) -> dict:
        """As result.json's ``inputs`` writes it: the pose as nested lists (m), and
        ``lidar_pose_source`` and ``rings`` (a list of ``{"frame", "method", "n_rings",
        "purity"}``) only when set."""
        out: dict = {"point_fields": dict(self.point_fields), "notes": list(self.notes),
                     "camera_model": self.camera_model,
                     "lidar_pose": None if self.lidar_pose is None
                     else np.asarray(self.lidar_pose).tolist(),
                     "mask": self.mask}
        if self.lidar_pose_source is not None:
            out["lidar_pose_source"] = self.lidar_pose_source
        if self.rings is not None:
            out["rings"] = [{"frame": name, **r.to_dict()} for name, r in self.rings]
        return out

    @classmethod
    def from_dict(cls, doc: dict) -> "InputsReport":
        """The report read back from its :meth:`to_dict` form; a key it lacks reads as
        empty (no fields, no notes, a pinhole camera, no pose, no mask).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (m).
        """
        pose = doc.get("lidar_pose")
        rings = doc.get("rings")
        return cls(point_fields=dict(doc.get("point_fields") or {}),
                   notes=tuple(str(n) for n in doc.get("notes") or ()),
                   camera_model=str(doc.get("camera_model", "pinhole")),
                   lidar_pose=None if pose is None else np.array(pose, dtype=np.float64),
                   mask=bool(doc.get("mask", False)),
                   lidar_pose_source=doc.get("lidar_pose_source"),
                   rings=None if rings is None else tuple(
                       (str(r["frame"]), RingBrief.from_dict(r)) for r in rings))


def describe_inputs(frames: list[Frame], lidar_info: dict | None = None,
                    rings: list[Rings] | None = None) -> InputsReport:
    """What the inputs offered (result.json ``inputs``): the point-cloud fields that gave
    intensity, ring and time, the reader's notes, the camera model, the LiDAR pose and, when
    given, where it came from (:func:`locate_lidar`) and each sweep's rings."""
    pf = dict(frames[0].point_fields or {})
    notes = sorted({w for f in frames for w in (f.point_fields or {}).get("warnings", ())})
    pf.pop("warnings", None)
    pose = frames[0].sensor_pose
    return InputsReport(
        point_fields=pf, notes=tuple(notes),
        camera_model=getattr(frames[0].camera, "model", "pinhole"),
        lidar_pose=None if pose is None else np.asarray(pose),
        mask=frames[0].mask is not None, lidar_pose_source=lidar_info,
        rings=None if rings is None else tuple(
            (f.name, RingBrief(method=r.method, n_rings=int(r.n_rings),
                               purity=round(float(r.purity), 4)))
            for f, r in zip(frames, rings)))


@dataclasses.dataclass
class LidarSteps:
    """The LiDAR-only steps of a calibration, done once for several cameras of one rig:
    the sweeps located (``sensor_pose``), their rings recovered, and de-skewed (``frames``,
    whose images and cameras are those of the camera they were computed with)."""

    frames: list[Frame]
    lidar_info: dict
    rings: list
    motion_info: MotionReport
    settings_key: dict

    def for_camera(self, frames: list[Frame]) -> list[Frame]:
        """``frames`` (another camera's, over the same clouds in the same order) with these
        steps' points and sensor pose: the image, camera, reference and mask stay theirs."""
        if [(f.name, f.points_path) for f in frames] != [(f.name, f.points_path)
                                                          for f in self.frames]:
            raise ValueError("LidarSteps.for_camera: the frames are not over the same clouds")
        return [dataclasses.replace(done, image=f.image, camera=f.camera, T_ref=f.T_ref,
                                    image_path=f.image_path, mask=f.mask,
                                    kitti_rect=f.kitti_rect)
                for done, f in zip(self.frames, frames)]


def lidar_settings_key(settings: Settings) -> dict:
    """The settings the LiDAR-only steps depend on (features, motion and the seed)."""
    d = settings.to_dict()
    return {"features": d.get("features"), "motion": d.get("motion"),
            "seed": settings.search.seed}


def prepare_lidar(frames: list[Frame], settings: Settings, views=None) -> LidarSteps:
    """Locate the LiDAR, recover the rings and compensate the motion of ``frames``' sweeps
    (as :func:`paretocal.calibrate` does), to be reused for every camera of a rig; ``views``
    as for :func:`sweep_rings` (every camera's that will use the steps)."""
    frames, lidar_info, first_rings = locate_lidar(frames, settings)
    rings = sweep_rings(frames, settings, first_rings, views)
    frames, motion_info = compensate_motion(frames, settings)
    return LidarSteps(frames, lidar_info, rings, motion_info, lidar_settings_key(settings))


def joint_frames(frames: dict[str, list[Frame]]) -> list[Frame]:
    """The frames of several cameras of one rig as one calibration of the first camera's
    extrinsic (a *joint* calibration).

    Every other camera's frames see the first camera's ``T_cam_lidar`` through a mount
    (:attr:`paretocal.camera.Camera.mount`), ``T_i @ inv(T_0)`` from the extrinsics the rig
    states (each frame's ``T_ref``), so that one correction ``D`` in the LiDAR frame moves
    every camera alike (``T_i @ D = mount_i @ T_0 @ D``): the cameras keep their relative
    poses, and only the LiDAR moves relative to them.

    Parameters
    ----------
    frames : dict of str to list of Frame
        Each camera's frames, cameras in the order they are listed; the first camera is the
        one whose extrinsic is estimated. Every camera's frames must state ``T_ref``.

    Returns
    -------
    list of Frame
        The frames, named ``<camera>/<frame>``, each with the first camera's ``T_ref``.
    """
    names = list(frames)
    _check_stated(frames)
    T0 = np.asarray(frames[names[0]][0].T_ref, dtype=np.float64)
    out = []
    for name in names:
        mount = None if name == names[0] else frames[name][0].T_ref @ invert(T0)
        for f in frames[name]:
            cam = f.camera if mount is None else dataclasses.replace(f.camera, mount=mount)
            out.append(dataclasses.replace(f, name=f"{name}/{f.name}", camera=cam, T_ref=T0))
    return out


def joint_camera(frame_name: str) -> str:
    """The camera a frame of a joint calibration belongs to: :func:`joint_frames` names its
    frames ``CAMERA/FRAME`` (camera names hold no ``/``)."""
    return frame_name.split("/", 1)[0]


def _check_stated(frames: dict[str, list[Frame]]) -> None:
    missing = [n for n in frames if not frames[n] or frames[n][0].T_ref is None]
    if missing:
        raise InputError(f"camera {missing[0]}: no frames or no stated T_cam_lidar; a joint "
                         "calibration keeps the cameras' relative poses as the rig states them")


def load_joint(source, settings: Settings, cameras: list[str] | None = None
               ) -> tuple[list[Frame], LidarSteps]:
    """The selected frames of the cameras ``cameras`` (all by default) of the rig folder
    ``source``, their LiDAR steps done once per set of clouds, as one joint calibration
    (:func:`joint_frames`): ``(frames, steps)`` for :func:`paretocal.calibrate`."""
    from .io import load_rig_frames, rig_cameras

    found = rig_cameras(source)
    if cameras:
        found = [(n, s) for n, s in found if n in cameras]
    loaded = load_rig_frames(found, settings.frames)
    _check_stated(loaded)
    steps = rig_lidar_steps(loaded, settings)
    frames = joint_frames({name: steps[name].for_camera(fr) for name, fr in loaded.items()})
    first = steps[next(iter(loaded))]
    rings = [r for name in loaded for r in steps[name].rings]
    return frames, LidarSteps(frames, first.lidar_info, rings, first.motion_info,
                              lidar_settings_key(settings))


def rig_lidar_steps(frames: dict[str, list[Frame]], settings: Settings,
                    T_views: dict | None = None) -> dict[str, LidarSteps]:
    """The LiDAR-only steps of a rig's cameras (:func:`prepare_lidar`), done once per set of
    clouds: by camera name, the steps over its frames' clouds, one object for the cameras
    whose selected frames use the same clouds (every camera's, when all cameras have an
    image of every selected frame). The rings are judged where any camera over those clouds
    looks: at ``T_views[name]`` (an initial extrinsic), else at its frames' ``T_ref``."""
    T_views = T_views or {}
    clouds = {name: tuple((f.name, str(f.points_path)) for f in fr)
              for name, fr in frames.items()}
    done: dict = {}
    for key in dict.fromkeys(clouds.values()):
        over = [n for n in frames if clouds[n] == key]
        views = []
        for n in over:
            T = T_views.get(n, frames[n][0].T_ref if frames[n] else None)
            if T is not None:
                views.append((frames[n][0].camera, np.asarray(T, dtype=np.float64)))
        done[key] = prepare_lidar(frames[over[0]], settings, views)
    return {name: done[clouds[name]] for name in frames}
