"""Ego-motion estimation and de-skewing (paretocal.lidar).

Synthetic oracles: a simulated spinning LiDAR (32 beams, one revolution per 100 ms, clockwise,
sweeps 133 ms apart like the aiMotive subset) moving with a known constant twist through a scene
of boxes, poles and a ground plane, with exact per-point times. Real data: the aiMotive clouds,
which are not motion-compensated and were recorded at about 30.2 m/s.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paretocal.io.clouds import read_cloud
from paretocal.lidar import (
    PoseTrajectory,
    Twist,
    deskew,
    estimate_motion,
    estimate_time_offset,
    pair_residuals,
    sweep_centre,
)

from .conftest import data_dir

PERIOD = 0.100       # s per revolution
FRAME_DT = 0.1333    # s between sweep starts (every second 15 Hz keyframe)
HEIGHT = 1.8         # m, sensor above the ground


# ----------------------------------------------------------------------------- simulator

def _box_hits(o, d, lo, hi):
    """Ray parameters of the entry into axis-aligned boxes; inf where a ray misses.

    o, d: (N, 3); lo, hi: (B, 3). Returns (N,) nearest positive hit over the boxes.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (lo[None] - o[:, None]) * inv[:, None]
        t2 = (hi[None] - o[:, None]) * inv[:, None]
    tmin = np.nanmax(np.minimum(t1, t2), axis=2)
    tmax = np.nanmin(np.maximum(t1, t2), axis=2)
    hit = (tmax >= tmin) & (tmin > 1e-6)
    return np.where(hit, tmin, np.inf).min(axis=1) if len(lo) else np.full(len(o), np.inf)


def _pole_hits(o, d, centres, radius, height):
    """Nearest positive hit on vertical cylinders (z in [0, height]); inf where a ray misses."""
    if not len(centres):
        return np.full(len(o), np.inf)
    oc = o[:, None, :2] - centres[None]
    a = (d[:, None, :2] ** 2).sum(-1)
    b = 2 * (oc * d[:, None, :2]).sum(-1)
    c = (oc ** 2).sum(-1) - radius ** 2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (-b - np.sqrt(disc)) / (2 * a)
    z = o[:, None, 2] + r * d[:, None, 2]
    ok = (disc > 0) & (r > 1e-6) & (z >= 0) & (z <= height)
    return np.where(ok, r, np.inf).min(axis=1)


def street_scene(rng):
    """Buildings with gaps on both sides, parked cars, poles every ~9 m, a ground plane."""
    lo, hi = [], []
    for side in (-1, 1):
        x = -70.0
        while x < 70.0:
            length = rng.uniform(6, 14)
            y0 = side * rng.uniform(9, 13)
            lo.append([x, min(y0, y0 + side * 8), 0.0])
            hi.append([x + length, max(y0, y0 + side * 8), rng.uniform(4, 12)])
            x += length + rng.uniform(2, 6)
        for x in np.arange(-60, 60, 17.0) + rng.uniform(0, 5):
            y = side * rng.uniform(5.0, 6.0)
            lo.append([x, y - 0.9, 0.0])
            hi.append([x + 4.3, y + 0.9, 1.5])
    poles = [[x, side * 7.5] for side in (-1, 1) for x in np.arange(-65, 65, 9.0) + rng.uniform(0, 3)]
    return dict(lo=np.array(lo), hi=np.array(hi), poles=np.array(poles), pole_r=0.15, pole_h=6.0)


def corridor_scene():
    """Two long parallel walls and a floor: nothing across the direction of travel (x)."""
    return dict(lo=np.array([[-2000.0, 4.0, 0.0], [-2000.0, -4.5, 0.0]]),
                hi=np.array([[2000.0, 4.5, 5.0], [2000.0, -4.0, 5.0]]),
                poles=np.zeros((0, 2)), pole_r=0.1, pole_h=1.0)


def sensor_pose(twist, t):
    """T_world_sensor(t) = T0 exp(t [v, w]) with the sensor HEIGHT above the ground at t = 0."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    R, p = twist.relative(t, 0.0)          # exp(t xi): frame at t in the frame at 0
    return R, p + [0.0, 0.0, HEIGHT]


def spin_scan(scene, twist, t0, *, seam_deg=0.0, n_az=720, noise=0.0, rng=None, max_range=80.0):
    """One clockwise revolution starting at ``t0``: points in the sensor frame at their own time.

    Returns xyz (N, 3), t (N,), and the noise-free world points (N, 3).
    """
    elev = np.radians(np.linspace(-25.0, 12.0, 32))
    j = np.arange(n_az)
    tc = t0 + j * PERIOD / n_az
    az = np.radians(seam_deg) - 2 * np.pi * j / n_az          # clockwise seen from above
    A, E = np.meshgrid(az, elev, indexing="ij")
    T = np.repeat(tc, len(elev))
    dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    R, p = sensor_pose(twist, T)
    dw = R.apply(dirs)
    r = np.full(len(T), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        ground = np.where(dw[:, 2] < 0, -p[:, 2] / dw[:, 2], np.inf)
    r = np.minimum(r, ground)
    r = np.minimum(r, _box_hits(p, dw, scene["lo"], scene["hi"]))
    r = np.minimum(r, _pole_hits(p, dw, scene["poles"], scene["pole_r"], scene["pole_h"]))
    keep = r < max_range
    r, dirs, T, p, dw = r[keep], dirs[keep], T[keep], p[keep], dw[keep]
    world = p + r[:, None] * dw
    rm = r + (rng.normal(0.0, noise, len(r)) if noise else 0.0)
    return dirs * rm[:, None], T, world


def sequence(scene, twist, n, *, noise=0.005, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        xyz, t, world = spin_scan(scene, twist, k * FRAME_DT, seam_deg=(0.0, -120.0, 120.0)[k % 3],
                                  noise=noise, rng=rng)
        out.append((xyz, t, world))
    return out


def in_frame(twist, world, t_ref):
    """World points expressed in the sensor frame at ``t_ref``."""
    R, p = sensor_pose(twist, [t_ref])
    return R[0].inv().apply(world - p[0])


TRUE = Twist([15.0, 0.0, 0.0], [0.0, 0.0, 0.2])       # 54 km/h, turning left at 11.5 deg/s


@pytest.fixture(scope="module")
def street():
    return sequence(street_scene(np.random.default_rng(7)), TRUE, 6)


# ----------------------------------------------------------------------------- de-skew

def test_forward_motion_sign_convention():
    """Pure forward motion: x' = x + s (t - t_ref), y and z unchanged."""
    rng = np.random.default_rng(1)
    xyz = rng.normal(0, 10, (500, 3))
    t = rng.uniform(10.0, 10.1, 500)
    out = deskew(xyz, t, 10.03, Twist([30.0, 0.0, 0.0]))
    np.testing.assert_allclose(out[:, 0], xyz[:, 0] + 30.0 * (t - 10.03), atol=1e-9)
    np.testing.assert_allclose(out[:, 1:], xyz[:, 1:], atol=1e-12)


def test_deskew_recovers_static_scene(street):
    """With the true twist every point lands where the static scene is at t_ref (< 1 mm)."""
    scene = street_scene(np.random.default_rng(7))
    xyz, t, world = spin_scan(scene, TRUE, 0.0, seam_deg=-120.0, noise=0.0)
    for t_ref in (sweep_centre(t), t.min(), t.max() + 0.02):
        out = deskew(xyz, t, t_ref, TRUE)
        err = np.linalg.norm(out - in_frame(TRUE, world, t_ref), axis=1)
        assert err.max() < 1e-3
    # The skew is real: without de-skewing the same points are off by up to ~1.5 m.
    raw_err = np.linalg.norm(xyz - in_frame(TRUE, world, sweep_centre(t)), axis=1)
    assert raw_err.max() > 0.5


def test_deskew_exponential_is_exact_for_large_rotation():
    """A full turn's worth of rotation: exp matches composition of many small steps."""
    tw = Twist([3.0, -1.0, 0.5], [0.4, -0.3, 2.0])
    p = np.array([[1.0, 2.0, 3.0]])
    one = deskew(p, [1.0], 0.0, tw)
    small = tw.pose(1.0 / 1000)
    T = np.eye(4)
    for _ in range(1000):
        T = T @ small
    np.testing.assert_allclose(one[0], T[:3, :3] @ p[0] + T[:3, 3], atol=1e-9)
    # And the log inverts the exponential.
    back = Twist.from_pose(tw.pose(0.37), 0.37)
    np.testing.assert_allclose(back.vector, tw.vector, atol=1e-12)


def test_pose_trajectory_slerp_linear_is_exact_for_its_own_model():
    """World-frame straight line plus constant rotation is what SLERP / linear reproduce."""
    w = np.array([0.1, -0.2, 0.5])
    vel = np.array([12.0, 1.0, -0.3])

    def pose(t):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(w * t).as_matrix()
        T[:3, 3] = vel * t + [5.0, -2.0, 1.0]
        return T

    traj = PoseTrajectory([0.0, 0.5], [pose(0.0), pose(0.5)])
    rng = np.random.default_rng(3)
    xyz = rng.normal(0, 20, (300, 3))
    t = rng.uniform(0.1, 0.2, 300)
    out = deskew(xyz, t, 0.15, traj)
    ref = np.array([np.linalg.solve(pose(0.15), pose(ti) @ np.append(p, 1.0))[:3]
                    for p, ti in zip(xyz, t)])
    np.testing.assert_allclose(out, ref, atol=1e-9)
    with pytest.raises(ValueError, match="outside the pose trajectory"):
        deskew(xyz, t + 1.0, 0.15, traj)


def test_pose_trajectory_agrees_with_twist_when_sampled_densely():
    """Poses sampled from a constant twist every 10 ms de-skew like the twist (< 1 mm)."""
    times = np.arange(-0.05, 0.3, 0.01)
    R, p = sensor_pose(TRUE, times)
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, :3] = R.as_matrix()
    poses[:, :3, 3] = p
    traj = PoseTrajectory(times, poses)
    scene = street_scene(np.random.default_rng(7))
    xyz, t, _ = spin_scan(scene, TRUE, 0.05, n_az=180)
    a = deskew(xyz, t, 0.1, traj)
    b = deskew(xyz, t, 0.1, TRUE)
    assert np.abs(a - b).max() < 1e-3


def test_motion_inputs_are_checked():
    with pytest.raises(ValueError, match="3 finite numbers"):
        Twist([1.0, 2.0])
    with pytest.raises(ValueError, match="3 finite numbers"):
        Twist([1.0, 0.0, 0.0], [np.nan, 0.0, 0.0])
    eye = np.tile(np.eye(4), (2, 1, 1))
    with pytest.raises(ValueError, match="strictly increasing"):
        PoseTrajectory([1.0, 1.0], eye)
    with pytest.raises(ValueError, match="shape"):
        PoseTrajectory([0.0, 1.0, 2.0], eye)
    with pytest.raises(ValueError, match="at least 2"):
        PoseTrajectory([0.0], eye[:1])


def test_deskew_rejects_missing_or_bad_time():
    xyz = np.zeros((3, 3))
    with pytest.raises(ValueError, match="no per-point time"):
        deskew(xyz, None, 0.0, TRUE)
    with pytest.raises(ValueError, match="finite"):
        deskew(xyz, [0.0, np.nan, 0.0], 0.0, TRUE)
    with pytest.raises(ValueError, match="2 times for 3 points"):
        deskew(xyz, [0.0, 0.0], 0.0, TRUE)
    assert deskew(np.zeros((0, 3)), np.zeros(0), 0.0, TRUE).shape == (0, 3)


# ----------------------------------------------------------------------------- estimation

def test_estimate_motion_recovers_speed_and_yaw_rate(street):
    clouds = [(x, t) for x, t, _ in street]
    est = estimate_motion(clouds, seed=0)
    assert est.converged
    assert abs(est.speed - TRUE.speed) < 0.02 * TRUE.speed
    assert abs(est.twist.w[2] - TRUE.w[2]) < 0.01
    assert np.abs(est.twist.v[1:]).max() < 0.02 * TRUE.speed
    assert est.observable.all() and est.compensable
    # Every pair agrees, and the spread is reported.
    speeds = np.linalg.norm(est.pair_twists[:, :3], axis=1)
    assert np.abs(speeds - TRUE.speed).max() < 0.03 * TRUE.speed
    assert 0 <= est.speed_spread < 0.03 * TRUE.speed
    # The iteration improved on the raw registration, which the skew biases.
    assert (est.residual < est.residual_raw).all()
    # frame_motion hands out a twist that de-skews to within a few cm of the truth.
    xyz, t, world = street[2]
    out = deskew(xyz, t, est.ref_times[2], est.frame_motion(2))
    err = np.linalg.norm(out - in_frame(TRUE, world, est.ref_times[2]), axis=1)
    assert np.median(err) < 0.03


def test_estimate_motion_per_frame_and_initial(street):
    clouds = [(x, t) for x, t, _ in street[:4]]
    est = estimate_motion(clouds, per_frame=True, initial=Twist([14.0, 0.0, 0.0]), seed=1,
                          residual_sample=0)
    assert len(est.frame_twists) == 4
    for tw in est.frame_twists:
        assert abs(tw.speed - TRUE.speed) < 0.03 * TRUE.speed
    assert est.frame_motion(1) is est.frame_twists[1]
    assert np.isnan(est.residual).all()
    # The estimate itself can drive the time-offset scan (its per-frame twists).
    seen = []
    estimate_time_offset(clouds, est, lambda c: seen.append(c[1]) or 0.0, half_width=0.0)
    np.testing.assert_allclose(seen[0], deskew(*clouds[1], sweep_centre(clouds[1][1]), est.frame_twists[1]))


def test_corridor_is_reported_unobservable_along_x(caplog):
    """Walls parallel to the motion and a flat floor do not fix the motion along x."""
    clouds = [(x, t) for x, t, _ in sequence(corridor_scene(), Twist([15.0, 0, 0]), 4)]
    with caplog.at_level(logging.WARNING, logger="paretocal.lidar.motion"):
        est = estimate_motion(clouds, seed=0, residual_sample=0)
    assert not est.observable[0]
    assert est.observable[1] and est.observable[2]
    assert not est.compensable
    assert np.median(est.share[:, 0]) < 0.1 * est.min_share
    assert np.abs(est.weakest_axis[:, 0]).min() > 0.99
    assert "not observable along x" in caplog.text
    with pytest.raises(ValueError, match="not observable along x"):
        est.frame_motion(0)
    with pytest.raises(ValueError, match="not observable along x"):
        estimate_time_offset(clouds, est, lambda c: 0.0)
    assert isinstance(est.frame_motion(0, force=True), Twist)


def test_estimate_motion_rejects_bad_input():
    xyz = np.zeros((10, 3))
    with pytest.raises(ValueError, match="at least two"):
        estimate_motion([(xyz, np.zeros(10))])
    with pytest.raises(ValueError, match="no per-point time"):
        estimate_motion([(xyz, None), (xyz, None)])
    with pytest.raises(ValueError, match="time order"):
        estimate_motion([(xyz, np.ones(10)), (xyz, np.zeros(10))])


# ----------------------------------------------------------------------------- time offset

def test_time_offset_finds_image_time(street):
    """Score = distance to the scene as seen at the image time: the minimum is that time."""
    frames = street[:3]
    clouds = [(x, t) for x, t, _ in frames]
    true_offset = 0.023
    targets = [in_frame(TRUE, w, sweep_centre(t) + true_offset) for _, t, w in frames]

    def score(clouds_at):
        return float(np.mean([np.mean(np.sum((c - g) ** 2, axis=1)) for c, g in zip(clouds_at, targets)]))

    res = estimate_time_offset(clouds, TRUE, score)
    assert res.refined and not res.at_edge
    assert res.offsets[0] == pytest.approx(-0.060, abs=0.003)
    assert res.offsets[1] - res.offsets[0] == pytest.approx(0.1 / 20, rel=0.02)
    assert abs(res.offset - true_offset) < 1e-3
    # One motion per cloud is accepted too; a grid too narrow reports its edge.
    edge = estimate_time_offset(clouds, [TRUE] * 3, score, half_width=0.01)
    assert edge.at_edge and not edge.refined and edge.offset == pytest.approx(0.01, abs=1e-3)


# ----------------------------------------------------------------------------- real data

def cloud_with_time(path):
    """Points (N, 3) float64 and per-point times (N,) in seconds of one sweep file."""
    cloud = read_cloud(path)
    assert cloud.time is not None, f"{path} has no per-point time"
    return cloud.points[:, :3].astype(np.float64), cloud.time


@pytest.fixture(scope="module")
def aimotive_clouds():
    folder = data_dir() / "aimotive" / "points"
    paths = sorted(folder.glob("*.pcd"))
    if len(paths) < 20:
        pytest.fail(f"aiMotive sample clouds not found in {folder}")
    return [cloud_with_time(p) for p in paths]


@pytest.mark.slow
def test_aimotive_speed_and_deskew_overlap(aimotive_clouds):
    """The 20 real sweeps: 30.2 m/s forward (the data README's check, registered 0.4 s apart).

    10k registration points per sweep instead of 15k keep the test near 10 s on 2 cores.
    """
    est = estimate_motion(aimotive_clouds, points=10000, residual_sample=10000, seed=0)
    assert est.converged
    assert abs(est.speed - 30.2) < 0.03 * 30.2
    assert abs(est.twist.v[0] - 30.2) < 0.03 * 30.2
    assert abs(est.twist.v[1]) < 1.0 and abs(est.twist.v[2]) < 1.0
    speeds = np.linalg.norm(est.pair_twists[:, :3], axis=1)
    assert np.abs(speeds - 30.2).max() < 0.05 * 30.2
    assert est.speed_spread < 0.02 * 30.2
    # The motorway is weakest along the direction of travel, yet observable there.
    assert (np.abs(est.weakest_axis[:, 0]) > 0.9).all()
    assert est.compensable
    # De-skewed consecutive clouds overlap better than the raw ones, pair by pair.
    assert (est.residual < est.residual_raw).all()
    assert np.median(est.residual) < 0.9 * np.median(est.residual_raw)


def test_aimotive_pair_residuals_raw_vs_known_speed(aimotive_clouds):
    """With the README's speed, de-skewing two real sweeps tightens their overlap."""
    clouds = aimotive_clouds[:2]
    tau = [sweep_centre(t) for _, t in clouds]
    dt = tau[1] - tau[0]
    fwd = Twist([30.2, 0.0, 0.0])
    raw = pair_residuals(clouds, tau, [Twist.zero()] * 2, fwd.pose(dt)[None], rng=0)
    fixed = pair_residuals(clouds, tau, [fwd] * 2, fwd.pose(dt)[None], rng=0)
    assert fixed[0] < raw[0]
    assert math.isfinite(raw[0]) and raw[0] < 1.0


def test_deskew_off_unquoted_in_a_config_file(tmp_path):
    """YAML reads an unquoted `off` as false; the setting means the word."""
    from paretocal.config import load_settings

    (tmp_path / "c.yaml").write_text("motion: {deskew: off}\n")
    assert load_settings(tmp_path / "c.yaml").validate().motion.deskew == "off"


def test_normals_match_a_batched_eigendecomposition():
    """The compiled normals (Jacobi rotations per neighbourhood) against numpy's ``eigh``:
    planarity to 1e-12 and the same normal up to sign, on planes, lines, scatter and a
    neighbourhood of one repeated point (planarity 0, no NaN)."""
    from paretocal.lidar.registration import _normals, neighbours

    rng = np.random.default_rng(3)
    plane = np.column_stack([rng.uniform(-5, 5, (400, 2)), 0.01 * rng.standard_normal(400)])
    tilt = Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix()
    line = np.column_stack([rng.uniform(0, 10, 200), 1e-3 * rng.standard_normal((200, 2))])
    pts = np.vstack([plane @ tilt.T, line + 20.0, rng.standard_normal((300, 3)) - 20.0])
    nb = neighbours(pts, 12)
    normals, planarity = _normals(pts, nb)
    d = pts[nb] - pts[nb].mean(axis=1, keepdims=True)
    vals, vecs = np.linalg.eigh(d.transpose(0, 2, 1) @ d)
    expect = np.clip((vals[:, 1] - vals[:, 0]) / vals[:, 2], 0.0, 1.0)
    np.testing.assert_allclose(planarity, expect, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    cos = np.abs(np.einsum("ij,ij->i", normals, vecs[:, :, 0]))
    assert cos[expect > 0.05].min() > 1 - 1e-9
    # The plane's points carry its normal (the tilted z axis) and a planarity near 1.
    assert np.abs(normals[:400] @ tilt[:, 2]).min() > 0.99 and np.median(planarity[:400]) > 0.5
    same = np.zeros((12, 3))
    n0, p0 = _normals(same, np.tile(np.arange(12), (12, 1)))
    assert np.all(p0 == 0.0) and np.isfinite(n0).all()
