"""The wide start (paretocal.wide): when it runs, what it needs, and what it finds on KITTI."""

import numpy as np
import pytest

from paretocal.config import Settings
from paretocal.geometry import decalibrate, pose_error
from paretocal.crosscheck import baseline_m, camera_pairs
from paretocal.wide import AFTER_DEG, AFTER_M, WIDE_DEG, WIDE_M, after_settings, wanted, wide_start


def _wide(deg=20.0, m=1.5, **search):
    return Settings().replace(search={"init_error_deg": deg, "init_error_m": m, **search})


def test_wanted_when_the_stated_error_is_wide():
    assert not wanted(Settings())
    assert not wanted(_wide(WIDE_DEG, WIDE_M))
    assert wanted(_wide(WIDE_DEG + 1, 0.1)) and wanted(_wide(5.0, WIDE_M + 0.1))
    assert not wanted(_wide(wide="off")) and wanted(Settings().replace(search={"wide": "on"}))


def test_after_settings_narrow_the_stated_error_never_widen_it():
    s = after_settings(_wide())
    assert (s.search.init_error_deg, s.search.init_error_m) == (AFTER_DEG, AFTER_M)
    s = after_settings(_wide(2.0, 0.05))
    assert (s.search.init_error_deg, s.search.init_error_m) == (2.0, 0.05)


def test_camera_pairs_a_baseline_apart():
    """Each frame with the first one far enough; a slow recording pairs what moved with its
    last frame; the baseline follows the image and the range."""
    steps = np.full(19, 0.4)
    pairs = camera_pairs(steps, 3.9, 1.0)
    assert pairs[0] == (0, 10) and pairs[-1] == (9, 19) and len(pairs) == 10
    slow = np.r_[np.zeros(12), np.full(7, 0.3)]               # stands, then pulls away
    pairs = camera_pairs(slow, 4.0, 1.0)
    assert pairs and all(j == 19 for _, j in pairs) and pairs[-1][0] == 15
    assert camera_pairs(np.zeros(5), 4.0, 1.0) == []
    assert baseline_m(1242, 721.0, 12.0, 0.25) == pytest.approx(5.17, abs=0.01)


def test_too_few_frames_say_why(raw_frames):
    out = wide_start(raw_frames[:2], raw_frames[0].T_ref, _wide())
    assert not out.applied and "at least 3 frames" in out.reasons[0]
    assert out.to_dict()["applied"] is False and out.to_dict()["T_found"] is None


def test_a_static_rig_says_it_cannot_apply(data):
    """PandaSet frames 00-06: the car stands in traffic; no start, and the reason says so."""
    from paretocal.io import load_frames

    root = data / "pandaset" / "front"
    if not root.is_dir():
        pytest.skip(f"PandaSet sample not found at {root}")
    frames = load_frames(root, "0:4")
    out = wide_start(frames, frames[0].T_ref, _wide())
    assert not out.applied and "barely moves" in " ".join(out.reasons)
    assert out.motion == {} and "odometry" in out.seconds


@pytest.mark.parametrize("seed", [0])
def test_wide_start_is_reproducible(raw_frames, seed):
    """The same seed, the same start (the calibration's resume depends on it)."""
    T0 = decalibrate(raw_frames[0].T_ref, 20.0, 1.5, 1000)[0]
    s = _wide(seed=seed)
    frames = raw_frames[:4]
    a, b = wide_start(frames, T0, s), wide_start(frames, T0, s)
    assert a.applied and b.applied, a.reasons
    assert np.array_equal(a.T, b.T) and a.rounds == b.rounds


def test_calibrate_runs_the_wide_start_and_records_it(raw_frames):
    """The library's calibrate from 17 deg / 33 cm off (the first of the README's +-20 deg /
    1.5 m trials) with that wide stated error: the wide start runs first, the usual calibration
    follows from it with the narrower error, and result.json says so."""
    from paretocal import calibrate

    T_ref = raw_frames[0].T_ref
    T0 = decalibrate(T_ref, 20.0, 1.5, 1000)[0]
    r = calibrate(raw_frames, T0, _wide())
    assert r.wide is not None and r.wide.applied
    assert np.allclose(r.wide.T_given, T0) and np.allclose(r.T_init, r.wide.T)
    assert r.wide.images is None and r.wide.scene is None          # its maps are let go
    assert (r.settings.search.init_error_deg, r.settings.search.init_error_m) == (AFTER_DEG,
                                                                                  AFTER_M)
    e = pose_error(r.T_cam_lidar, T_ref)
    assert e["rotation_deg"] < 1.0 and e["translation_cm"] < 10.0
    assert r.reliability.verdict == "ok", r.reliability.reasons
    doc = r.to_dict()
    assert doc["wide_start"]["applied"] and "wide" in doc["timings_s"]
    w = doc["wide_start"]
    # The motion fixed two angles (a straight drive leaves the third free), the search found
    # the rest; the start found lies within 0.5 deg / 5 cm of the reference.
    assert w["motion"]["directions"] > 0 and w["motion"]["free_axis_lidar"] is not None
    e = pose_error(np.array(w["T_found"]), T_ref)
    assert e["rotation_deg"] < 0.5 and e["translation_cm"] < 5.0
    assert not w["ambiguous"] and w["rounds"] and w["basins"][0]["photo"] > 0
    # Photo-consistency agrees with the calibration that followed.
    assert w["photo_check"]["agree"], w["photo_check"]
    assert r.wide.photo is not None and w["photo_check"] == r.wide.photo.to_dict()
