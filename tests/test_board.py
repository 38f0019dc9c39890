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
    from helpers import bad_cli

    bad = variant(lce(data, "walkway_b"), tmp_path / "v",
                  edit=lambda c: c["board"].update(squares=[9, 1]))
    bad_cli(capfd, "calibrate", bad, "--out", tmp_path / "o",
            expect=(f"{bad / 'calib.yaml'}: board.squares must be two whole numbers",))
    both = variant(lce(data, "walkway_b"), tmp_path / "w", board="file",
                   edit=lambda c: c.update(board={"kind": "checkerboard"}))
    bad_cli(capfd, "check", both, expect=("board is given here and in",))
