"""Rig variants made at run time (paretocal.testing): packet order with per-laser azimuth
offsets, and the truth of a cloud without a ring field (PandaSet) from the ring recovery.
Ring recovery must not depend on the order a sensor's driver stores its points in."""

from __future__ import annotations

import numpy as np
import pytest

from paretocal.lidar.rings import MIN_PURITY, azimuth, recover_rings
from paretocal.geometry import invert, transform_points
from paretocal.testing import (decimate, kitti_truth, packet_order, recovered_truth,
                               ring_accuracy, shuffled, to_vehicle_frame)


@pytest.fixture(scope="module")
def sweeps(raw_frames):
    # Three frames spread over the drive, as tests/test_rings.py takes them.
    return [kitti_truth(raw_frames[i].points) for i in (0, 9, 19)]


def _rows(v) -> np.ndarray:
    """Every point with its ring, in one canonical order (to compare as sets)."""
    a = np.column_stack([v.points.astype(np.float64), v.ring, v.time])
    return a[np.lexsort(a.T[::-1])]


def test_packet_order_keeps_every_point_and_breaks_the_scan_order(sweeps):
    v = sweeps[0]
    w = packet_order(v)
    np.testing.assert_array_equal(_rows(w), _rows(v))
    # Consecutive points change laser and, by the lasers' offsets, jump in azimuth.
    assert np.mean(np.diff(w.ring) != 0) > 0.9
    step = np.abs(np.angle(np.exp(1j * np.diff(azimuth(w.points)))))
    assert np.mean(step > np.radians(1.0)) > 0.5
    # The file order tells nothing about the rings: the scan-order method is not chosen.
    assert recover_rings(v.points).method == "scan"
    assert recover_rings(w.points).method != "scan"
    # Other offsets (or another seed) give another order of the same points.
    other = packet_order(v, rng=1)
    assert not np.array_equal(other.points, w.points)
    np.testing.assert_array_equal(_rows(other), _rows(v))
    with pytest.raises(ValueError, match="one per laser"):
        packet_order(v, np.zeros(3))


def test_packet_order_of_a_cloud_in_a_vehicle_frame_is_the_sensors(sweeps):
    """Columns are taken about the sensor's axis, not the cloud's origin."""
    v = decimate(sweeps[0], 4)
    np.testing.assert_array_equal(packet_order(to_vehicle_frame(v)).ring,
                                  packet_order(v).ring)


@pytest.mark.parametrize("beams", [64, 32, 16])
def test_true_ring_of_every_point_in_packet_order(sweeps, beams):
    for v in sweeps:
        w = packet_order(decimate(v, 64 // beams))
        r = recover_rings(w.points)
        acc = ring_accuracy(r.ring, w.ring)
        assert (r.n_rings, r.method) == (beams, "lines"), (r.notes, r.purity)
        assert acc >= 0.99, f"{beams} beams: {acc:.4f} ({r.method}, purity {r.purity:.3f})"
        assert r.purity >= MIN_PURITY


def _pose(position, axis) -> np.ndarray:
    """cloud <- sensor with the spinning axis ``axis``, the yaw as the cloud's."""
    z = np.asarray(axis, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    P = np.eye(4)
    P[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    P[:3, 3] = position
    return P


#: The Pandar64 in PandaSet's frame as paretocal locates it, from the data's README (the
#: estimate itself takes about a minute).
PANDAR_POSE = _pose((0.000, 0.779, 1.859), (-0.0005, -0.0157, 0.9999))


@pytest.fixture(scope="module")
def pandaset(data):
    from paretocal.io import load_frames

    root = data / "pandaset" / "front"
    if not (root / "calib.yaml").is_file():
        pytest.skip("PandaSet sample not present")
    # Frame 00: the car stands still, so the whole sweep lies on its lasers' cones.
    return recovered_truth(load_frames(root, "0")[0].points, PANDAR_POSE)


def test_pandaset_rings_do_not_depend_on_the_order(pandaset):
    v = pandaset
    assert v.ring.max() + 1 == 64 and np.mean(v.ring >= 0) > 0.95
    for name, w in (("packet order", packet_order(v)), ("shuffled", shuffled(v, 5))):
        np.testing.assert_array_equal(_rows(w), _rows(v))
        r = recover_rings(transform_points(invert(w.sensor_pose), w.points))
        agree = ring_accuracy(r.ring, w.ring)
        assert r.n_rings == 64 and agree >= 0.99, f"{name}: {agree:.4f} ({r.method}, purity " \
                                                   f"{r.purity:.3f}, {r.notes})"


def test_recovered_truth_is_refused_when_implausible(sweeps):
    # A cloud in a vehicle frame taken about its origin: the returns are on no cone.
    v = to_vehicle_frame(decimate(sweeps[0], 4))
    with pytest.raises(ValueError, match="not plausible"):
        recovered_truth(v.points, np.eye(4))
    # About the right pose the truth is the exact one.
    w = recovered_truth(v.points, v.sensor_pose)
    assert ring_accuracy(w.ring, v.ring) >= 0.99
