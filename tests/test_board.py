"""The checkerboard: calib.yaml's ``board:`` section and board.yaml, the board in the image and in
the cloud, the closed form from no initial guess and the board's terms of the objective, on the
real LCE-Calib recordings (lce_board/) and on exact synthetic boards."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from paretocal.errors import InputError
from paretocal.io import load_frames
from paretocal.io.board import Board, read_board

LCE = ("walkway_a", "walkway_b")


def lce(data: Path, name: str) -> Path:
    root = data / "lce_board" / name
    if not (root / "calib.yaml").is_file():
        pytest.skip("lce_board not present")
    return root


def variant(src: Path, dst: Path, board: str = "section", with_T: bool = True,
            edit=None) -> Path:
    """A generic folder over ``src``'s frames (symbolic links) whose calib.yaml holds the board
    as a ``board:`` section (``board="section"``), beside it as board.yaml (``"file"``) or not
    at all (``"none"``); ``with_T`` False leaves ``T_cam_lidar`` out; ``edit(calib)`` changes
    the calib.yaml mapping last."""
    dst.mkdir(parents=True, exist_ok=True)
    for sub in ("images", "points"):
        os.symlink((src / sub).resolve(), dst / sub)
    calib = yaml.safe_load((src / "calib.yaml").read_text())
    section = yaml.safe_load((src / "board.yaml").read_text())["board"]
    if not with_T:
        calib.pop("T_cam_lidar")
    if board == "section":
        calib["board"] = section
    elif board == "file":
        os.symlink((src / "board.yaml").resolve(), dst / "board.yaml")
    if edit is not None:
        edit(calib)
    (dst / "calib.yaml").write_text(yaml.safe_dump(calib))
    return dst


# --- calib.yaml's board: and board.yaml ---------------------------------------------------------

def test_the_lce_board_is_read_from_board_yaml_beside_calib_yaml(data):
    frames = load_frames(lce(data, "walkway_b"), "0:2")
    b = frames[0].board
    assert b == Board(squares=(9, 7), square_m=0.07, size_m=(0.767, 0.626))
    assert b.inner == (8, 6)
    assert np.allclose(b.margin_m, (0.0685, 0.068))
    corners = b.corners_m()
    assert corners.shape == (48, 3) and np.allclose(corners.mean(axis=0), 0.0)
    assert np.isclose(np.ptp(corners[:, 0]), 7 * 0.07) and np.isclose(np.ptp(corners[:, 1]), 0.35)
    centres, parity = b.square_centres_m()
    assert centres.shape == (63, 3) and parity.sum() == 31
    assert np.allclose(np.ptp(b.outline_m(), axis=0)[:2], (0.767, 0.626))


def test_a_board_section_in_calib_yaml_and_in_a_rig(data, tmp_path):
    root = variant(lce(data, "walkway_b"), tmp_path / "v")
    assert load_frames(root, "0")[0].board.squares == (9, 7)
    none = variant(lce(data, "walkway_b"), tmp_path / "n", board="none")
    assert load_frames(none, "0")[0].board is None
    # A rig: the top-level board is every camera's, a camera's own replaces it.
    calib = yaml.safe_load((root / "calib.yaml").read_text())
    cam = {"name": "c", "camera": calib["camera"], "T_cam_lidar": calib["T_cam_lidar"],
           "images": "images"}
    other = dict(cam, name="d", board={"kind": "checkerboard", "squares": [7, 5],
                                       "square_m": 0.07, "size_m": [0.6, 0.5]})
    (root / "calib.yaml").write_text(yaml.safe_dump(
        {"cameras": [cam, other], "board": calib["board"]}))
    from paretocal.io import rig_cameras

    boards = {n: s.frames[0].board for n, s in rig_cameras(root)}
    assert boards["c"].squares == (9, 7) and boards["d"].squares == (7, 5)


@pytest.mark.parametrize("section, expect", [
    ({"kind": "circles", "squares": [9, 7], "square_m": 0.07, "size_m": [0.8, 0.6]},
     "board.kind 'circles' is not one of checkerboard"),
    ({"kind": "checkerboard", "squares": [9], "square_m": 0.07, "size_m": [0.8, 0.6]},
     "board.squares must be two whole numbers of at least 3"),
    ({"kind": "checkerboard", "squares": [9, 2], "square_m": 0.07, "size_m": [0.8, 0.6]},
     "board.squares must be two whole numbers of at least 3"),
    ({"kind": "checkerboard", "squares": [9.5, 7], "square_m": 0.07, "size_m": [0.8, 0.6]},
     "board.squares must be two whole numbers"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": 0.07, "size_m": [0.6, 0.6]},
     "board.size_m: the board's width 0.6 m is smaller than its 9 squares of 0.07 m (0.63 m)"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": -1, "size_m": [0.8, 0.6]},
     "board.square_m must be a positive number of metres"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": 0.07, "size_m": "big"},
     "board.size_m must be two positive numbers of metres"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": 0.07},
     "board.size_m is missing"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": 0.07, "size_m": [0.767, 0.626],
      "margin_mm": [100, 136]}, "board.margin_mm [100, 136] disagrees with size_m minus the "
     "squares (137, 136 mm)"),
    ({"kind": "checkerboard", "squares": [9, 7], "square_m": 0.07, "size_m": [0.8, 0.6],
      "colour": "red"}, "board: unknown key(s) colour"),
    ("checkerboard", "board must be a mapping"),
])
def test_bad_boards_are_one_line_naming_the_key(section, expect):
    with pytest.raises(InputError) as err:
        read_board(section, "calib.yaml")
    assert str(err.value).startswith("calib.yaml: ") and expect in str(err.value)


def test_bad_boards_exit_2_from_the_command_line(data, tmp_path, capfd):
    from .helpers import bad_cli

    bad = variant(lce(data, "walkway_b"), tmp_path / "v",
                  edit=lambda c: c["board"].update(squares=[9, 1]))
    bad_cli(capfd, "calibrate", bad, "--out", tmp_path / "o",
            expect=(f"{bad / 'calib.yaml'}: board.squares must be two whole numbers",))
    both = variant(lce(data, "walkway_b"), tmp_path / "w", board="file",
                   edit=lambda c: c.update(board={"kind": "checkerboard"}))
    bad_cli(capfd, "check", both, expect=("board is given here and in",))


# --- the board in the image ---------------------------------------------------------------------

@pytest.fixture(scope="session")
def lce_frames(data):
    """Every frame of both LCE-Calib recordings, by recording."""
    return {name: load_frames(lce(data, name)) for name in LCE}


@pytest.fixture(scope="session")
def lce_views(lce_frames):
    from paretocal.features.board import find_board

    return {name: [find_board(f.image, f.camera, f.board) for f in frames]
            for name, frames in lce_frames.items()}


@pytest.mark.parametrize("name", LCE)
def test_corners_are_found_in_every_frame_and_fit_the_lens_model(lce_frames, lce_views, name):
    import cv2

    views = lce_views[name]
    found = [v for v in views if v is not None]
    assert len(found) >= 0.9 * len(views)
    assert len(found) == len(views)                      # measured: 29 of 29, 15 of 15
    for f, v in zip(lce_frames[name], views):
        assert v.rms_px < 1.0 and v.ordered == 1.0
        assert np.isclose(np.linalg.norm(v.normal), 1.0) and v.normal @ v.centre_cam < 0
        # OpenCV's own undistortion and solver agree with the pose through the lens model.
        cam = f.camera
        xy = cv2.undistortPoints(v.corners_uv.reshape(-1, 1, 2), cam.K, np.array(cam.D))
        ok, rvec, tvec = cv2.solvePnP(f.board.corners_m(), xy, np.eye(3), None)
        R = cv2.Rodrigues(rvec)[0]
        n_cv = R[:, 2] * np.sign(-(R[:, 2] @ tvec.ravel()))
        assert np.degrees(np.arccos(min(1.0, n_cv @ v.normal))) < 0.5
        assert abs(float(-(n_cv @ tvec.ravel())) - v.distance_m) < 0.01 * v.distance_m
        # The outline is the board's size, around the corners' centre.
        o = v.outline_cam
        assert np.isclose(np.linalg.norm(o[1] - o[0]), 0.767) and \
            np.isclose(np.linalg.norm(o[3] - o[0]), 0.626)
        assert np.allclose(o.mean(axis=0), v.centre_cam)


def _look_at(centre, tilt_deg):
    """A board pose at ``centre`` (camera frame, m) facing the camera, turned by ``tilt_deg``
    (yaw, pitch, roll about its own axes)."""
    from paretocal.geometry import rotation_zyx

    z = -np.asarray(centre, float) / np.linalg.norm(centre)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z]) @ rotation_zyx(*tilt_deg)
    T[:3, 3] = centre
    return T


#: Lenses at half the LCE camera's size (a quarter of the rays to render), and how near each
#: sees the board with squares of 14-20 px (its focal length at the centre: f, f, f / (1 + xi)).
SYNTH_CAMERAS = {
    "pinhole": dict(K=[[450, 0, 320], [0, 450, 180], [0, 0, 1]], D=(-0.44, 0.23, 0, 0, -0.07)),
    "fisheye": dict(K=[[175, 0, 320], [0, 175, 180], [0, 0, 1]], model="fisheye",
                    D=(0.05, -0.01, 0.002, 0)),
    "mei": dict(K=[[250, 0, 320], [0, 250, 180], [0, 0, 1]], model="mei", xi=1.2,
                D=(-0.1, 0.02, 0, 0)),
}
SYNTH_NEAR = {"pinhole": 1.0, "fisheye": 0.5, "mei": 0.35}


@pytest.mark.parametrize("model", SYNTH_CAMERAS)
@pytest.mark.parametrize("centre, tilt", [((0.0, 0.0, 1.6), (10, 20, 10)),
                                          ((0.9, 0.3, 1.5), (30, -20, 25)),
                                          ((-1.3, -0.3, 1.2), (-15, 25, -10))])
def test_an_exact_board_is_found_through_every_lens_model(model, centre, tilt):
    from .helpers import render_board

    from paretocal.camera import Camera
    from paretocal.features.board import find_board

    cam = Camera(width=640, height=360, **SYNTH_CAMERAS[model])
    board = Board((9, 7), 0.07, (0.767, 0.626))
    centre = SYNTH_NEAR[model] * np.array(centre)
    T = _look_at(centre, tilt)
    uv = cam.project_camera_points(centre)[0]
    if not (np.isfinite(uv).all() and 0 < uv[0] < cam.width):
        pytest.skip("outside this lens's image")
    v = find_board(render_board(cam, board, T), cam, board)
    # Squares of 8-19 px at this size: the pose to a fraction of a degree and a centimetre.
    assert v is not None and v.rms_px < 0.3
    assert np.degrees(np.arccos(min(1.0, v.normal @ T[:3, 2]))) < 1.0
    assert np.linalg.norm(v.centre_cam - T[:3, 3]) < 0.005 * np.linalg.norm(centre)


def test_the_perspective_view_maps_corners_back_through_the_lens():
    from .helpers import render_board

    import cv2

    from paretocal.camera import Camera
    from paretocal.features.board import _from_view, perspective_view

    cam = Camera(width=640, height=360, **SYNTH_CAMERAS["fisheye"])
    board = Board((9, 7), 0.07, (0.767, 0.626))
    T = _look_at((-0.8, 0.2, 1.0), (0, 10, 0))
    img = render_board(cam, board, T)
    view, K_view = perspective_view(img, cam)
    ok, c = cv2.findChessboardCornersSB(view, board.inner, flags=cv2.CALIB_CB_ACCURACY)
    assert ok
    back = _from_view(c.reshape(-1, 2).astype(float), K_view, cam)
    truth = cam.project_camera_points(board.corners_m() @ T[:3, :3].T + T[:3, 3])[0]
    err = np.min(np.linalg.norm(back[:, None] - truth[None], axis=2), axis=1)
    assert np.median(err) < 0.3


def test_a_board_described_wrong_is_not_found(lce_frames):
    from paretocal.features.board import find_board

    f = lce_frames["walkway_b"][0]
    assert find_board(f.image, f.camera, Board((8, 7), 0.07, (0.767, 0.626))) is None


# --- the board in the cloud, the closed form --------------------------------------------------

@pytest.fixture(scope="session")
def lce_starts(lce_frames):
    """The board stage on both recordings, with the rings the pipeline recovers."""
    from paretocal.board import board_start
    from paretocal.config import Settings
    from paretocal.inputs import sweep_rings

    return {name: board_start(frames, Settings(), sweep_rings(frames, Settings()))
            for name, frames in lce_frames.items()}


@pytest.mark.parametrize("name", LCE)
def test_the_board_is_found_in_every_sweep_and_lies_on_the_image_board(lce_frames, lce_starts,
                                                                      name):
    """No extrinsic: what moved between sweeps, planar, of the board's size; at the reference
    its returns lie on the plane the image's corners give (measured: medians within 2.3 cm,
    1 cm range noise; 29 of 29 and 15 of 15 frames)."""
    frames, start = lce_frames[name], lce_starts[name]
    assert start.geometry.ring_gap_deg == pytest.approx(2.0, abs=0.05)      # a VLP-16
    assert start.geometry.azimuth_step_deg == pytest.approx(0.2, abs=0.02)
    assert 0.003 < start.geometry.sigma_m < 0.03
    found = [f for f in start.frames if f.cloud is not None]
    assert len(found) >= 0.9 * len(frames)
    T_ref = frames[0].T_ref
    for f, bf in zip(frames, start.frames):
        c = bf.cloud
        assert c.rings >= 3 and c.extent_m[1] < np.hypot(*f.board.size_m) + 0.1
        p = f.points[c.index, :3] @ T_ref[:3, :3].T + T_ref[:3, 3]
        r = p @ bf.image.normal + bf.image.distance_m
        assert abs(np.median(r)) < 0.03, (f.name, np.median(r))
        assert bf.used and bf.points >= 50 and bf.ends >= 6


@pytest.mark.parametrize("name", LCE)
def test_the_closed_form_needs_no_guess_and_is_refined_to_the_reference(lce_frames, lce_starts,
                                                                        name):
    """Measured: the closed form 0.76 deg / 1.6 cm (walkway_a) and 0.38 deg / 3.1 cm
    (walkway_b) from the reference, refined by the boards' residuals 0.38 deg / 1.1 cm and
    0.39 deg / 2.8 cm; the rotation about the boards' mean normal to +-0.27 and 0.37 deg."""
    from paretocal.geometry import pose_error

    start = lce_starts[name]
    T_ref = lce_frames[name][0].T_ref
    assert start.applied and not start.reasons and start.conditioning.ok
    closed = pose_error(start.T_closed, T_ref)
    assert closed["rotation_deg"] < 1.0 and closed["translation_cm"] < 5.0
    refined = pose_error(start.T, T_ref)
    assert refined["rotation_deg"] < 0.5 and refined["translation_cm"] < 3.5
    c = start.conditioning
    assert c.boards == len(lce_frames[name]) and c.spread_deg > 10
    assert c.rotation_se_deg < 0.5 and c.translation_se_m < 0.05
    s = start.scene
    assert s.n_boards == len(lce_frames[name])
    assert 0.004 < s.sigma_plane_m < 0.015 and 0.002 < s.sigma_outline_m < 0.015


def _planes_of(T: np.ndarray, normals_cam: np.ndarray, d_cam: np.ndarray):
    """The LiDAR's view of camera planes (normal towards the sensor) under ``T`` (LiDAR to
    camera): ``n_l = R^T n_c``, ``d_l = d_c + n_c . t``."""
    n_l = normals_cam @ T[:3, :3]
    d_l = d_cam + normals_cam @ T[:3, 3]
    return n_l, d_l


def test_the_closed_form_is_exact_and_says_what_parallel_boards_leave_free():
    from paretocal.geometry import apply_correction, pose_error
    from paretocal.search.board import closed_form, conditioning

    rng = np.random.default_rng(4)
    T = apply_correction(np.eye(4), [0.1, -0.2, 0.05, 40.0, -10.0, 95.0])
    n = rng.normal(size=(6, 3)) * [0.4, 0.3, 0.1] + [0, 0, -1]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.uniform(1.5, 3.0, 6)
    n_l, d_l = _planes_of(T, n, d)
    got = closed_form(n_l, d_l, n, d)
    e = pose_error(got, T)
    assert e["rotation_deg"] < 1e-9 and e["translation_cm"] < 1e-9
    assert conditioning(got, n_l, d_l, n, d).ok
    # Boards all turned alike, with a little noise on the normals: the rotation about their
    # common normal (the optical axis here) is not fixed, and the words say so.
    par = np.tile([0.0, 0.0, -1.0], (6, 1)) + rng.normal(size=(6, 3)) * 1e-3
    par /= np.linalg.norm(par, axis=1, keepdims=True)
    n_l, d_l = _planes_of(T, par, d)
    n_l = n_l + rng.normal(size=n_l.shape) * 2e-3           # the LiDAR's noise: 0.1 deg, 5 mm
    n_l /= np.linalg.norm(n_l, axis=1, keepdims=True)
    d_l = d_l + rng.normal(size=d_l.shape) * 0.005
    c = conditioning(closed_form(n_l, d_l, par, d), n_l, d_l, par, d)
    assert not c.ok
    assert any("rotation about the camera's optical axis (z) free" in t for t in c.notes)
    assert any("translation along" in t for t in c.notes)


# --- the board's terms of the objective ---------------------------------------------------------

def test_the_board_kernel_matches_its_oracle_and_its_optimum_is_the_refined_start(lce_starts):
    from paretocal.geometry import apply_correction
    from paretocal.objective.board import board_sums, board_sums_numpy, board_terms

    start = lce_starts["walkway_b"]
    rng = np.random.default_rng(7)
    X = rng.normal(size=(64, 6)) * [0.02, 0.02, 0.02, 0.5, 0.5, 0.5]
    X[0] = 0.0
    T = apply_correction(start.T, X)
    a, b = board_sums(start.scene, T), board_sums_numpy(start.scene, T)
    assert np.allclose(a[0], b[0], rtol=1e-12, atol=1e-12)
    assert np.allclose(a[1], b[1], rtol=1e-12, atol=1e-12)
    cost = board_terms(start.scene, T)["cost"].sum(axis=1)
    assert np.argmin(cost) == 0                     # the refined start is the board's optimum
    # At the optimum a return costs about its noise: rho(1) / rho(3) of the truncation.
    per_frame = board_terms(start.scene, T[:1])["cost"][0]
    assert np.all(per_frame < 0.6 * start.scene.truncation_px)


def test_the_board_objective_adds_the_boards_to_their_frames_only(lce_frames, lce_starts):
    from paretocal.board import board_settings
    from paretocal.config import Settings
    from paretocal.objective.board import board_terms
    from paretocal.stage import Stage

    frames = lce_frames["walkway_b"][:5]
    start = lce_starts["walkway_b"]
    keep = [0, 2, 4]
    # Three of five frames show the board (their board terms are those of frames 0, 2, 4).
    sub = start.scene.select(keep)
    assert sub.names == ("00", "02", "04") and sub.n_boards == 3
    assert np.array_equal(sub.frames, keep)
    st = Stage(frames, start.T, start.T, board_settings(Settings()), board=sub)
    X = np.zeros((3, 7))
    X[:, 6] = st.n_max
    X[1, 3] = 0.5
    X[2, 0] = 0.03
    both = st.objective.chamfer(X)
    edges = st.objective.edges.chamfer(X)
    added = both["per_frame"] - edges["per_frame"]
    assert np.allclose(added[:, [1, 3]], 0.0)
    cost = board_terms(sub, st.objective.transforms(X))["cost"]
    assert np.allclose(added[:, keep], cost)
    assert np.allclose(both["f1"], edges["f1"] + cost.sum(axis=1) / 5)
    assert np.all(both["board"][1:] > both["board"][0])      # off the board's optimum costs
    assert np.allclose(st.objective.evaluate(X)[:, 1], st.objective.edges.cost(X)["f2"])


# --- the verdict ------------------------------------------------------------------------------

def test_a_board_found_nowhere_and_parallel_boards_are_reasons_in_words(lce_frames):
    import dataclasses

    from paretocal.board import RECORD_ADVICE, BoardStart, board_start
    from paretocal.config import Settings
    from paretocal.search.board import Conditioning

    wrong = Board((8, 5), 0.07, (0.767, 0.626))
    frames = [dataclasses.replace(f, board=wrong) for f in lce_frames["walkway_b"][:3]]
    start = board_start(frames, Settings())
    assert not start.applied and start.found_in_images == 0
    assert start.verdict_reasons() == [
        "the board (8 x 5 squares of 7 cm) was found in no frame's image: check board: in "
        "calib.yaml (the squares, not the inner corners)"]
    note = ("the board poses leave the rotation about the camera's optical axis (z) free (the "
            "boards' normals spread 0.3 deg, +-4 deg): tilt the board differently between "
            "frames")
    parallel = BoardStart(board=wrong, conditioning=Conditioning(0.3, 4.0, (0, 1, 0), 0.2, 5,
                                                                 (note,)),
                          reasons=[note])
    assert parallel.verdict_reasons() == [f"{note}; {RECORD_ADVICE}"]
    assert "while driving" not in RECORD_ADVICE


@pytest.mark.slow
def test_a_board_recording_calibrates_from_no_guess_through_the_command_line(data, tmp_path,
                                                                           capfd):
    """calib.yaml without T_cam_lidar: the closed form is the start; a short search; the
    board's stages timed; result.json says what the board gave."""
    import json

    from .helpers import run_cli

    from paretocal.geometry import pose_error

    src = lce(data, "walkway_b")
    root = variant(src, tmp_path / "v", board="file", with_T=False)
    code, out, err = run_cli(capfd, "calibrate", root, "--out", tmp_path / "o", "--frames",
                             "0:6", "--pop", "40", "--gens", "12", "--no-figures", "--quiet")
    assert code == 0, err
    doc = json.loads((tmp_path / "o" / "result.json").read_text())
    b = doc["board"]
    assert b["applied"] and b["used"] == 6 and b["found_in_images"] == 6
    for k in ("board", "board_image", "board_cloud", "board_fit"):
        assert doc["timings_s"][k] > 0
    assert doc["config"]["search"]["gens"] == 3 and doc["config"]["features"]["reselect"] is False
    T_ref = np.array(yaml.safe_load((src / "calib.yaml").read_text())["T_cam_lidar"])
    e = pose_error(np.array(doc["T_cam_lidar"]), T_ref)
    assert e["rotation_deg"] < 1.0 and e["translation_cm"] < 5.0, e    # 6 boards: 0.71 / 3.1
    ev = b["evidence"]
    assert len(ev["per_frame"]) == 6 and set(ev["lobo_se"]) == {"x", "y", "z", "yaw", "pitch",
                                                               "roll"}
    assert "while driving" not in " ".join(doc["reliability"]["reasons"])
