"""Several cameras, one LiDAR, one run: a rig folder made at run time from the aiMotive sample
(front pinhole + left Mei fisheye over one points/ folder)."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from paretocal.cli import main
from paretocal.config import Settings
from paretocal.errors import InputError, ParetocalError
from paretocal.geometry import invert, pose_error
from paretocal.io import detect_source, is_rig, load_rig_frames, read_extrinsic, rig_cameras

from .conftest import data_dir

# Absolute: the rig's symbolic links are made in a temporary folder.
DATA = data_dir() / "aimotive"
pytestmark = pytest.mark.skipif(not (DATA / "front_pinhole" / "calib.yaml").is_file(),
                                reason="aiMotive sample not available")


def _entry(name: str, folder: str) -> dict:
    calib = yaml.safe_load((DATA / folder / "calib.yaml").read_text())
    return {"name": name, "camera": calib["camera"], "T_cam_lidar": calib["T_cam_lidar"],
            "images": f"{name}_images"}


def make_rig(tmp_path: Path, edit=None) -> Path:
    """A rig folder in tmp_path: calib.yaml with both cameras; image folders and points/ are
    links into the dataset. ``edit(data)`` changes calib.yaml's content before it is written."""
    rig = tmp_path / "rig"
    rig.mkdir()
    (rig / "points").symlink_to(DATA / "points")
    (rig / "front_images").symlink_to(DATA / "front_pinhole" / "images")
    (rig / "left_images").symlink_to(DATA / "left_fisheye" / "images")
    data = {"cameras": [_entry("front", "front_pinhole"), _entry("left", "left_fisheye")]}
    if edit is not None:
        edit(data)
    (rig / "calib.yaml").write_text(yaml.safe_dump(data))
    return rig


def test_rig_layout(tmp_path):
    rig = make_rig(tmp_path)
    assert is_rig(rig) and not is_rig(DATA / "front_pinhole")
    cams = rig_cameras(rig)
    assert [n for n, _ in cams] == ["front", "left"]
    front, left = (s for _, s in cams)
    assert front.frames[0].camera.model == "pinhole" and left.frames[0].camera.model == "mei"
    single = detect_source(DATA / "left_fisheye")
    np.testing.assert_allclose(left.frames[0].T_ref, single.frames[0].T_ref)
    assert [f.name for f in left.frames] == [f.name for f in single.frames]
    # One cloud read for both cameras.
    frames = load_rig_frames(cams, "0:2")
    assert frames["front"][1].points is frames["left"][1].points
    # A single-camera command on a rig says what to do.
    with pytest.raises(InputError, match=r"name one with --camera NAME \('paretocal calibrate' "
                                         r"takes all of them\)"):
        detect_source(rig)


def test_one_camera_of_a_rig_is_checked_by_name(tmp_path, capfd):
    """``check --camera NAME`` reads that camera of a rig folder, as ``calibrate --camera``
    does (issue 45: it took only a KITTI index); without a name it says which there are."""
    from .helpers import run_cli

    rig = make_rig(tmp_path)
    out = tmp_path / "check.json"
    code, stdout, err = run_cli(capfd, "check", rig, "--camera", "left", "--frames", "0",
                                "--out", out, "--quiet")
    assert code == 0, err
    doc = json.loads(out.read_text())
    left = dict(rig_cameras(rig))["left"]
    np.testing.assert_array_equal(doc["T_checked"], left.frames[0].T_ref)
    assert doc["frames"] == [left.frames[0].name]
    code, _, err = run_cli(capfd, "check", rig)
    assert code == 2 and "name the camera with --camera (front, left)" in err
    code, _, err = run_cli(capfd, "depth", rig, "--camera", "rear", "--out", tmp_path / "d")
    assert code == 2 and "--camera rear: " in err and "lists the cameras front, left" in err


def test_mapping_form(tmp_path):
    def as_mapping(d):
        d["cameras"] = {e.pop("name"): e for e in d["cameras"]}
    assert [n for n, _ in rig_cameras(make_rig(tmp_path, as_mapping))] == ["front", "left"]


def _dup(d):
    d["cameras"][1]["name"] = "front"


def _no_images(d):
    d["cameras"][1]["images"] = "nowhere"


def _no_T(d):
    del d["cameras"][0]["T_cam_lidar"]


def _no_name(d):
    del d["cameras"][1]["name"]


def _unknown_key(d):
    d["cameras"][0]["extrinsic"] = 1


def _bad_K(d):
    d["cameras"][1]["camera"]["K"] = [[1, 0], [0, 1]]


def _top_level_camera(d):
    d["camera"] = d["cameras"][0]["camera"]


def _not_a_list(d):
    d["cameras"] = "front"


def _empty(d):
    d["cameras"] = []


def _slash(d):
    d["cameras"][0]["name"] = "a/b"


def _top_level_typo(d):
    d["lidar_pos"] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]


def _camera_typo(d):
    d["cameras"][1]["camera"]["widht"] = d["cameras"][1]["camera"].pop("width")


@pytest.mark.parametrize("edit, words", [
    (_not_a_list, ["cameras must be a list of cameras"]),
    (_empty, ["cameras lists no camera"]),
    (_slash, ["cameras[0].name 'a/b'"]),
    (_dup, ["cameras", "'front' is given twice"]),
    (_no_images, ["cameras.left.images", "nowhere"]),
    (_no_T, ["cameras.front.T_cam_lidar is missing"]),
    (_no_name, ["cameras[1].name is missing"]),
    (_unknown_key, ["cameras.front", "extrinsic"]),
    (_bad_K, ["cameras.left: camera.K"]),
    (_top_level_camera, ["camera at the top level and 'cameras'"]),
    (_top_level_typo, ["calib.yaml: unknown key(s) lidar_pos (expected cameras, lidar_pose,"]),
    (_camera_typo, ["cameras.left: camera: unknown key(s) widht (expected K, width,"]),
])
def test_bad_rig_calib_exits_2(tmp_path, capsys, edit, words):
    rig = make_rig(tmp_path, edit)
    status = main(["calibrate", str(rig), "--out", str(tmp_path / "out"), "--no-figures"])
    err = capsys.readouterr().err
    assert status == 2, err
    for w in words:
        assert w in err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, words", [
    (["--camera", "right"], ["--camera right", "front, left"]),
    (["--init", "x.yaml"], ["--init x.yaml", "--camera NAME"]),
    (["single"], ["--camera front: a KITTI camera index", "rig folder"]),
    (["--joint", "--camera", "left"], ["--camera left", "--joint calibrates every camera"]),
    (["single", "--joint"], ["--joint", "not a rig folder"]),
])
def test_bad_rig_options_exit_2(tmp_path, capsys, args, words):
    rig = make_rig(tmp_path)
    if "single" in args:
        args = ["--joint"] if "--joint" in args else ["--camera", "front"]
        rig = DATA / "front_pinhole"
    status = main(["calibrate", str(rig), "--out", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err
    assert status == 2, err
    for w in words:
        assert w in err


def test_lidar_steps_for_another_camera(tmp_path):
    """LiDAR steps done with one camera's frames give another camera's frames their points
    and sensor pose and keep that camera's image, model, reference and mask; frames over other
    clouds are refused. (That the steps are the camera's own is checked on the aiMotive
    frames by hand: too slow for the suite.)"""
    import dataclasses

    from paretocal.inputs import LidarSteps, lidar_settings_key

    frames = load_rig_frames(rig_cameras(make_rig(tmp_path)), "0:2")
    done = [dataclasses.replace(f, points=f.points[:10].copy(), sensor_pose=np.eye(4))
            for f in frames["front"]]
    steps = LidarSteps(done, {"source": "test"}, [None, None], {}, lidar_settings_key(Settings()))
    got = steps.for_camera(frames["left"])
    for g, d, f in zip(got, done, frames["left"]):
        assert g.points is d.points and g.sensor_pose is d.sensor_pose
        assert g.image is f.image and g.camera is f.camera and g.mask is f.mask
        np.testing.assert_array_equal(g.T_ref, f.T_ref)
    with pytest.raises(ValueError, match="same clouds"):
        steps.for_camera(frames["left"][::-1])


def test_two_camera_run(tmp_path, capsys):
    """Both cameras' run folders and rig.json; the implied pair is the one the two results
    give; started at calib.yaml's extrinsics, the initial pair is the reference pair."""
    from paretocal.apps.rig import RIG_JSON, calibrate_rig
    from paretocal.rundir import run_arguments

    rig = make_rig(tmp_path)
    cams = dict(rig_cameras(rig))
    T_ref = {n: s.frames[0].T_ref for n, s in cams.items()}
    settings = Settings(frames="0:2").replace(search={"pop": 12, "gens": 2},
                                               decision={"polish": False, "restarts": 0})
    out = tmp_path / "out"
    summary = calibrate_rig(rig, out, settings, T_inits=dict(T_ref), figures=False)
    assert summary["lidar_steps_done"] == 1
    for name in ("front", "left"):
        assert (out / name / "result.json").is_file()
        assert run_arguments(out / name)["rig_camera"] == name
    with pytest.raises(ParetocalError, match="resume one camera with --resume"):
        run_arguments(out)
    on_disk = json.loads((out / RIG_JSON).read_text())
    assert [c["name"] for c in on_disk["cameras"]] == ["front", "left"]
    T = {n: np.asarray(json.loads((out / n / "result.json").read_text())["T_cam_lidar"])
         for n in ("front", "left")}
    (pair,) = on_disk["pairs"]
    assert pair["cameras"] == ["front", "left"]
    np.testing.assert_allclose(pair["T_a_b"], T["front"] @ invert(T["left"]), atol=1e-6)
    e = pose_error(T["front"] @ invert(T["left"]), T_ref["front"] @ invert(T_ref["left"]))
    assert pair["vs_reference"]["rotation_deg"] == pytest.approx(float(e["rotation_deg"]),
                                                                 abs=1e-3)
    assert pair["initial_vs_reference"]["rotation_deg"] < 1e-6
    assert pair["initial_vs_reference"]["translation_cm"] < 1e-6
    ov = pair["overlap"]
    assert 0 <= ov["points_in_both"] <= min(ov["points_in_view_a"], ov["points_in_view_b"])
    assert pair["consistency"]["verdict"] in ("consistent", "inconsistent", "not checked")


def test_one_camera_of_the_rig_from_the_command_line(tmp_path, capsys):
    """``--camera NAME`` calibrates that camera into OUT/NAME/ (no rig.json), from --init."""
    rig = make_rig(tmp_path)
    config = tmp_path / "fast.yaml"
    # Fast: no de-skew and rings by elevation (no sensor pose to estimate).
    config.write_text("decision: {restarts: 0}\nmotion: {deskew: \"off\"}\n"
                      "features: {ring_method: elevation}\n")
    out = tmp_path / "out"
    status = main(["calibrate", str(rig), "--out", str(out), "--camera", "left", "--init",
                   str(DATA / "left_fisheye" / "calib.yaml"), "--frames", "0:2", "--pop", "12",
                   "--gens", "2", "--no-polish", "--no-figures", "--config", str(config)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "camera left: 2 frames" in captured.out
    assert "error vs reference: n/a" not in captured.out
    assert (out / "left" / "result.json").is_file()
    assert not (out / "front").exists() and not (out / "rig.json").exists()


def test_a_camera_that_fails_is_named(tmp_path, capsys):
    """A camera whose images hold no edges stops the rig with exit 2 naming the camera."""
    import cv2

    def black_left(d):
        d["cameras"] = d["cameras"][::-1]
        d["cameras"][0]["images"] = "black"
    rig = make_rig(tmp_path, black_left)
    (rig / "black").mkdir()
    for f in sorted((DATA / "left_fisheye" / "images").iterdir())[:2]:
        cv2.imwrite(str(rig / "black" / f.name), np.zeros((704, 1280, 3), np.uint8))
    config = tmp_path / "fast.yaml"
    config.write_text("motion: {deskew: \"off\"}\nfeatures: {ring_method: elevation}\n")
    status = main(["calibrate", str(rig), "--out", str(tmp_path / "out"), "--frames", "0:2",
                   "--no-figures", "--config", str(config)])
    err = capsys.readouterr().err
    assert status == 2, err
    assert "paretocal: error: camera left: " in err and not (tmp_path / "out" / "front").exists()


def test_resume_loads_the_recorded_camera(tmp_path, monkeypatch):
    """A rig camera's run folder records the camera; a resume loads that camera's frames
    (the calibration itself is stubbed out here)."""
    import paretocal.rundir as rundir

    rig = make_rig(tmp_path)
    run = tmp_path / "out" / "left"
    run.mkdir(parents=True)
    (run / rundir.RUN_ARGS).write_text(json.dumps({
        "source": str(rig), "T_init": None, "settings": Settings(frames="0:2").to_dict(),
        "figures": False, "rig_camera": "left"}))
    seen = {}

    class Stop(Exception):
        pass

    def stub(frames, *args, **kwargs):
        seen["models"] = {f.camera.model for f in frames}
        seen["images"] = {f.image_path.parent.name for f in frames}
        raise Stop
    monkeypatch.setattr(rundir, "calibrate", stub)
    with pytest.raises(Stop):
        rundir.resume_run(run)
    assert seen == {"models": {"mei"}, "images": {"left_images"}}


def test_joint_run_from_the_command_line(tmp_path, capsys):
    """``--joint``: one run folder OUT/joint over both cameras' frames, the second camera seen
    through its mount (calib.yaml's camera-to-camera pose); rig.json holds every camera's
    extrinsic, which keeps that pose; the run records the cameras for a resume."""
    from paretocal.apps.rig import RIG_JSON
    from paretocal.rundir import run_arguments

    rig = make_rig(tmp_path)
    cams = dict(rig_cameras(rig))
    T_ref = {n: s.frames[0].T_ref for n, s in cams.items()}
    config = tmp_path / "fast.yaml"
    config.write_text("decision: {restarts: 0}\nmotion: {deskew: \"off\"}\n"
                      "features: {ring_method: elevation}\n")
    out = tmp_path / "out"
    status = main(["calibrate", str(rig), "--out", str(out), "--joint", "--init",
                   str(DATA / "front_pinhole" / "calib.yaml"), "--frames", "0:2", "--pop", "12",
                   "--gens", "2", "--no-polish", "--no-figures", "--config", str(config)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "cameras front, left at once: 4 frames" in captured.out
    doc = json.loads((out / "joint" / "result.json").read_text())
    assert doc["frames"] == [f"{c}/{n}" for c in ("front", "left")
                             for n in ("0033643", "0033645")]
    assert run_arguments(out / "joint")["joint"] == ["front", "left"]
    with pytest.raises(ParetocalError, match="resume the cameras at once with --resume .*joint"):
        run_arguments(out)
    summary = json.loads((out / RIG_JSON).read_text())
    assert summary["joint"] is True and summary["pairs"] == []
    T = {c["name"]: np.asarray(c["T_cam_lidar"]) for c in summary["cameras"]}
    np.testing.assert_allclose(T["front"], doc["T_cam_lidar"], atol=1e-8)
    np.testing.assert_allclose(T["left"] @ invert(T["front"]),
                               T_ref["left"] @ invert(T_ref["front"]), atol=1e-7)
    assert {c["verdict"] for c in summary["cameras"]} == {doc["reliability"]["verdict"]}
    for c in summary["cameras"]:
        assert c["extrinsic_file"] == f"extrinsic_{c['name']}.yaml"
        np.testing.assert_allclose(read_extrinsic(out / c["extrinsic_file"]), T[c["name"]],
                                   atol=1e-8)
    assert not (out / "front").exists() and not (out / "left").exists()


def test_joint_frames_see_the_first_camera_through_their_mounts(tmp_path, monkeypatch):
    """A joint run folder's resume loads both cameras' frames as one set: the second camera's
    frames carry the mount ``T_left @ inv(T_front)`` and the first camera's reference (the
    calibration itself is stubbed out here); a camera without a stated extrinsic is refused."""
    import paretocal.rundir as rundir
    from paretocal.inputs import joint_frames

    rig = make_rig(tmp_path)
    run = tmp_path / "out" / "joint"
    run.mkdir(parents=True)
    # Fast: no de-skew and rings by elevation (the LiDAR steps are not what is tested).
    fast = Settings(frames="0:2").replace(motion={"deskew": "off"},
                                          features={"ring_method": "elevation"})
    (run / rundir.RUN_ARGS).write_text(json.dumps({
        "source": str(rig), "T_init": None, "settings": fast.to_dict(),
        "figures": False, "joint": ["front", "left"]}))
    seen = {}

    class Stop(Exception):
        pass

    def stub(frames, *args, lidar=None, **kwargs):
        seen["frames"], seen["lidar"] = frames, lidar
        raise Stop
    monkeypatch.setattr(rundir, "calibrate", stub)
    with pytest.raises(Stop):
        rundir.resume_run(run)
    frames = seen["frames"]
    assert [f.name for f in frames] == [f"{c}/{n}" for c in ("front", "left")
                                        for n in ("0033643", "0033645")]
    assert seen["lidar"].frames is frames and len(seen["lidar"].rings) == 4
    T_ref = {n: s.frames[0].T_ref for n, s in rig_cameras(rig)}
    assert frames[0].camera.mount is None
    np.testing.assert_allclose(frames[2].camera.mount, T_ref["left"] @ invert(T_ref["front"]),
                               atol=1e-12)
    for f in frames:
        np.testing.assert_allclose(f.T_ref, T_ref["front"])
    # The same points project where the left camera alone puts them.
    from paretocal.camera import project
    single = load_rig_frames(rig_cameras(rig), "0:1")["left"][0]
    np.testing.assert_allclose(project(single.points, frames[2].camera, T_ref["front"])[0],
                               project(single.points, single.camera, T_ref["left"])[0],
                               atol=1e-6)
    import dataclasses

    bare = load_rig_frames(rig_cameras(rig), "0:1")
    bare["left"] = [dataclasses.replace(bare["left"][0], T_ref=None)]
    with pytest.raises(InputError, match="camera left: .*stated T_cam_lidar"):
        joint_frames(bare)
