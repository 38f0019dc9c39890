"""Ring recovery against exact truth on rig variants of real KITTI sweeps (made at run time)."""

import numpy as np
import pytest

from paretocal.features.prepare import sensor_points
from paretocal.lidar.rings import MIN_PURITY, recover_rings, ring_purity
from paretocal.testing import (decimate, firing_order, kitti_truth, ring_accuracy, shuffled,
                               to_vehicle_frame)


@pytest.fixture(scope="module")
def sweeps(raw_frames):
    # Three frames spread over the drive.
    return [kitti_truth(raw_frames[i].points) for i in (0, 9, 19)]


def _recover(v, **kw):
    return recover_rings(v.points, **kw)


@pytest.mark.parametrize("name,make,beams", [
    ("kitti order", lambda v: v, 64),
    ("32 beams", lambda v: decimate(v, 2), 32),
    ("16 beams", lambda v: decimate(v, 4), 16),
    ("firing order", firing_order, 64),
    ("firing order, 16 beams", lambda v: firing_order(decimate(v, 4)), 16),
    ("shuffled", lambda v: shuffled(v, 3), 64),
    ("shuffled, 32 beams", lambda v: shuffled(decimate(v, 2), 4), 32),
])
def test_true_ring_of_every_point(sweeps, name, make, beams):
    for v in sweeps:
        w = make(v)
        r = _recover(w)
        assert r.n_rings == beams, name
        acc = ring_accuracy(r.ring, w.ring)
        assert acc >= 0.99, f"{name}: {acc:.4f}"
        assert r.purity >= MIN_PURITY


def test_scan_order_is_taken_as_is_and_other_orders_are_not(sweeps):
    v = sweeps[0]
    assert _recover(v).method == "scan"
    assert _recover(firing_order(v)).method == "lines"


def test_ring_field_used_when_plausible_and_replaced_when_not(sweeps, rng):
    v = firing_order(sweeps[0])
    r = recover_rings(v.points, ring_field=v.ring)
    assert r.method == "field" and ring_accuracy(r.ring, v.ring) == 1.0
    # A ring field that does not describe the lasers (values scrambled) is replaced.
    bogus = rng.integers(0, 64, len(v.ring))
    r = recover_rings(v.points, ring_field=bogus, source="x.pcd")
    assert r.method == "lines" and ring_accuracy(r.ring, v.ring) >= 0.99
    assert any("x.pcd" in n and "ring field" in n for n in r.notes)


def test_vehicle_frame_needs_the_sensor_pose(sweeps, raw_frames):
    from dataclasses import replace

    v = to_vehicle_frame(sweeps[0])
    # About the vehicle origin the returns do not lie on cones: the purity says so.
    assert ring_purity(v.points, v.ring) < 0.5
    frame = replace(raw_frames[0], points=v.points, sensor_pose=v.sensor_pose)
    r = recover_rings(sensor_points(frame))
    assert r.n_rings == 64 and ring_accuracy(r.ring, v.ring) >= 0.99


def test_purity_rejects_mixed_rings(sweeps):
    v = sweeps[0]
    assert ring_purity(v.points, v.ring) > 0.99
    # Two lasers in one "ring" (every ring merged with its neighbour) fail the line model.
    assert ring_purity(v.points, v.ring // 2) < 0.6


def test_implausible_rings_are_said_with_the_file_and_the_fallback(sweeps, raw_frames, caplog):
    from dataclasses import replace

    from paretocal.pipeline import warn_rings

    # About a wrong origin (a vehicle frame without lidar_pose) the recovered rings fail the
    # line model: one warning names the file, says the rings are still used with poor depth
    # edges, and asks for the pose.
    v = to_vehicle_frame(sweeps[0])
    frame = replace(raw_frames[0], points=v.points, ring=None, sensor_pose=None)
    r = recover_rings(v.points, source=str(frame.points_path))
    assert r.purity < MIN_PURITY or r.n_rings < 8
    with caplog.at_level("WARNING", logger="paretocal"):
        warn_rings([frame], [r])
    text = [rec.getMessage() for rec in caplog.records]
    assert any(str(frame.points_path) in t and "lidar_pose" in t and "unreliable" in t
               for t in text), text


def test_later_sweeps_labelled_with_the_first_sweeps_lines(sweeps):
    # The line model of one sweep labels the next sweeps of the same sensor exactly, without
    # a note (notes are problems the user is told about).
    first = recover_rings(firing_order(sweeps[0]).points)
    for v in (firing_order(sweeps[1]), shuffled(decimate(sweeps[2], 1), 7)):
        r = recover_rings(v.points, model=first)
        assert r.method == "lines" and r.n_rings == 64 and not r.notes
        assert ring_accuracy(r.ring, v.ring) >= 0.99


def test_a_model_that_does_not_fit_is_replaced(sweeps):
    # A 16-line model cannot explain a 64-beam sweep: the sweep is searched afresh and the
    # note says so.
    first = recover_rings(firing_order(decimate(sweeps[0], 4)).points)
    v = firing_order(sweeps[1])
    r = recover_rings(v.points, model=first)
    assert r.n_rings == 64 and ring_accuracy(r.ring, v.ring) >= 0.99
    assert any("earlier sweep's line model" in n for n in r.notes)


def test_group_sigma_is_each_labels_own_sigma(rng):
    """The grouped robust scatter equals the one-label formula on every label (odd and even
    counts, a label with one point, labels without points)."""
    from paretocal.lidar.rings import _group_sigma, _sigma

    lab = np.concatenate([rng.integers(0, 9, 5000), [11]])
    r = np.abs(rng.normal(size=len(lab)))
    got = _group_sigma(r, lab, 13)
    for k in range(13):
        if (lab == k).any():
            assert got[k] == _sigma(r[lab == k])
        else:
            assert np.isnan(got[k])


def test_compiled_ring_line_sums_are_numpys(rng):
    """The per-ring passes of fit_ring_lines are compiled loops in point order: the same sums,
    ranges and median residuals as np.bincount, ufunc.at and np.median, bit for bit."""
    from paretocal.lidar.rings import _group_lines, _group_sigma

    n = 40
    lab = rng.integers(0, n - 3, 5000)                      # the last labels stay empty
    te, inv, r = rng.normal(size=5000), rng.random(5000), np.abs(rng.normal(size=5000))
    a, h, count = _group_lines(te, inv, lab, n)
    cnt = np.bincount(lab, minlength=n).astype(float)
    safe = np.maximum(cnt, 1.0)
    m_inv, m_te = np.bincount(lab, inv, n) / safe, np.bincount(lab, te, n) / safe
    di = inv - m_inv[lab]
    sxx, sxy = np.bincount(lab, di * di, n), np.bincount(lab, di * (te - m_te[lab]), n)
    np.testing.assert_array_equal(count, cnt)
    h_ref = np.where(cnt >= 2, sxy / np.where(sxx > 0, sxx, 1.0), np.nan)
    np.testing.assert_array_equal(h[cnt > 0], h_ref[cnt > 0])
    np.testing.assert_array_equal(a[cnt > 0], (m_te - h_ref * m_inv)[cnt > 0])
    assert np.isnan(a[cnt == 0]).all() and np.isnan(h[cnt == 0]).all()
    sig = _group_sigma(r, lab, n)
    ref = np.array([1.4826 * np.median(r[lab == k]) + 1e-7 if (lab == k).any() else np.nan
                    for k in range(n)])
    np.testing.assert_array_equal(sig, ref)


def test_a_motion_compensated_sweep_is_judged_where_the_camera_looks(sweeps, raw_frames):
    """A sweep moved into the frame of the camera's instant while the vehicle drove and
    pitched lies on its lasers' cones only near the view: judged on the whole sweep its rings
    are implausible, judged on the returns the features come from they are the sensor's."""
    from dataclasses import replace

    from paretocal.config import FeatureSettings
    from paretocal.features.prepare import view_mask
    from paretocal.testing import compensated

    first = recover_rings(firing_order(sweeps[0]).points)
    v = firing_order(compensated(sweeps[1], speed_mps=1.5, pitch_dps=2.0))
    frame = replace(raw_frames[9], points=v.points, ring=None)
    view = view_mask(frame, [(frame.camera, frame.T_ref)], FeatureSettings())
    whole = recover_rings(v.points, model=first)
    assert whole.n_rings < 8 or whole.purity < MIN_PURITY
    r = recover_rings(v.points, model=first, view=view)
    assert r.n_rings == 64 and r.purity >= MIN_PURITY and not r.notes
    assert ring_accuracy(r.ring[view], v.ring[view]) >= 0.99
