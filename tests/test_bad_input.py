"""Bad input through the real command line: exit 2 and one line naming the file or option.

Complements the bad-input tests of test_cli.py (TestBadInput), test_io.py and test_formats.py
(docs/bad_input.md lists every case and its test). Also: degenerate scenes, the reliability
verdict of result.json, and a 2-million-point cloud.

Every test captures at the file-descriptor level (``capfd``), so that a line printed by native
code (libpng, OpenCV) would count as a second line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
import tracemalloc
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import yaml

from paretocal.cli import main
from paretocal.config import Settings
from paretocal.errors import ParetocalError
from paretocal.geometry import correction_matrix, invert, rotation_zyx
from paretocal.io import load_frames, write_extrinsic

from .helpers import (bad_cli as bad, default_sigint, run_cli as run, run_with_stdout_closed,
                      write_generic)

FAST = ["--pop", "16", "--gens", "3", "--no-polish", "--frames", "0:2", "--no-figures",
        "--checkpoint-every", "0"]


@pytest.fixture
def rig(tmp_path, raw_frames):
    """A generic folder with the first three KITTI frames (calib.yaml, images/, points/)."""
    return write_generic(tmp_path / "rig", raw_frames[:3])


def _calib(root):
    return yaml.safe_load((root / "calib.yaml").read_text())


def _edit_calib(root, edit):
    doc = _calib(root)
    edit(doc)
    (root / "calib.yaml").write_text(yaml.safe_dump(doc))


def _stem(raw_frames, k=0):
    return raw_frames[k].name


# --- missing, unreadable and odd files --------------------------------------------------------------

_PRIV_CAPS = "-dac_override,-dac_read_search"


def _can_drop_root_bypass() -> bool:
    """Root reads any file: running with CAP_DAC_OVERRIDE and CAP_DAC_READ_SEARCH dropped
    (setpriv) makes file permissions apply to root too."""
    if os.geteuid() != 0:
        return True
    if shutil.which("setpriv") is None:
        return False
    r = subprocess.run(["setpriv", f"--bounding-set={_PRIV_CAPS}", f"--inh-caps={_PRIV_CAPS}",
                        "true"], capture_output=True)
    return r.returncode == 0


def run_without_root_bypass(capfd, *args):
    """The CLI as an unprivileged user would run it: in-process when not root; as root, in a
    subprocess without the capabilities that bypass file permissions."""
    args = [str(a) for a in args]
    if os.geteuid() != 0:
        return run(capfd, *args)
    r = subprocess.run(["setpriv", f"--bounding-set={_PRIV_CAPS}", f"--inh-caps={_PRIV_CAPS}",
                        sys.executable, "-c",
                        "import sys; from paretocal.cli import main; sys.exit(main(sys.argv[1:]))",
                        *args], capture_output=True, text=True, timeout=300)
    return r.returncode, r.stdout, r.stderr


@pytest.mark.skipif(not _can_drop_root_bypass(),
                    reason="running as root without setpriv: permissions do not apply")
@pytest.mark.parametrize("target, expect", [
    ("points/{stem}.bin", "cannot read point cloud (Permission denied)"),
    ("images/{stem}.png", "cannot read the image (Permission denied)"),
    ("calib.yaml", "calib.yaml: cannot read (Permission denied)"),
    ("points", "points: cannot list the folder (Permission denied)"),
    ("init.yaml", "Invalid value for '--init': path"),
])
def test_unreadable_files(capfd, tmp_path, rig, raw_frames, target, expect):
    path = rig / target.format(stem=_stem(raw_frames))
    extra = []
    if target == "init.yaml":
        write_extrinsic(path, raw_frames[0].T_ref)
        extra = ["--init", path]
    mode = path.stat().st_mode
    path.chmod(0)
    try:
        code, _, err = run_without_root_bypass(capfd, "calibrate", rig, "--out", tmp_path / "o",
                                               *extra, *FAST)
    finally:
        path.chmod(mode)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and expect in lines[0], err


@pytest.mark.skipif(not _can_drop_root_bypass(),
                    reason="running as root without setpriv: permissions do not apply")
def test_unwritable_out(capfd, tmp_path, rig):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        code, _, err = run_without_root_bypass(capfd, "calibrate", rig, "--out", locked / "run",
                                               *FAST)
    finally:
        locked.chmod(0o755)
    assert code == 2 and "--out" in err and "no permission to write there" in err, err


def test_a_folder_where_a_file_should_be(capfd, tmp_path, rig, raw_frames):
    p = rig / "points" / f"{_stem(raw_frames)}.bin"
    p.unlink()
    p.mkdir()
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(p), "point cloud file expected, but this is a folder"))
    bad(capfd, "calibrate", rig, "--init", tmp_path, "--out", tmp_path / "o", *FAST,
        expect=(str(tmp_path), "file expected, but this is a folder"))


def test_source_is_a_file(capfd, tmp_path, rig):
    bad(capfd, "calibrate", rig / "calib.yaml", "--out", tmp_path / "o",
        expect="calib.yaml: source must be a folder")


def test_unrecognised_layouts(capfd, tmp_path, object_dir):
    empty = tmp_path / "empty"
    empty.mkdir()
    bad(capfd, "calibrate", empty, "--out", tmp_path / "o",
        expect=(str(empty), "not a recognised layout (expected a KITTI raw drive or date folder"))
    date = tmp_path / "2011_09_26"
    for drive in ("a_sync", "b_sync"):
        (date / drive).mkdir(parents=True)
    bad(capfd, "calibrate", date, "--out", tmp_path / "o",
        expect=(str(date), "must hold exactly one *_sync drive (found 2); pass the drive folder"))
    bad(capfd, "calibrate", object_dir, "--camera", "0", "--out", tmp_path / "o",
        expect="--camera 0: the KITTI object layout has cameras 2 and 3")


@pytest.mark.parametrize("make", ["file", "parent"])
def test_out_is_a_file(capfd, tmp_path, rig, make):
    f = tmp_path / "taken"
    f.write_text("x")
    out = f if make == "file" else f / "run"
    bad(capfd, "calibrate", rig, "--out", out, *FAST,
        expect=("--out", "exists and is not a folder" if make == "file" else "is a file"))
    assert f.read_text() == "x"


# --- point clouds -------------------------------------------------------------------------------------

@pytest.mark.parametrize("content, expect", [
    (b"", "the point cloud is empty"),
    (np.full((100, 4), np.nan, np.float32).tobytes(), "all 100 points have NaN or infinite"),
    (np.tile(np.float32([np.inf, 1, 1, 0]), (16, 1)).tobytes(), "all 16 points have NaN or"),
])
def test_empty_or_all_nan_bin(capfd, tmp_path, rig, raw_frames, content, expect):
    p = rig / "points" / f"{_stem(raw_frames)}.bin"
    p.write_bytes(content)
    line = bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(str(p), expect))
    assert "WARNING" not in line


def test_some_nan_points_are_dropped_with_a_count(capfd, tmp_path, rig, raw_frames):
    p = rig / "points" / f"{_stem(raw_frames)}.bin"
    pts = np.fromfile(p, np.float32).reshape(-1, 4)
    pts[:7, 0] = np.nan
    pts[7:9, 2] = -np.inf
    pts.tofile(p)
    code, _, err = run(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST)
    assert code == 0, err
    assert f"{p}: dropped 9 points with NaN or infinite coordinates" in err


@pytest.mark.parametrize("write, expect", [
    (lambda p: p.write_bytes(b"not numpy at all"), "not a NumPy .npy file"),
    (lambda p: np.save(p, np.zeros((5, 3), complex)), "expected real numbers, got dtype complex128"),
    (lambda p: np.save(p, np.zeros((5, 2))), "expected an N x 3 or N x 4 array, got shape (5, 2)"),
    (lambda p: np.save(p, np.full((5, 3), 1e300)), "all 5 points have NaN or infinite"),
])
def test_bad_npy(capfd, tmp_path, rig, raw_frames, write, expect):
    (rig / "points" / f"{_stem(raw_frames)}.bin").unlink()
    p = rig / "points" / f"{_stem(raw_frames)}.npy"
    write(p)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(str(p), expect))


# --- images -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("damage, expect", [
    (lambda b: b"", "the image file is empty (0 bytes)"),
    (lambda b: b[:200], "cannot decode the image (corrupt, truncated or not an image"),
    (lambda b: b[: len(b) // 2], "cannot decode the image (corrupt, truncated or not an image"),
    (lambda b: b"GIF89a this is no image", "cannot decode the image"),
])
def test_broken_png(capfd, tmp_path, rig, raw_frames, damage, expect):
    p = rig / "images" / f"{_stem(raw_frames)}.png"
    p.write_bytes(damage(p.read_bytes()))
    line = bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(str(p), expect))
    assert "libpng error" not in line.split("(")[0]     # the decoder's words only in the reason


def test_image_size_disagrees_with_calib_yaml(capfd, tmp_path, rig, raw_frames):
    p = rig / "images" / f"{_stem(raw_frames, 1)}.png"
    cv2.imwrite(str(p), np.zeros((100, 200, 3), np.uint8))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(p), "image is 200x100 but the calibration says 1242x375"))


# --- calib.yaml ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("edit, expect", [
    (lambda c: c["camera"]["K"][0].__setitem__(0, float("nan")), "camera.K contains NaN"),
    (lambda c: c["camera"].update(K=[[1, 2], [3]]),
     "camera.K is not a list of numbers (rows of different lengths)"),
    (lambda c: c["camera"].update(K="abc"), "camera.K is not a list of numbers"),
    (lambda c: c["camera"].update(K=[[700, 0, 600], [0, 700, 180], [0, 0, 2]]),
     "camera.K must have positive focal lengths and last row [0, 0, 1]"),
    (lambda c: c["camera"].update(width=1242.7),
     "camera.width must be a positive whole number of pixels, got 1242.7"),
    (lambda c: c["camera"].update(height=0), "camera.height must be a positive whole number"),
    (lambda c: c["camera"].update(width="wide"), "camera.width must be a positive whole number"),
    (lambda c: c["camera"].update(D=[0.1, "x"]), "camera.D is not a list of numbers"),
    (lambda c: c["camera"].update(D=[0.1, 0.2, 0.3]), "camera.D must hold 4, 5, 8, 12 or 14"),
    (lambda c: c["T_cam_lidar"][0].__setitem__(3, float("nan")),
     "T_cam_lidar contains NaN or infinite values"),
    (lambda c: c.update(T_cam_lidar=np.eye(3).tolist()),
     "T_cam_lidar must be 4x4 (or 3x4), got shape (3, 3)"),
    (lambda c: c.update(camera="pinhole"), "missing 'camera' section"),
    (lambda c: c["camera"].update(model="mei", D=[0.03, -0.08, 0.0, 0.0, 0.0]),
     "camera.xi is missing: the mei (unified) model needs the mirror parameter xi"),
    (lambda c: c["camera"].update(model="unified", xi=-0.5),
     "camera.xi must be a finite number >= 0, got -0.5"),
    (lambda c: c["camera"].update(model="omni", xi=float("nan")),
     "camera.xi must be a finite number >= 0"),
    (lambda c: c["camera"].update(model="mei", xi=1.0e300, D=[0.03, -0.08, 0.0, 0.0]),
     "camera.xi must be at most 100 (the unified model's mirror parameter: about 1 for "
     "mirrors, up to about 3 for fisheye lenses), got 1e+300"),
    (lambda c: c["camera"].update(model="mei", xi=1.0, D=[0.1, 0.2, 0.3]),
     "camera.D must hold the Mei model's k1, k2, p1, p2 [, k3], got 3"),
    (lambda c: c["camera"].update(D=[0.0] * 13 + [0.01]),
     "the tilted-sensor coefficients (the last two of 14) are not supported"),
    (lambda c: c["camera"].update(mask="masks/none.png"), "camera.mask file"),
    (lambda c: c["camera"].update(mask=3), "camera.mask must be the path of a mask image"),
    (lambda c: c["camera"].update(K=[[700, 0, 600], [5, 700, 180], [0, 0, 1]]),
     "camera.K must be upper triangular (its second row starts with 0)"),
])
def test_malformed_calib_yaml(capfd, tmp_path, rig, edit, expect):
    _edit_calib(rig, edit)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(rig / "calib.yaml"), expect))


@pytest.mark.parametrize("shape, expect", [
    ((100, 1242), "mask is 1242x100 but the calibration says 1242x375"),
    ((375, 1242), "the mask has no usable (nonzero) pixel"),
])
def test_bad_mask_file(capfd, tmp_path, rig, shape, expect):
    cv2.imwrite(str(rig / "mask.png"), np.zeros(shape, np.uint8))
    _edit_calib(rig, lambda c: c["camera"].update(mask="mask.png"))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(rig / "mask.png"), expect))


@pytest.mark.parametrize("text, expect", [
    ("camera: [unclosed\n  K: {", "not valid YAML (line 2, column 4: expected ',' or ']'"),
    ("- 1\n- 2\n", "expected a mapping (key: value) at the top level, got a list"),
    ("", "expected a mapping (key: value) at the top level, got an empty file"),
    (b"\xff\xfe\x00binary", "not a text file (not UTF-8); expected YAML or JSON"),
])
def test_calib_yaml_that_is_not_a_mapping(capfd, tmp_path, rig, text, expect):
    p = rig / "calib.yaml"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(str(p), expect))


# --- --init -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, text, expect", [
    ("reflection.yaml", "T_cam_lidar: [[1,0,0,0],[0,1,0,0],[0,0,-1,0],[0,0,0,1]]\n",
     "is not a rotation matrix (|R^T R - I| = 0, det = -1.0000)"),
    ("nan.yaml", "T_cam_lidar: [[.nan,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n",
     "T_cam_lidar contains NaN or infinite values"),
    ("shape.yaml", "T_cam_lidar: [1, 2, 3]\n", "T_cam_lidar must be 4x4 (or 3x4), got shape (3,)"),
    ("ragged.yaml", "T_cam_lidar: [[1,0,0,0],[0,1,0],[0,0,1,0],[0,0,0,1]]\n",
     "T_cam_lidar is not a numeric matrix (rows of different lengths)"),
    ("text.yaml", "T_cam_lidar: hello\n", "T_cam_lidar is not a numeric matrix"),
    ("row.yaml", "T_cam_lidar: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]\n",
     "the last row of T_cam_lidar must be [0, 0, 0, 1]"),
    ("huge.yaml", "T_cam_lidar: [[1e300,0,0,0],[0,1e300,0,0],[0,0,1,0],[0,0,0,1]]\n",
     "is not a rotation matrix"),
    ("bad.json", "{T_cam_lidar: ", "not valid JSON (Expecting property name"),
    ("notyaml.yaml", "T_cam_lidar: [[1, 0]\n", "not valid YAML (line 2"),
])
def test_bad_init(capfd, tmp_path, rig, name, text, expect):
    p = tmp_path / name
    p.write_text(text)
    bad(capfd, "calibrate", rig, "--init", p, "--out", tmp_path / "o", *FAST,
        expect=(str(p), expect))


# --- frames -----------------------------------------------------------------------------------------

def test_unpaired_files_are_named_in_a_warning(tmp_path, rig, raw_frames, caplog):
    (rig / "points" / f"{_stem(raw_frames, 1)}.bin").unlink()
    (rig / "points" / "extra.bin").write_bytes(b"")
    with caplog.at_level(logging.WARNING, logger="paretocal"):
        frames = load_frames(rig)
    assert [f.name for f in frames] == [_stem(raw_frames, 0), _stem(raw_frames, 2)]
    assert f"1 images without a partner in {rig / 'points'}, skipped ({_stem(raw_frames, 1)})" \
        in caplog.text
    assert "1 point clouds without a partner" in caplog.text and "(extra)" in caplog.text


@pytest.mark.parametrize("folder, suffixes, what", [("images", (".jpg", ".png"), "images"),
                                                    ("points", (".bin", ".npy"), "point clouds")])
def test_two_files_for_one_frame_are_named(capfd, tmp_path, rig, raw_frames, folder, suffixes,
                                           what):
    stem = _stem(raw_frames, 1)
    extra = rig / folder / f"{stem}{suffixes[0] if folder == 'images' else suffixes[1]}"
    if folder == "images":
        cv2.imwrite(str(extra), raw_frames[1].image)
    else:
        np.save(extra, raw_frames[1].points)
    a, b = (rig / folder / f"{stem}{s}" for s in suffixes)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=f"{a} and {b}: 2 {what} for frame {stem}; a frame has one image and one point "
               "cloud: remove or rename the others")


@pytest.mark.parametrize("spec, expect", [
    ("3:", "--frames 3:: selects no frame (the source has 3)"),
    # A slice beyond the frames is refused as an index beyond them is (issue 45: 0:50 of 10
    # frames silently took 10).
    ("0:50", "--frames 0:50: '0:50' reaches index 50, beyond the source's 3 frames (indices 0 "
             "to 2); 0:3 ends at the last one"),
    ("5:9", "--frames 5:9: '5:9' reaches index 5, beyond the source's 3 frames"),
    ("1:9:2", "--frames 1:9:2: '1:9:2' reaches index 9, beyond the source's 3 frames (indices "
              "0 to 2); 1:3:2 ends at the last one"),
    ("99", "--frames 99: index 99 is out of range (the source has 3 frames)"),
    (",", "--frames ,: selects no frame"),
    ("0:3:0", "--frames 0:3:0: the step of '0:3:0' is zero"),
    ("abc", "--frames abc: 'abc' is neither a frame stem nor an index"),
])
def test_frames_selecting_nothing(capfd, tmp_path, rig, spec, expect):
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", "--frames", spec, expect=expect)


# --- options ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, expect", [
    (["--n-min", "500", "--n-max", "100"], "--n-min 500 is larger than --n-max 100"),
    (["--bound-t", "-1"], "--bound-t -1: the translation bound must be positive"),
    (["--bound-r", "0"], "--bound-r 0: the rotation bound must be positive"),
    (["--bound-r", "100"], "--bound-r 100: at most 90 degrees"),
    (["--bound-t", "inf"], "--bound-t inf: must be a finite number"),
    (["--bound-t", "nan"], "--bound-t nan: must be a finite number"),
    (["--n-min", "0"], "--n-min 0: must be at least 1"),
    (["--n-max", "0"], "--n-max 0: must be at least 1"),
    (["--pop", "2"], "--pop 2: the population needs at least 4 individuals"),
    (["--gens", "0"], "--gens 0: needs at least 1 generation"),
    (["--seed", "-1"], "--seed -1: must be 0 or more"),
    (["--pop", "abc"], "Invalid value for '--pop'"),
    (["--max-deviation", "nan"], "--max-deviation nan: must be a finite number"),
    (["--budget-ms", "-1"], "--budget-ms must be a positive number of milliseconds"),
    (["--camera", "9"], "--camera 9: must be 0, 1, 2 or 3"),
])
def test_out_of_range_options(capfd, tmp_path, rig, args, expect):
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, *args, expect=expect)
    assert not (tmp_path / "o").exists()                # nothing written


def _memory_available(monkeypatch, nbytes):
    import psutil

    monkeypatch.setattr(psutil, "virtual_memory", lambda: SimpleNamespace(available=nbytes))


def test_population_beyond_memory(capfd, tmp_path, rig, monkeypatch):
    # The machine's memory is fixed here, so that the outcome does not depend on the machine.
    _memory_available(monkeypatch, 16 * 10**9)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, "--pop", "100000000",
        expect="--pop 100000000: the search needs at least 80.0 GB (800 bytes per individual "
               "on 1 frame: the population, its offspring and their evaluation), more than the "
               "16.0 GB of memory available")
    # A population that fits one frame but not the frames selected: refused once they are
    # counted, before any feature is extracted.
    _memory_available(monkeypatch, 10**9)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, "--pop", "1000000",
        "--frames", "0:3", expect="--pop 1000000: the search needs at least 1.4 GB (1376 "
                                  "bytes per individual on 3 frames")
    assert not (tmp_path / "o").exists()


def test_search_memory_per_individual_is_what_the_bound_says(raw_frames):
    """One NSGA-II generation holds at most SEARCH_BYTES_PER_INDIVIDUAL(_FRAME) per individual
    (measured), and not much less (the bound would refuse populations that fit)."""
    from paretocal.config import (SEARCH_BYTES_PER_INDIVIDUAL,
                                  SEARCH_BYTES_PER_INDIVIDUAL_FRAME, SearchSettings)
    from paretocal.search.engine import ArrayNSGA2
    from paretocal.search.nsga import initial_population
    from paretocal.search.problem import bounds, round_n
    from paretocal.stage import Stage

    settings = Settings().replace(objective={"evaluator": "numba"})
    frames = raw_frames[:2]
    stage = Stage(frames, frames[0].T_ref, frames[0].T_ref, settings)
    pop = 4000
    xl, xu = bounds(settings.search, stage.n_min, stage.n_max)
    X0 = initial_population(SearchSettings(pop=pop), xl, xu)
    engine = ArrayNSGA2(stage.objective.evaluate, xl, xu, pop, lambda X: round_n(X, xl, xu))
    engine.step(engine.start(X0[:8], 0))                 # compiled and warm
    tracemalloc.start()
    try:
        engine.step(engine.start(X0, 0))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    model = SEARCH_BYTES_PER_INDIVIDUAL + SEARCH_BYTES_PER_INDIVIDUAL_FRAME * len(frames)
    assert peak / pop <= model <= 1.25 * peak / pop, (peak / pop, model)


@pytest.mark.parametrize("args, expect", [
    (["--n-max", "100000"], "--n-max 100000: the frames hold at most"),
    (["--n-min", "100000"], "--n-min 100000 is larger than the largest n"),
])
def test_n_range_beyond_what_the_frames_hold(capfd, tmp_path, rig, args, expect):
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, *args, expect=expect)


@pytest.mark.parametrize("text, expect", [
    ("searc: {pop: 3}\n", "unknown section(s) searc (known: camera, decision"),
    ("search: {pop: [1,\n", "not valid YAML (line 2, column 1"),
    ("just a string\n", "expected a mapping (key: value) at the top level, got a str"),
    ("search: {pop: many}\n", "search.pop: expected a whole number, got 'many'"),
    ("search: {bound_t_m: abc}\n", "search.bound_t_m: expected a number or null, got 'abc'"),
    ("search: 5\n", "section 'search' must be a mapping of settings (key: value), got 5"),
    ("features: {grid: 5}\n", "features.grid: expected a list of 2 whole numbers, got 5"),
    ("camera: two\n", "camera: expected a whole number, got 'two'"),
    ("frames: [1, 2]\n", "frames: expected a string or null, got [1, 2]"),
    ("features: {blur_sigma: -3}\n", "features: blur_sigma must not be negative"),
    ("features: {canny_noise: 0}\n", "canny_noise 0.0: must be positive"),
    ("search: {seed: -1}\n", "--seed -1: must be 0 or more"),
    ("decision: {polish: maybe}\n", "decision.polish: expected true or false, got 'maybe'"),
    ("1: 2\n", "unknown section(s) 1"),
    # A typo names the key and the keys allowed, in one line with the file.
    ("serch: {pop: 3}\n", "unknown section(s) serch (known: camera, decision, features, "),
    ("search: {popp: 3}\n", "unknown setting(s) popp in section 'search' (known: "),
])
def test_bad_config_file(capfd, tmp_path, rig, text, expect):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(text)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", "--config", cfg, *FAST,
        expect=(str(cfg), expect))


@pytest.mark.parametrize("text, expect", [
    ("search: {seed_grid_deg: 0.001}\n",
     "search.seed_grid_deg 0.001: a grid over +-15 deg in steps of 0.001 deg holds "
     "27,002,700,090,001 rotations, more than the 1,000,000 the seeding scores (about a second "
     "per 10,000 on 20 frames); use a step of at least 0.31 deg, or null for no grid"),
    ("search: {seed_grid_t_m: 1.0e-6}\n",
     "search.seed_grid_t_m 1e-06: a joint grid of 343 rotations (+-15 deg in steps of 5 deg) "
     "and translations over +-0.45 m in steps of 1e-06 m holds"),
    ("features: {grid: [100000, 100000]}\n", "features.grid [100000, 100000]: must lie in "
                                              "[1, 1024]"),
    ("objective: {truncation_px: 1.0e+300}\n",
     "objective.truncation_px 1e+300: must lie in (0, 16384]"),
    ("objective: {contrast: 1.0e+300}\n", "objective.contrast 1e+300: must lie in [0, 100]"),
    ("features: {blur_sigma: 1.0e+6}\n", "features.blur_sigma 1e+06: must lie in [0, 50]"),
], ids=["seed grid step", "joint grid step", "feature grid", "truncation", "contrast", "blur"])
def test_config_values_without_a_sensible_range_are_refused(capfd, tmp_path, rig, text, expect):
    """Values validation let through, which then failed with exit 1 (MemoryError, LinAlgError,
    OpenCV's bad_array_new_length): every numeric setting now has a range (config.ranges)."""
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(text)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", "--config", cfg, *FAST,
        expect=(f"{cfg}: {expect}",))


def test_every_numeric_setting_has_a_range():
    """Every whole-number and number setting of every section has a range (config.ranges)
    that holds its default; a value beyond either end is refused, naming the setting."""
    import dataclasses as dc

    from paretocal.config import _field_types, _option, ranges
    from paretocal.errors import SettingsError

    base = Settings()
    numeric = {("", "camera")}
    for f in dc.fields(Settings):
        section = getattr(base, f.name)
        if dc.is_dataclass(section):
            numeric |= {(f.name, k) for k, a in _field_types(type(section)).items()
                        if a.split("|")[0].strip() in ("int", "float", "tuple[int, int]")}
    assert numeric == set(ranges())
    for (section, name), r in ranges().items():
        default = getattr(base if not section else getattr(base, section), name)
        values = default if isinstance(default, tuple) else (default,)
        assert all(v is None or r.holds(v) for v in values), (section, name)
        integer = isinstance(values[0], int)
        beyond = [r.low - 1 if integer or not r.open_low else r.low]
        if r.high is not None:
            beyond.append(r.high + 1 if integer else r.high * 2 if r.high else 1.0)
        for v in beyond:
            value = (v,) * len(values) if isinstance(default, tuple) else v
            with pytest.raises(SettingsError) as info:
                if section:
                    base.replace(**{section: {name: value}}).validate()
                else:
                    dc.replace(base, **{name: value}).validate()
            assert name in str(info.value) or _option(name) in str(info.value), info.value


@pytest.mark.parametrize("search", [
    {"seed_grid_deg": 0.001}, {"seed_grid_deg": 0.001, "bound_r_deg": 90},
    {"seed_grid_deg": 0.01, "init_error_deg": 3}, {"seed_grid_t_m": 1e-6},
    {"seed_grid_t_m": 1e-4, "bound_t_m": 5, "bound_r_deg": 40}])
def test_the_step_a_seed_grid_refusal_suggests_is_accepted(search):
    import re

    from paretocal.errors import SettingsError

    with pytest.raises(SettingsError) as info:
        Settings().replace(search=search).validate()
    key = next(k for k in search if k.startswith("seed_grid"))
    step = float(re.search(r"a step of at least ([0-9.e+-]+)", str(info.value)).group(1))
    Settings().replace(search=dict(search, **{key: step})).validate()


def test_a_checkpoint_of_the_most_generations_is_a_text_the_reader_takes():
    """The checkpoint's metadata holds a record per generation and is read back as a text of
    at most MAX_TEXT_BYTES: search.gens is bounded so that it fits, with long figures."""
    from paretocal.config import ranges
    from paretocal.io.text import MAX_TEXT_BYTES

    gens = ranges()[("search", "gens")].high
    record = {"gen": gens, "best_f1": -1.2345678901234567e-05, "evaluations": 10 ** 12}
    assert len(json.dumps([record] * gens)) + 1000 < MAX_TEXT_BYTES


def test_config_that_is_an_image(capfd, tmp_path, rig, raw_frames):
    cfg = rig / "images" / f"{_stem(raw_frames)}.png"
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", "--config", cfg, *FAST,
        expect=(str(cfg), "not a text file (not UTF-8); expected YAML or JSON"))


def test_missing_config_file(capfd, tmp_path, rig):
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", "--config", tmp_path / "no.yaml",
        *FAST, expect=f"{tmp_path / 'no.yaml'}: file not found")


# --- KITTI calibration files ---------------------------------------------------------------------

def _kitti_copy(raw_date, dst, c2c=None, v2c=None):
    dst.mkdir(parents=True)
    for name, edit in (("calib_cam_to_cam.txt", c2c), ("calib_velo_to_cam.txt", v2c)):
        text = (raw_date / name).read_text()
        (dst / name).write_bytes(edit(text) if edit else text.encode())
    drive = next(p for p in raw_date.iterdir() if p.name.endswith("_sync"))
    (dst / drive.name).symlink_to(drive.resolve(), target_is_directory=True)
    return dst


@pytest.mark.parametrize("c2c, v2c, expect", [
    (lambda t: "\n".join(ln for ln in t.splitlines() if not ln.startswith("P_rect_02")).encode(),
     None, "calib_cam_to_cam.txt: missing key 'P_rect_02'"),
    (lambda t: t.replace("P_rect_02: ", "P_rect_02: 1 ").encode(), None,
     "'P_rect_02' has 13 values, expected 12 (3x4)"),
    (None, lambda t: "\n".join("T: nan 0 0" if ln.startswith("T:") else ln
                               for ln in t.splitlines()).encode(),
     "calib_velo_to_cam.txt: 'T' contains NaN or infinite values"),
    (None, lambda t: b"\xff\xd8 binary", "calib_velo_to_cam.txt: not a text file (not UTF-8)"),
])
def test_bad_kitti_calibration(capfd, tmp_path, raw_date, c2c, v2c, expect):
    date = _kitti_copy(raw_date, tmp_path / "2011_09_26", c2c, v2c)
    bad(capfd, "calibrate", date, "--out", tmp_path / "o", *FAST, expect=expect)


# --- degenerate scenes ---------------------------------------------------------------------------

def test_one_blank_frame_is_named(capfd, tmp_path, rig, raw_frames):
    cv2.imwrite(str(rig / "images" / f"{_stem(raw_frames, 1)}.png"),
                np.full((375, 1242, 3), 128, np.uint8))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(f"no image edges in frame(s) {_stem(raw_frames, 1)} (0 px)",
                "leave these frames out with --frames"))


def _half_turned_init(T, path):
    """An --init turned 180 deg about the LiDAR's vertical axis (the camera looks backwards)."""
    D = np.eye(4)
    D[:3, :3] = rotation_zyx(180.0, 0.0, 0.0)
    write_extrinsic(path, T @ D)
    return path


def test_every_point_behind_the_camera(capfd, tmp_path, rig, raw_frames):
    # Clouds cropped to the camera's half (as many datasets ship them): turned around, the
    # camera sees none of their points.
    for p in (rig / "points").iterdir():
        pts = np.fromfile(p, np.float32).reshape(-1, 4)
        pts[pts[:, 0] > 0].tofile(p)
    init = _half_turned_init(raw_frames[0].T_ref, tmp_path / "init.yaml")
    bad(capfd, "calibrate", rig, "--init", init, "--out", tmp_path / "o", *FAST,
        expect=("too few LiDAR feature points in view at the initial extrinsic",
                "lie in front of the camera: nearly every point is behind it",
                "is it turned 180 deg about the vertical axis?"))


def test_inverted_init_is_suspected(capfd, tmp_path, rig, raw_frames):
    # Only the points ahead and to the left of the vehicle: the inverse of KITTI's extrinsic
    # makes the camera look to the right, at none of them.
    for p in (rig / "points").iterdir():
        pts = np.fromfile(p, np.float32).reshape(-1, 4)
        pts[(pts[:, 0] > 0) & (pts[:, 1] > 0)].tofile(p)
    init = tmp_path / "inverse.yaml"
    write_extrinsic(init, invert(raw_frames[0].T_ref))
    line = bad(capfd, "calibrate", rig, "--init", init, "--out", tmp_path / "o", *FAST,
               expect="too few LiDAR feature points in view at the initial extrinsic")
    assert "is it inverted (T_lidar_cam given for T_cam_lidar)?" in line, line


def test_sparse_frames(capfd, tmp_path, rig, raw_frames):
    for p in (rig / "points").iterdir():
        pts = np.fromfile(p, np.float32).reshape(-1, 4)
        pts[::2000].tofile(p)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=("too few LiDAR feature points in view at the initial extrinsic (fewer than 30",
                "project into the image but few are edges"))


def test_one_sparse_frame_among_good_ones_is_a_warning(raw_frames, caplog):
    from paretocal.pipeline import check_scene, prepare_features

    frames = [raw_frames[0], dataclasses.replace(raw_frames[1],
                                                 points=raw_frames[1].points[::2000])]
    T = raw_frames[0].T_ref
    feats = prepare_features(frames, T, Settings())
    with caplog.at_level(logging.WARNING, logger="paretocal"):
        check_scene(feats, frames, T)
    assert f"frame(s) {raw_frames[1].name} (" in caplog.text
    assert "fewer than 30 LiDAR feature points in view" in caplog.text


#: FAST with the polish and the re-selection of the feature points at the estimate.
POLISHED = [a for a in FAST if a != "--no-polish"]


def _no_polish(objective, X, F, *args):
    return X, F, 0


def test_no_points_in_view_after_the_reselection_names_that_stage(capfd, tmp_path, rig,
                                                                   monkeypatch):
    """The search reaches a pose that sees none of the points (forced here: the estimate is
    turned 180 deg about the LiDAR's vertical axis, and the clouds hold the camera's half
    only): the message names the re-selection and how far its pose is from the start, and
    does not blame --init."""
    import paretocal.pipeline as pipeline

    for p in (rig / "points").iterdir():
        pts = np.fromfile(p, np.float32).reshape(-1, 4)
        pts[pts[:, 0] > 0].tofile(p)

    def turned_around(objective, X, F, *args):
        X = X.copy()
        X[:, :6] = [0, 0, 0, 180.0, 0, 0]                # x, y, z (m), yaw, pitch, roll (deg)
        return X, F, None, 0

    monkeypatch.setattr(pipeline, "polish_front", _no_polish)
    monkeypatch.setattr(pipeline, "prefer_near", turned_around)
    line = bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *POLISHED,
               expect=("too few LiDAR feature points in view after re-selecting points at the "
                       "estimate (180.0 deg, 0 cm from the initial extrinsic) (fewer than 30 per "
                       "frame", "nearly every point is behind it",
                       "the search moved the extrinsic away from where the frames' points are "
                       "in view"))
    assert "turned 180 deg" not in line and "at the initial extrinsic (" not in line
    assert not (tmp_path / "o").exists()


def test_frame_warnings_are_said_once(capfd, tmp_path, rig, raw_frames, monkeypatch):
    """An image without a partner (said when the source is detected, which the command line
    did twice) and a sparse frame (said by the scene check, which the re-selection of the
    feature points ran again): one line each."""
    import paretocal.pipeline as pipeline

    monkeypatch.setattr(pipeline, "polish_front", _no_polish)       # the re-selection stays
    monkeypatch.setattr(pipeline, "prefer_near", lambda objective, X, F, *a: (X, F, None, 0))
    shutil.copy(rig / "images" / f"{_stem(raw_frames, 0)}.png", rig / "images" / "lonely.png")
    p = rig / "points" / f"{_stem(raw_frames, 1)}.bin"
    np.fromfile(p, np.float32).reshape(-1, 4)[::2000].tofile(p)
    code, _, err = run(capfd, "calibrate", rig, "--out", tmp_path / "o", *POLISHED,
                       "--frames", "0:3")
    assert code == 0, err
    lines = err.strip().splitlines()
    assert sum("1 images without a partner" in line for line in lines) == 1, err
    assert sum(f"frame(s) {_stem(raw_frames, 1)} (" in line for line in lines) == 1, err
    assert len(lines) == len(set(lines)), err


# --- the reliability verdict ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def perturbed_init(tmp_path_factory, raw_frames):
    """KITTI's extrinsic moved by about 2 deg and 9 cm (the correction back: see the values)."""
    p = tmp_path_factory.mktemp("init") / "init.yaml"
    back = np.array([0.061, 0.062, 0.003, -0.86, -1.78, -0.47])
    write_extrinsic(p, raw_frames[0].T_ref @ invert(correction_matrix(back)))
    return p


@pytest.fixture(scope="module")
def rig3(tmp_path_factory, raw_frames):
    return write_generic(tmp_path_factory.mktemp("rig3") / "rig", raw_frames[:3])


def test_a_normal_short_run_is_ok(tmp_path, rig3, perturbed_init):
    out = tmp_path / "run"
    assert main(["calibrate", str(rig3), "--init", str(perturbed_init), "--out", str(out),
                 "--pop", "16", "--gens", "3", "--no-figures", "--checkpoint-every", "0",
                 "--quiet"]) == 0
    doc = json.loads((out / "result.json").read_text())
    rel = doc["reliability"]
    assert set(rel) >= {"verdict", "reasons", "frames", "in_view", "at_bound"}
    assert rel["frames"] == 3 and 0 < rel["in_view"] <= 1
    assert rel["verdict"] == "ok", rel["reasons"]
    assert rel["intervals"]["frame"] == "lidar" and rel["intervals_not_trusted"] is None
    assert doc["reference_error"]["rotation_deg"] < 1.0      # and it is indeed close


def test_a_correction_held_by_the_bounds_is_flagged(capfd, tmp_path, rig3, perturbed_init):
    out = tmp_path / "run"
    code, _, err = run(capfd, "calibrate", rig3, "--init", perturbed_init, "--out", out,
                       "--pop", "16", "--gens", "3", "--no-figures", "--checkpoint-every", "0",
                       "--bound-r", "0.5", "--bound-t", "0.02")
    assert code == 0, err
    rel = json.loads((out / "result.json").read_text())["reliability"]
    assert rel["verdict"] == "unreliable" and rel["at_bound"], rel
    assert any("search bound" in r for r in rel["reasons"])
    assert "WARNING: the result may be unreliable" in err


def _basin(**over):
    """A near/far basin test of two basins (:class:`paretocal.search.basin.BasinTest`)."""
    from paretocal.search.basin import BasinTest

    doc = {"separation_px": 45.7, "separation_deg": 3.6163, "separation_cm": 11.749,
           "departure_near": 0.4, "departure_far": 0.3, "same_basin": False, "mean_px": 0.02,
           "se_px": 0.05, "t": 0.4, "alternative": [0.1, 0, 0, 3.6, 0, 0], "rebuilt": False}
    return BasinTest.from_dict({**doc, **over})


def _motion(compensated, **over):
    """A motion report (:class:`paretocal.inputs.MotionReport`) with an estimate."""
    from paretocal.inputs import MotionReport

    return MotionReport(compensated, **{"speed_mps": 30.0, "speed_spread_mps": 0.1,
                                        "v_mps": (30.0, 0.0, 0.0), "yaw_rate_dps": 0.0,
                                        "observable_xyz": (True, True, True),
                                        "median_share_xyz": (0.2, 0.4, 0.4),
                                        "time_offset_s": 0.0, **over})


def test_the_motion_report_is_written_as_before():
    """result.json's ``motion``: the estimate's figures (when there is one), then whether it
    was applied, and why not or how far it moved a point."""
    from paretocal.inputs import MotionReport

    assert MotionReport(False, "one frame").to_dict() == {"compensated": False,
                                                          "reason": "one frame"}
    done = _motion(True, skew_m=3.0, max_shift_m=1.5).to_dict()
    assert list(done) == ["speed_mps", "speed_spread_mps", "v_mps", "yaw_rate_dps",
                          "observable_xyz", "median_share_xyz", "time_offset_s", "skew_m",
                          "compensated", "max_shift_m"]
    assert done["v_mps"] == [30.0, 0.0, 0.0] and done["compensated"] is True
    left = _motion(False, skew_m=3.0, reason="not observable").to_dict()
    assert list(left)[-2:] == ["compensated", "reason"] and "max_shift_m" not in left
    json.dumps(done, allow_nan=False)


def test_the_inputs_report_is_written_as_before():
    """result.json's ``inputs``: the fields, the notes, the camera model, the pose as nested
    lists and the mask, then where the pose came from and each sweep's rings when given;
    read back, the same JSON."""
    from paretocal.inputs import InputsReport, RingBrief

    pose = np.eye(4)
    pose[:3, 3] = [0.1, -0.2, 1.7]
    report = InputsReport(point_fields={"intensity": "intensity", "ring": None},
                          notes=("no time field",), camera_model="fisheye", lidar_pose=pose,
                          mask=True, lidar_pose_source={"source": "cloud origin"},
                          rings=(("a", RingBrief("scan", 64, 0.9931)),
                                 ("b", RingBrief("lines", 3, 0.4))))
    doc = report.to_dict()
    assert list(doc) == ["point_fields", "notes", "camera_model", "lidar_pose", "mask",
                         "lidar_pose_source", "rings"]
    assert doc["notes"] == ["no time field"] and doc["lidar_pose"] == pose.tolist()
    assert doc["rings"] == [{"frame": "a", "method": "scan", "n_rings": 64, "purity": 0.9931},
                            {"frame": "b", "method": "lines", "n_rings": 3, "purity": 0.4}]
    text = json.dumps(doc, indent=2, allow_nan=False)
    assert json.dumps(InputsReport.from_dict(json.loads(text)).to_dict(), indent=2) == text
    # Without a pose, its source or rings: null, and the last two not written.
    bare = InputsReport(point_fields={}, notes=(), camera_model="pinhole", lidar_pose=None,
                        mask=False).to_dict()
    assert bare == {"point_fields": {}, "notes": [], "camera_model": "pinhole",
                    "lidar_pose": None, "mask": False}
    assert InputsReport.from_dict(bare).to_dict() == bare


def test_clouds_without_time_are_not_deskewed(raw_frames):
    from paretocal.config import Settings
    from paretocal.inputs import compensate_motion

    frames, report = compensate_motion(raw_frames[:2], Settings())
    assert frames == raw_frames[:2] and not report.compensated
    assert "no per-point time" in report.reason and report.speed_mps is None


def _wide(photo=None, **over):
    """An applied wide start (:class:`paretocal.wide.WideStart`) with ``photo`` its check."""
    from paretocal.wide import PhotoCheck, WideStart

    return WideStart(np.eye(4), np.eye(4), photo=None if photo is None else PhotoCheck(**photo),
                     **over)


def _counts(doc):
    """The feature counts of a fake result (:class:`paretocal.stage.FeatureCounts`) from
    their dict form, None when not given."""
    from paretocal.stage import FeatureCounts

    return None if doc is None else FeatureCounts.from_dict(doc)


def _fake_result(**over):
    """The parts of a CalibrationResult that :func:`reliability` reads."""
    from paretocal.decide import Decision
    from paretocal.quality import AXES, UNITS, Quality
    from paretocal.verdict import Evidence

    # In result.json's form (cm and deg), read back as the run holds it.
    q = {"units": dict(zip(AXES, UNITS)), "jackknife_se": dict.fromkeys(AXES, 0.1),
         "step_to_local_optimum": dict.fromkeys(AXES, 0.0)}
    q.update(over.pop("quality", {}))
    q = Quality.from_dict(q)
    X = np.zeros((1, 7))
    X[0, :6] = over.pop("x", np.zeros(6))
    deg, m = over.pop("init_error", (10.0, 0.3))
    r = SimpleNamespace(frames=over.pop("frames", ["a", "b", "c", "d"]), chosen=0,
                        front=SimpleNamespace(X=X), quality=q,
                        decision=Decision(rule="knee", deviation_px=0.0,
                                          basin=over.pop("basin", None)),
                        motion=over.pop("motion", None),
                        feature_counts=_counts(over.pop("feature_counts", None)),
                        evidence=Evidence.from_dict(over.pop("evidence", {})),
                        wide=over.pop("wide", None),
                        settings=Settings().replace(search={"bound_t_m": 0.1, "bound_r_deg": 2.0,
                                                            "init_error_deg": deg,
                                                            "init_error_m": m}))
    in_view = over.pop("in_view", 0.9)
    r.objectives = lambda: {"chamfer": 1.0, "in_view": in_view}
    return r


@pytest.mark.parametrize("over, reason", [
    ({}, None),
    ({"frames": ["a", "b"]}, "only 2 frame(s)"),
    ({"feature_counts": {"frames_contributing": 1}},
     "only 1 of the 4 frames have LiDAR feature points in view"),
    ({"in_view": 0.3}, "only 30 % of the feature points project into the image"),
    ({"x": [0.0, 0.0, 0.0999, 0, 0, 0]}, "sits at the search bound on z"),
    ({"x": [0, 0, 0, -1.99, 0, 0]}, "sits at the search bound on yaw"),
    ({"x": [0.09, 0, 0, 0, 0, 0], "quality": {"step_to_local_optimum": {
        "x": 5.0, "y": 0, "z": 0, "yaw": 0, "pitch": 0, "roll": 0}}},
     "the objective still falls beyond the search bound on x"),
    ({"quality": {"jackknife_se": {"x": 12.0, "y": 1, "z": 1, "yaw": 1.5, "pitch": 0,
                                   "roll": 0}}},
     "the frames disagree: jackknife standard error x 12 cm, yaw 1.5 deg"),
    ({"x": [0, 0.075, 0, 0, 0, 0], "init_error": (10.0, 0.05)},
     "the correction lies beyond the stated initial error (y 7.5 cm"),
    ({"x": [0, 0, 0, 0, 1.6, 0], "init_error": (1.0, 0.3)},
     "the correction lies beyond the stated initial error (pitch 1.6 deg"),
    ({"evidence": {"restart": {"disagrees": True, "runs": [
        {"distinct": False, "separation_deg": 0.1, "separation_cm": 1.0, "mean_px": 0.0,
         "frames_restart_better": 2, "frames": 4},
        {"distinct": True, "separation_deg": 4.0, "separation_cm": 30.0, "mean_px": 0.1,
         "frames_restart_better": 3, "frames": 4}]}}},
     "an independent restart of the search ended 4 deg / 30 cm away and fits the frames "
     "better (3 of 4 frames prefer it)"),
    ({"evidence": {"restart": {"disagrees": False, "runs": [
        {"distinct": True, "separation_deg": 4.0, "separation_cm": 30.0, "mean_px": -0.5,
         "frames_restart_better": 0, "frames": 4}]}}}, None),
    ({"evidence": {"contrast": {"frames_clear": 0.25, "z": 4.0}}},
     "images and clouds barely agree: in only 25 % of the frames"),
    ({"evidence": {"contrast": {"frames_clear": 1.0, "z": 2.4}}},
     "images and clouds barely agree: the result fits the image edges only 2.4 spreads better"),
    ({"evidence": {"contrast": {"frames_clear": 0.95, "z": 5.0}}}, None),
    # A joint calibration: a camera whose own frames prefer another pose is named.
    ({"evidence": {"cameras": {"disagreeing": ["left"], "cameras": [
        {"name": "front", "checked": True, "agrees": True},
        {"name": "left", "checked": True, "agrees": False, "separation_deg": 0.51,
         "separation_cm": 8.2, "own_optimum_px": 5.2, "tolerance_px": 2.0}]}}},
     "the cameras disagree: camera left's frames alone prefer a pose 0.51 deg / 8.2 cm away, "
     "moving its points 5.2 px (its edges are trusted to 2 px)"),
    ({"evidence": {"cameras": {"disagreeing": [], "cameras": [
        {"name": "front", "checked": True, "agrees": True},
        {"name": "left", "checked": False}]}}}, None),
    # The wide start's ambiguity is the verdict's; its disagreement alone is not.
    ({"wide": _wide(ambiguity="the wide search found two poses 2.9 deg / 203 cm apart that "
                    "the frames do not tell apart")},
     "the wide search found two poses 2.9 deg / 203 cm apart"),
    ({"wide": _wide(disagreement="the edge objective and photo-consistency prefer poses "
                    "3 deg / 140 cm apart")}, None),
    # The near/far basin test of the front: two poses the frames do not tell apart.
    ({"basin": _basin(ambiguous=True, kept="near", p=0.2, frames=4)},
     "ambiguous: a pose 3.6 deg / 12 cm away fits the frames about as well (paired test over "
     "4 frames: p = 0.8); the result is the optimum next to the initial extrinsic"),
    ({"basin": _basin(ambiguous=False, kept="far", p=0.001, frames=4)}, None),
    # A sweep skewed by the motion and left as recorded.
    ({"motion": _motion(False, skew_m=3.0, reason="ego-motion is not observable along x")},
     "the LiDAR moved 3 m during a sweep and the motion could not be compensated (ego-motion "
     "is not observable along x)"),
    ({"motion": _motion(False, skew_m=0.05, reason="ego-motion is not observable along x")},
     None),
    ({"motion": _motion(True, skew_m=3.0, max_shift_m=1.5)}, None),
    # Photo-consistency checks the calibration that followed a wide start.
    ({"wide": _wide(photo=dict(agree=False, result=0.512, rival=0.47, separation_deg=3.1,
                               separation_m=1.42, p=0.0))},
     "photo-consistency disagrees: the images agree clearly better at a pose 3.1 deg / 142 cm "
     "from the "
     "result (cost 0.470 against 0.512)"),
    ({"wide": _wide(photo=dict(agree=True, result=0.47, rival=0.512, separation_deg=3.1,
                               separation_m=1.42, p=1.0))}, None),
    # The jackknife of the intervals (at the local optimum) decides when there is one.
    ({"quality": {"jackknife_se": {"x": 0.1, "y": 0.1, "z": 13.6, "yaw": 0.1, "pitch": 0.1,
                                   "roll": 0.1}},
      "evidence": {"intervals": {"units": {"x": "cm", "z": "cm", "roll": "deg"},
                                 "jackknife_se": {"x": 0.3, "z": 0.7, "roll": None}}}}, None),
    ({"evidence": {"intervals": {"units": {"x": "cm", "z": "cm"},
                                 "jackknife_se": {"x": 0.3, "z": 11.0}}}},
     "the frames disagree: jackknife standard error z 11 cm"),
    # Frames that agree on a pose the data fix only coarsely: the intervals say how coarsely.
    ({"evidence": {"intervals": {"units": {"x": "cm", "y": "cm", "pitch": "deg"},
                                 "half_width": {"x": 9.0, "y": 14.0, "pitch": 0.5},
                                 "undetermined": [], "alignment_px": 1.7,
                                 "sampling_px": [7.3, 6.8]}}},
     "the data fix the result only to y +-14 cm (95 %; a usable calibration needs 10 cm and "
     "1 deg); the LiDAR samples this camera's view coarsely (neighbouring returns 7.3 px "
     "apart along a ring and 6.8 px between rings)"),
    ({"evidence": {"intervals": {"units": {"x": "cm", "pitch": "deg"},
                                 "half_width": {"x": 3.0, "pitch": 1.4},
                                 "undetermined": ["z"], "alignment_px": 1.7,
                                 "sampling_px": [2.0, 3.0]}}},
     "the data fix the result only to pitch +-1.4 deg, z not at all (95 %"),
    ({"evidence": {"intervals": {"units": {"x": "cm"}, "half_width": {"x": 9.9},
                                 "undetermined": [], "alignment_px": 1.7,
                                 "sampling_px": None}}}, None),
    ({"evidence": {"motion": {"applied": True, "directions": 9, "residual_deg": 0.6,
                              "change_deg": 2.5, "tolerance_deg": 1.5}}},
     "the motion disagrees: the directions of travel both sensors see put the camera's "
     "rotation 2.5 deg from the result's (they agree to 1.5 deg over 9 directions of travel "
     "and turns)"),
    ({"evidence": {"motion": {"applied": True, "directions": 9, "residual_deg": 0.6,
                              "change_deg": 0.5, "tolerance_deg": 1.5}}}, None),
    ({"evidence": {"motion": {"applied": False, "standing": True, "travel_m": 0.02,
                              "need_m": 2.0, "reason": "the rig barely moves"}}},
     "the rig stands still over the 4 frames (the LiDAR travels 0.02 m; the view changes "
     "with about 2 m)"),
    ({"evidence": {"motion": {"applied": False, "reason": "the motion gives 1 direction(s)"}}},
     None),
    # A search stopped short of its optimum: a local polish moves the result beyond the
    # intervals the data give about the optimum (half-widths include the move: y 13.8 cm =
    # 3.6 about the optimum + 10.2 moved).
    ({"evidence": {"intervals": {"units": {"y": "cm", "yaw": "deg"},
                                 "half_width": {"y": 13.8, "yaw": 0.83}, "undetermined": [],
                                 "move": {"y": 10.2, "yaw": 0.62}},
                   "move": {"separation_deg": 0.85, "separation_cm": 12.6, "px": 4.6,
                            "polished": False}}},
     "the search stopped short of the objective's optimum: a local polish from the result "
     "moves it 0.85 deg / 13 cm (4.6 px), beyond the 95 % intervals the frames give about "
     "that optimum (y 10 cm against +-3.6, yaw 0.62 deg against +-0.21); run again with the "
     "polish (without --no-polish) or a longer search"),
    ({"evidence": {"intervals": {"units": {"y": "cm"}, "half_width": {"y": 5.0},
                                 "undetermined": [], "move": {"y": 3.0}},
                   "move": {"separation_deg": 0.1, "separation_cm": 3.0, "px": 2.0,
                            "polished": True}}},
     "moves it 0.1 deg / 3 cm (2 px), beyond the 95 % intervals the frames give about that "
     "optimum (y 3 cm against +-2); run again with a longer search"),
    # ... within them: the intervals include the move, the verdict stays ok.
    ({"evidence": {"intervals": {"units": {"y": "cm"}, "half_width": {"y": 4.8},
                                 "undetermined": [], "move": {"y": 0.7}},
                   "move": {"separation_deg": 0.04, "separation_cm": 0.7, "px": 0.4,
                            "polished": True}}}, None),
])
def test_reliability_reasons(over, reason):
    from paretocal.verdict import reliability

    rel = reliability(_fake_result(**over))
    if reason is None:
        assert rel.verdict == "ok" and rel.reasons == ()
    else:
        assert rel.verdict == "unreliable" and len(rel.reasons) == 1, rel
        assert reason in rel.reasons[0], rel.reasons
    json.dumps(rel.to_dict(), allow_nan=False)           # plain JSON


def _restart(correction):
    """A restart that disagrees, its pose at ``correction`` (m, deg) from the start."""
    return {"restart": {"disagrees": True, "runs": [
        {"distinct": True, "separation_deg": 4.0, "separation_cm": 30.0, "mean_px": 0.1,
         "frames_restart_better": 3, "frames": 4, "correction": correction}]}}


EDGELESS = {"frames_contributing": 4, "per_frame": [
    {"frame": "a", "depth_edge": 400, "intensity_edge": 200, "smooth": 500},
    {"frame": "b", "depth_edge": 12, "intensity_edge": 9, "smooth": 800},
    {"frame": "c", "depth_edge": 300, "intensity_edge": 100, "smooth": 500},
    {"frame": "d", "depth_edge": 0, "intensity_edge": 3, "smooth": 900}]}


@pytest.mark.parametrize("over, says, never", [
    # The restart's pose lies farther from the start than the result (8 deg against 0.5):
    # a smaller stated error that keeps the result and leaves it out is worth stating.
    ({"x": [0.01, 0, 0, 0.5, 0, 0], "evidence": _restart([0.02, 0, 0, 8.0, 0, 0])},
     ["add frames with more varied structure", "state a smaller initial error "
      "(--init-error 2,0.06 keeps the result inside the search box"], []),
    # ... nearer the start than the result: a smaller stated error cannot help; not offered.
    ({"x": [0.05, 0, 0, 1.5, 0, 0], "evidence": _restart([0.01, 0, 0, 0.5, 0, 0])},
     ["add frames with more varied structure"], ["--init-error"]),
    # The ambiguous basin kept the start's own optimum: no advice to narrow the stated error.
    ({"basin": _basin(ambiguous=True, kept="near", p=0.2, frames=4)},
     ["add frames with more varied structure"], ["smaller --init-error"]),
    ({"basin": _basin(ambiguous=True, kept="far", p=0.8, frames=4)},
     ["state a smaller --init-error if the start is known to be close"], []),
    # Frames without edges are named when the verdict is unreliable ...
    ({"frames": ["a", "b"], "feature_counts": EDGELESS},
     ["few edges: 2 of 4 frames (b, d) have fewer than 30 LiDAR edge points in view"], []),
])
def test_advice_follows_the_evidence(over, says, never):
    from paretocal.verdict import reliability

    rel = reliability(_fake_result(**over))
    text = " | ".join(rel.reasons)
    assert rel.verdict == "unreliable"
    for s in says:
        assert s in text, text
    for s in never:
        assert s not in text, text


def test_frames_without_edges_alone_leave_the_verdict_ok():
    """... and alone they only add nothing: the verdict stays ok."""
    from paretocal.verdict import reliability

    rel = reliability(_fake_result(feature_counts=EDGELESS))
    assert rel.verdict == "ok" and rel.reasons == ()


def test_a_contrast_without_spread_is_no_agreement():
    from paretocal.verdict import reliability

    rel = reliability(_fake_result(evidence={"contrast": {"frames_clear": 1.0, "z": None}}))
    assert rel.verdict == "unreliable"
    assert "every random pose within the stated initial error scores alike" in rel.reasons[0]


@pytest.mark.parametrize("over, ok", [({}, True), ({"frames": ["a", "b"]}, False)])
def test_intervals_are_given_only_for_a_result_judged_ok(over, ok):
    """An unreliable result's intervals are not what they claim (a wrong basin, frames that
    disagree): result.json keeps them under ``intervals_not_trusted`` and the console says
    none."""
    from paretocal.verdict import Intervals, interval_text, reliability

    iv = {"frame": "lidar", "units": {"x": "cm"}, "half_width": {"x": 1.5}, "undetermined": []}
    rel = reliability(_fake_result(evidence={"intervals": iv}, **over))
    written = Intervals.from_dict(iv).to_dict()
    assert written["half_width"] == {"x": 1.5, "y": None, "z": None, "yaw": None, "pitch": None,
                                     "roll": None}
    assert rel.verdict == ("ok" if ok else "unreliable")
    assert (rel.intervals is not None) == ok and (rel.intervals_not_trusted is None) == ok
    doc = rel.to_dict()
    assert doc["intervals"] == (written if ok else None)
    assert doc["intervals_not_trusted"] == (None if ok else written)
    assert interval_text(rel) == ("x +-1.5 cm" if ok else None)


# --- a very large cloud ---------------------------------------------------------------------------

def test_two_million_points_load_and_prepare(tmp_path, raw_frames):
    """18 KITTI sweeps in one cloud (about 2 M points) load and yield features; the arrays held
    at once stay within a loose multiple of the cloud's size (measured: about 6x)."""
    from paretocal.pipeline import prepare_features

    big = np.vstack([f.points for f in raw_frames[:18]])
    assert len(big) > 2_000_000
    root = write_generic(tmp_path / "big", raw_frames[:1])
    big.tofile(root / "points" / f"{raw_frames[0].name}.bin")
    del big
    tracemalloc.start()
    try:
        (frame,) = load_frames(root)
        feats = prepare_features([frame], frame.T_ref, Settings())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(frame.points) > 2_000_000 and len(feats[0].xyz) > 1000
    assert peak < 20 * frame.points.nbytes, f"peak {peak / 2**20:.0f} MB"


@pytest.mark.parametrize("command", [["study", "--quick"], ["depth"], ["batch"]])
def test_out_onto_a_file_is_refused_by_every_command(tmp_path, raw_date, capsys, command):
    blocker = tmp_path / "taken"
    blocker.write_text("a file")
    source = str(tmp_path / "m.yaml") if command[0] == "batch" else str(raw_date)
    code = main([command[0], source, "--out", str(blocker)] + command[1:])
    err = capsys.readouterr().err
    assert code == 2 and "--out" in err and "not a folder" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("command", [
    ["calibrate", "RIG", *FAST, "--out"], ["calibrate", "--resume"],
    ["check", "RIG", "--frames", "0:2", "--out"], ["perturb", "RIG", "--out"],
    ["depth", "RIG", "--frames", "0:1", "--out"], ["study", "RIG", "--out"],
    ["batch", "MANIFEST", "--out"], ["compare", "INIT", "INIT", "--out"],
    ["extract", "BAG", "--out"]], ids=lambda c: " ".join(c[:1] + c[-1:]))
def test_an_empty_path_is_refused(capfd, tmp_path, rig, monkeypatch, command):
    """``--out ''`` was the current folder: calibrate wrote its run there, exit 0."""
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    init = tmp_path / "init.yaml"
    write_extrinsic(init, np.eye(4))
    (tmp_path / "m.yaml").write_text(f"- {{id: a, source: {rig}}}\n")
    given = {"RIG": rig, "MANIFEST": tmp_path / "m.yaml", "INIT": init, "BAG": tmp_path / "b.bag"}
    option = command[-1]
    bad(capfd, *[given.get(a, a) for a in command], "",
        expect=f"Invalid value for '{option}': the path is empty")
    assert not list(cwd.iterdir())


# --- outputs: checked before the work; a failed write names the file ---------------------------

def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_disk_full_names_the_file_being_written(capfd, tmp_path, rig, monkeypatch):
    # Every text output is flushed to the disk (fsync) before it is renamed into place: a full
    # disk fails there at the latest.
    monkeypatch.setattr(os, "fsync", _no_space)
    out = tmp_path / "o"
    line = bad(capfd, "calibrate", rig, "--out", out, *FAST, "-q",
               expect=(str(out), ": cannot write (No space left on device)"))
    assert "result.json" in line and not (out / "result.json").exists()
    assert not (out / ".staging").exists()              # no half-written run is left behind
    init = tmp_path / "init.yaml"
    bad(capfd, "perturb", rig, "--out", init,
        expect=f"{init}: cannot write (No space left on device)")
    assert not init.exists()


@pytest.mark.skipif(not _can_drop_root_bypass(),
                    reason="running as root without setpriv: permissions do not apply")
def test_unwritable_resume_folder_and_check_out(capfd, tmp_path, rig):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "run_args.json").write_text(json.dumps(
        {"source": str(rig), "T_init": None, "settings": Settings().to_dict(), "figures": False}))
    ro = tmp_path / "ro"
    ro.mkdir()
    for d in (run_dir, ro):
        d.chmod(0o555)
    try:
        code, _, err = run_without_root_bypass(capfd, "calibrate", "--resume", run_dir)
        # check's --out is checked before anything is read: the missing source is not reached.
        code2, _, err2 = run_without_root_bypass(capfd, "check", tmp_path / "no_source",
                                                 "--extrinsic", tmp_path / "none.yaml",
                                                 "--out", ro / "r.json")
    finally:
        for d in (run_dir, ro):
            d.chmod(0o755)
    assert code == 2 and err.strip() == (f"paretocal: error: --resume {run_dir}: no permission "
                                         "to write there"), err
    assert code2 == 2 and err2.strip() == (f"paretocal: error: --out {ro / 'r.json'}: no "
                                           "permission to write there"), err2
    assert sorted(p.name for p in run_dir.iterdir()) == ["run_args.json"] and not any(ro.iterdir())


@pytest.mark.parametrize("command", ["check", "perturb"])
def test_file_out_onto_a_directory(capfd, tmp_path, rig, raw_frames, command):
    folder = tmp_path / "adir"
    folder.mkdir()
    extra = []
    if command == "check":
        write_extrinsic(tmp_path / "e.yaml", raw_frames[0].T_ref)
        extra = ["--extrinsic", tmp_path / "e.yaml"]
    bad(capfd, command, rig, *extra, "--out", folder,
        expect=f"--out {folder}: is a directory (give the name of the file to write)")
    assert not any(folder.iterdir()) and not list(tmp_path.glob(".adir*"))


@pytest.mark.parametrize("args, expect", [
    (["--rot", "nan"], "--rot nan: must be a finite number"),
    (["--rot", "inf"], "--rot inf: must be a finite number"),
    (["--trans", "nan"], "--trans nan: must be a finite number"),
    (["--trans", "-inf"], "--trans -inf: must be a finite number"),
    (["--rot", "-1"], "--rot -1: must not be negative"),
    (["--rot", "200"], "--rot 200: at most 180 degrees per axis"),
    (["--trans", "1e308"], "--trans 1e+308: too large (the box +-TRANS must have a finite width)"),
])
def test_perturb_bounds(capfd, tmp_path, rig, args, expect):
    bad(capfd, "perturb", rig, "--out", tmp_path / "p.yaml", *args, expect=expect)
    assert not (tmp_path / "p.yaml").exists()


@pytest.mark.parametrize("kind", ["dangling", "loop"])
@pytest.mark.parametrize("command", [["calibrate"], ["check"], ["perturb"], ["depth"],
                                     ["study", "--quick"]])
def test_out_a_symlink_that_leads_nowhere(capfd, tmp_path, rig, raw_frames, command, kind):
    link = tmp_path / "out"
    if kind == "loop":
        os.symlink(link.name, link)
        expect = f"--out {link}: symlink loop"
    else:
        os.symlink(tmp_path / "gone" / "x", link)
        expect = f"--out {link}: a symbolic link to {tmp_path / 'gone' / 'x'}, which does not exist"
    extra = []
    if command[0] == "check":
        write_extrinsic(tmp_path / "e.yaml", raw_frames[0].T_ref)
        extra = ["--extrinsic", tmp_path / "e.yaml"]
    bad(capfd, command[0], rig, *command[1:], *extra, "--out", link, expect=expect)
    assert link.is_symlink() and not (tmp_path / "gone").exists()      # left as it was


def _alias_bomb(last: str) -> str:
    """The "billion laughs": nine anchors, each a list of nine aliases of the one before
    (about 340 bytes, 387 million values expanded), and ``last`` using the top one (&i)."""
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi"):
        lines.append(f"{name}: &{name} [{', '.join(['*' + prev] * 9)}]")
    return "\n".join(lines + [last]) + "\n"


@pytest.mark.parametrize("where", ["calib.yaml", "--config", "--init"])
def test_yaml_alias_bomb_is_refused(capfd, tmp_path, rig, where):
    extra = []
    if where == "calib.yaml":
        path = rig / "calib.yaml"
        path.write_text(_alias_bomb(path.read_text().replace("T_cam_lidar:", "x:")
                                    + "T_cam_lidar: *i"))
    else:
        path = tmp_path / "bomb.yaml"
        path.write_text(_alias_bomb("T_cam_lidar: *i" if where == "--init"
                                    else "search: {pop: *i}"))
        extra = [where, path]
    assert len(path.read_bytes()) < 2000
    tracemalloc.start()
    try:
        bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *extra, *FAST,
            expect=f"{path}: its YAML aliases expand it to more than 1,000,000 values")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 100 * 2**20, f"peak {peak / 2**20:.0f} MB"        # nothing was expanded


def test_yaml_aliases_that_stay_small_are_read(tmp_path, raw_frames):
    from paretocal.io import read_extrinsic

    rows = json.dumps(raw_frames[0].T_ref.tolist())
    path = tmp_path / "init.yaml"
    path.write_text(f"T: &t {rows}\nT_cam_lidar: *t\ncopies: [*t, *t, *t]\n")
    np.testing.assert_allclose(read_extrinsic(path), raw_frames[0].T_ref, atol=1e-12)
    path.write_text("a: &a [1, *a]\nT_cam_lidar: *a\n")
    with pytest.raises(ParetocalError, match="refers to a structure that contains it"):
        read_extrinsic(path)


# --- symbolic links in the source that lead nowhere -------------------------------------------

@pytest.mark.parametrize("target, what", [
    ("", "source folder"), ("calib.yaml", "file"), ("images", "image folder"),
    ("points/{stem}.bin", "point cloud file"), ("images/{stem}.png", "image file")])
def test_symlink_loops_in_the_source_are_named(capfd, tmp_path, rig, raw_frames, target, what):
    path = rig / target.format(stem=_stem(raw_frames)) if target else tmp_path / "loop"
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
    os.symlink(path.name, path)                    # a link to itself
    bad(capfd, "calibrate", rig if target else path, "--out", tmp_path / "o", *FAST,
        expect=f"{path}: {what} not reachable: symlink loop")


def test_a_dangling_link_in_the_source_is_named(capfd, tmp_path, rig, raw_frames):
    path = rig / "points" / f"{_stem(raw_frames)}.bin"
    path.unlink()
    os.symlink(tmp_path / "moved.bin", path)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(f"{path}: point cloud file not reachable: a symbolic link to "
                f"{tmp_path / 'moved.bin'}, which does not exist"))


# --- results and commands ---------------------------------------------------------------------

def test_check_without_an_extrinsic_on_a_dataset_without_one(capfd, tmp_path, raw_frames):
    """``check`` takes the dataset's own extrinsic by default; a folder whose calib.yaml has
    none exits 2 saying to pass --extrinsic, before any feature is computed."""
    folder = write_generic(tmp_path / "noT", raw_frames[:1], with_T=False)
    bad(capfd, "check", folder,
        expect=(f"{folder}: the dataset has no extrinsic of its own (T_cam_lidar in "
                "calib.yaml); pass --extrinsic FILE"))


# --- sizes, excerpts and start-up -------------------------------------------------------------
# A file's contents reach a message only as a short excerpt; what a header claims is checked
# before anything is allocated for it; an interrupt while the command line starts prints one line.

SHADOW = ("root:$6$Zq0sAlt$0123456789abcdefHASHhashHASH:19000:0:99999:7:::\n"
          "alice:$6$pepper$secretSECRETsecret/0123456789:19000:0:99999:7:::\n")


@pytest.mark.parametrize("option, expect", [
    ("--init", "no extrinsic found (keys: 2 not shown (not plain names)); expected T_cam_lidar"),
    ("--config", "unknown section(s) 2 not shown (not plain names) (known: "),
])
def test_a_colon_separated_text_file_is_not_echoed(capfd, tmp_path, rig, option, expect):
    """Each line of /etc/shadow ends in ':', so YAML reads it as a key: the keys used to be
    listed in the message, whole."""
    path = tmp_path / "shadow"
    path.write_text(SHADOW)
    line = bad(capfd, "calibrate", rig, option, path, "--out", tmp_path / "o", *FAST,
               expect=(str(path), expect))
    assert "$6$" not in line and "secret" not in line and "alice" not in line


def test_values_of_a_file_are_quoted_short_and_on_one_line(capfd, tmp_path, rig):
    """A value in a message is a bounded excerpt with its control characters escaped: no
    second line, no terminal escape sequence, however long the value."""
    _edit_calib(rig, lambda c: c["camera"].update(width="wide\n\x1b[2J" + "w" * 100_000))
    line = bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
               expect="camera.width must be a positive whole number of pixels, got 'wide\\n\\x1b[2J")
    assert len(line) < 300 and "\x1b" not in line
    _edit_calib(rig, lambda c: c["camera"].update(width=1242))
    many = {f"key{k}": k for k in range(10_000)}
    path = tmp_path / "init.yaml"
    path.write_text(yaml.safe_dump(many))
    line = bad(capfd, "calibrate", rig, "--init", path, "--out", tmp_path / "o", *FAST,
               expect="no extrinsic found (keys: key0, key1, ")
    assert len(line) < 500 and "more)" in line


def test_a_batch_reason_is_one_bounded_line(tmp_path, rig, monkeypatch):
    """The reason of a failed entry goes into summary.csv and summary.parquet: the same
    excerpt as on the command line, and any exception's message on one bounded line."""
    import pyarrow.parquet as pq

    from paretocal.apps import batch
    from paretocal.errors import MESSAGE_CHARS

    init = tmp_path / "shadow"
    init.write_text(SHADOW)
    records = [batch.run_entry(batch.Entry(id="leaky", source=str(rig), init=str(init)),
                               Settings().to_dict(), str(tmp_path / "out"), check=False)]

    def odd(*args, **kwargs):
        raise ValueError("first line\nsecond line " + "x" * 10_000)
    monkeypatch.setattr("paretocal.pipeline.calibrate", odd)
    records.append(batch.run_entry(batch.Entry(id="odd", source=str(rig)), Settings().to_dict(),
                                   str(tmp_path / "out"), check=False))
    batch.write_summary(batch.summary_rows(records), tmp_path)
    reasons = pq.read_table(tmp_path / "summary.parquet").to_pydict()["reason"]
    assert reasons[0].startswith(f"{init}: no extrinsic found (keys: 2 not shown")
    assert reasons[1].startswith("unexpected ValueError: first line\\nsecond line xxx")
    for reason in reasons:
        assert "\n" not in reason and len(reason) <= MESSAGE_CHARS and "$6$" not in reason
    text = (tmp_path / "summary.csv").read_text()
    assert "$6$" not in text and len(text.splitlines()) == 3


def _npy_claiming(path, shape, dtype="<f8", data=b"\0" * 64):
    """A .npy file whose header says ``shape`` of ``dtype`` followed by ``data``."""
    buf = __import__("io").BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False,
                                               "shape": shape})
    path.write_bytes(buf.getvalue() + data)


@pytest.mark.parametrize("shape, expect", [
    ((10**12, 4), "1,000,000,000,000 points by its header (shape (1000000000000, 4), float64), "
                  "more than the 33,554,432 a point cloud file may hold"),
    ((1000, 4), "the .npy header says shape (1000, 4) of float64 (32,000 bytes), but 64 bytes "
                "of data follow; the file is truncated or its header is wrong"),
    ((10**6, 10**4), "80,000,000,000 bytes of point data by its header (shape (1000000, 10000), "
                     "float64), more than the 2 GiB a point cloud file may hold"),
])
def test_an_npy_header_claiming_too_much_is_refused_before_reading(capfd, tmp_path, rig,
                                                                   raw_frames, shape, expect):
    (rig / "points" / f"{_stem(raw_frames)}.bin").unlink()
    path = rig / "points" / f"{_stem(raw_frames)}.npy"
    _npy_claiming(path, shape)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(str(path), expect))


def _npy_raw_header(text: str, version: int = 1) -> bytes:
    """A .npy file whose header is ``text`` as it stands (no check that it parses), followed by
    64 bytes of data; ``version`` 1 (a 2-byte length) or 3 (4 bytes, UTF-8)."""
    body = text.encode("utf-8")
    body += b" " * (-(len(body) + 7 + 2 * version) % 64) + b"\n"
    size = len(body).to_bytes(2 if version == 1 else 4, "little")
    return b"\x93NUMPY" + bytes([version, 0]) + size + body + b"\0" * 64


def _nested_shape(minuses: int) -> str:
    return ("{'descr': '<f8', 'fortran_order': False, 'shape': (" + "-" * minuses
            + "5, 4), }")


@pytest.mark.parametrize("content, expect", [
    (_npy_raw_header(_nested_shape(5_000)), "unreadable .npy header (its shape is nested too "
                                            "deeply to be read)"),
    (_npy_raw_header(_nested_shape(9_000)), "unreadable .npy header (its shape is nested too "
                                            "deeply to be read)"),
    (_npy_raw_header(_nested_shape(1_000_000), version=3),
     "a .npy header of 1,000,116 bytes, more than the 10,000 numpy writes and reads"),
    (_npy_raw_header("{'descr': '<f8', 'fortran_order': False, 'shape': (-5, 4), }"),
     "unreadable .npy header (shape (-5, 4) is not a tuple of sizes)"),
], ids=["5,000 minuses", "9,000 minuses", "1 MB v3.0 header", "negative size"])
def test_an_npy_header_that_cannot_be_a_header_is_refused(capfd, tmp_path, rig, raw_frames,
                                                          content, expect):
    """A .npy header whose shape is an expression nested thousands deep (exit 1 before:
    RecursionError, MemoryError), or a header longer than numpy itself reads (1 MB)."""
    (rig / "points" / f"{_stem(raw_frames)}.bin").unlink()
    path = rig / "points" / f"{_stem(raw_frames)}.npy"
    path.write_bytes(content)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(f"{path}: {expect}",))


def _pcd(header: str, data: bytes = b"") -> bytes:
    return ("VERSION 0.7\n" + header + "VIEWPOINT 0 0 0 1 0 0 0\n").encode() + data


@pytest.mark.parametrize("name, content, expect", [
    ("points.pcd", _pcd("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 100000000\n"
                        "HEIGHT 1\nPOINTS 100000000\nDATA binary\n", b"\0" * 24),
     "100,000,000 points by its header, more than the 33,554,432"),
    ("count.pcd", _pcd("FIELDS x y z d\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 5000\n"
                       "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n", b"\0" * 16),
     "PCD header COUNT sums to 5,003 values per point, more than the 4,096"),
    ("shadow.pcd", SHADOW.encode(),
     "not a PCD file: the header starts with a word that is no PCD keyword"),
    ("vertices.ply", b"ply\nformat ascii 1.0\nelement vertex 1000000000000\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n1 2 3\n",
     "1,000,000,000,000 points by its header (element vertex), more than the 33,554,432"),
    ("faces.ply", b"ply\nformat ascii 1.0\nelement face 1000000000000\nproperty float q\n"
                  b"element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  b"end_header\n1\n1 2 3\n4 5 6\n7 8 9\n",
     "PLY ascii data has 4 lines; the header says 1000000000000 before the 3 vertex lines"),
])
def test_cloud_headers_claiming_too_much_are_refused(tmp_path, name, content, expect):
    """Refused from the header, before anything of the claimed size is allocated (a count of
    10**8 per point used to make 10**8 columns; 10**12 PLY lines made numpy reserve them)."""
    from paretocal.io.clouds import read_cloud

    path = tmp_path / name
    path.write_bytes(content)
    tracemalloc.start()
    try:
        with pytest.raises(ParetocalError) as info:
            read_cloud(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert str(info.value).startswith(f"{path}: ") and expect in str(info.value)
    assert "$6$" not in str(info.value) and peak < 20 * 2**20


def test_a_bag_cloud_field_with_a_huge_count_is_refused(capfd, tmp_path, raw_frames):
    """A PointCloud2 field of 10**9 values per point: numpy cannot even make its type (exit 1,
    "unexpected error"); it lies beyond the point's bytes, which says what is wrong."""
    pytest.importorskip("rosbags")
    from .test_bags import PERIOD, T0, Msgs, records, write_bag

    msgs, frames = Msgs(ros1=True), raw_frames[:2]
    images = [msgs.image(T0 + k * PERIOD, f.image, "bgr8") for k, f in enumerate(frames)]
    clouds = [msgs.cloud(T0 + k * PERIOD + 3_000_000, records(f)) for k, f in enumerate(frames)]
    clouds[0].fields[3].count = 10**9                   # intensity, float32 at offset 12
    bag = write_bag(tmp_path / "huge.bag", "ros1", {
        "/img": images, "/pts": clouds, "/info": [msgs.info(T0, frames[0].camera)]})
    bad(capfd, "extract", bag, "--out", tmp_path / "o", "--image-topic", "/img",
        "--cloud-topic", "/pts",
        expect=(f"{bag}: topic '/pts', cloud 0 (stamp ", "PointCloud2 field 'intensity' at "
                "offset 12 (1000000000 x 4 bytes) lies beyond point_step 22"))
    assert not (tmp_path / "o").exists()


def _png_header(width: int, height: int, depth: int = 8, colour: int = 0) -> bytes:
    """The start of a PNG of ``width`` x ``height`` pixels of ``depth`` bits (``colour``: 0
    grey, 6 RGBA): signature and IHDR (a decoder reads the size from there; the pixel data
    need not follow)."""
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    chunk = struct.pack(">I", 13) + b"IHDR" + ihdr
    return (b"\x89PNG\r\n\x1a\n" + chunk + struct.pack(">I", zlib.crc32(chunk[4:]))
            + bytes(64))


def _jpeg_header(width: int, height: int) -> bytes:
    """The start of a JPEG of ``width`` x ``height``: SOI, an APP0 segment, a baseline frame
    header (SOF0)."""
    app0 = b"\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"
    sof = (b"\xff\xc0\x00\x0b\x08" + height.to_bytes(2, "big") + width.to_bytes(2, "big")
           + b"\x01\x01\x11\x00")
    return b"\xff\xd8" + app0 + sof + bytes(64)


@pytest.mark.parametrize("suffix, head", [(".png", _png_header(20000, 20000)),
                                          (".jpg", _jpeg_header(65000, 65000))])
def test_an_image_header_claiming_too_many_pixels_is_refused_before_decoding(
        capfd, tmp_path, rig, raw_frames, suffix, head):
    """A 20000 x 20000 PNG (a 1 MB file) used to be decoded, 1.2 GB and 14 s, before its size
    was compared with the camera's; its header says enough."""
    (rig / "images" / f"{_stem(raw_frames)}.png").unlink()
    path = rig / "images" / f"{_stem(raw_frames)}{suffix}"
    path.write_bytes(head)
    w, h = (20000, 20000) if suffix == ".png" else (65000, 65000)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(path), f"the image header says {w}x{h} pixels, more than the 268,435,456 "
                           "an image may have"))


def test_image_header_sizes_match_the_decoder():
    """The header reader agrees with OpenCV on real PNG and JPEG files (baseline and
    progressive, with an EXIF segment) and leaves other formats to the decoder."""
    from io import BytesIO

    from PIL import Image

    from paretocal.io.bags import compressed_image
    from paretocal.io.images import image_header_size

    img = np.random.default_rng(1).integers(0, 255, (37, 53, 3), np.uint8)
    files = [cv2.imencode(ext, img)[1].tobytes() for ext in (".png", ".jpg", ".bmp")]
    progressive = BytesIO()
    Image.fromarray(img).save(progressive, "JPEG", progressive=True, exif=b"Exif\0\0" + bytes(900))
    files.append(progressive.getvalue())
    sizes = [image_header_size(BytesIO(f)) for f in files]
    assert sizes == [(53, 37), (53, 37), None, (53, 37)]
    with pytest.raises(ParetocalError, match="bag: the image header says 20000x20000 pixels"):
        compressed_image(SimpleNamespace(format="png", data=_png_header(20000, 20000)), "bag")


def _padded(jpeg: bytes, padding: str) -> bytes:
    """``jpeg`` with 1,100 fill bytes (0xFF, which may precede any marker) or 1,100 empty
    comment segments after its start (SOI): legal, and both once hid the frame header from the
    header reader, which stopped after 1,024 segments."""
    pad = b"\xff" * 1100 if padding == "fill" else b"\xff\xfe\x00\x02" * 1100
    return jpeg[:2] + pad + jpeg[2:]


@pytest.mark.parametrize("padding", ["fill", "comments"])
def test_the_jpeg_header_is_found_after_any_padding(padding):
    """On a real JPEG padded before its frame header, the header reader agrees with the
    decoder."""
    from io import BytesIO

    from paretocal.io.images import image_header_size

    img = np.random.default_rng(2).integers(0, 255, (37, 53, 3), np.uint8)
    data = _padded(cv2.imencode(".jpg", img)[1].tobytes(), padding)
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED).shape == (37, 53, 3)
    assert image_header_size(BytesIO(data)) == (53, 37)
    # Cut before its frame header, a JPEG gives no size (the decoder then judges it).
    assert image_header_size(BytesIO(data[:2 + 1100])) is None


def _never_decoded(monkeypatch):
    """Make any decoding fail the test: the size must be refused from the header."""
    monkeypatch.setattr(cv2, "imdecode",
                        lambda *a, **k: pytest.fail("decoded before the size was checked"))


@pytest.mark.parametrize("suffix, head, expect", [
    (".jpg", _padded(_jpeg_header(30000, 30000), "fill"),
     "the image header says 30000x30000 pixels, more than the 268,435,456 an image may have"),
    (".jpg", _padded(_jpeg_header(30000, 30000), "comments"),
     "the image header says 30000x30000 pixels, more than the 268,435,456 an image may have"),
    (".jpg", _padded(_jpeg_header(4000, 3000), "comments"),
     "image is 4000x3000 but the calibration says 1242x375"),
    (".png", _png_header(16384, 16384, depth=16, colour=6),
     "image is 16384x16384 but the calibration says 1242x375"),
], ids=["jpeg after fill bytes", "jpeg after comments", "jpeg of another size",
        "16-bit png of another size"])
def test_an_image_of_another_size_is_refused_from_its_header(
        capfd, tmp_path, rig, raw_frames, monkeypatch, suffix, head, expect):
    """The size is read from the header whatever precedes it and compared with the
    calibration's before decoding: a JPEG whose frame header came after 1,100 fill bytes or
    empty comments was decoded whole (5.3 GB, 8-13 s at 30000 x 30000), as was a 16384 x 16384
    16-bit PNG (4.3 GB, 29 s) of another size than the camera's."""
    (rig / "images" / f"{_stem(raw_frames)}.png").unlink()
    path = rig / "images" / f"{_stem(raw_frames)}{suffix}"
    path.write_bytes(head)
    _never_decoded(monkeypatch)
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST, expect=(f"{path}: {expect}",))


def test_a_bag_image_of_another_size_is_refused_from_its_header(monkeypatch):
    """The same for a bag's CompressedImage (a padded 30000 x 30000 JPEG: 5.2 GB decoded),
    against the camera's size when it is known."""
    from paretocal.io.bags import compressed_image

    _never_decoded(monkeypatch)
    msg = SimpleNamespace(format="jpeg", data=_padded(_jpeg_header(30000, 30000), "fill"))
    with pytest.raises(ParetocalError, match="bag: the image header says 30000x30000 pixels"):
        compressed_image(msg, "bag")
    msg = SimpleNamespace(format="png", data=_png_header(16384, 16384, depth=16, colour=6))
    with pytest.raises(ParetocalError,
                       match="^bag: image is 16384x16384 but the camera is 1242x375$"):
        compressed_image(msg, "bag", size=(1242, 375))


def test_a_text_file_too_large_is_refused_before_parsing(capfd, tmp_path, rig):
    """A 200 MB calib.yaml was still parsing after two minutes; beyond 8 MiB a text input is
    refused from its size, before it is read."""
    path = rig / "calib.yaml"
    with open(path, "a") as fh:
        fh.write(("# " + "x" * 1022 + "\n") * (9 << 10))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(str(path), " bytes, more than the 8 MiB a YAML, JSON, CSV or calibration text "
                           "file may hold"))


@pytest.mark.parametrize("where, text, expect", [
    ("calib.yaml", "{calib}camera: {{K: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}\n",
     "'camera' is given twice in one mapping (lines "),
    ("calib.yaml", "{calib}x: {{a: 1, a: 2}}\n",
     "'a' is given twice in one mapping (line "),
    ("--init", "T_cam_lidar: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n"
               "T_cam_lidar: [[0,-1,0,0],[0,0,-1,0],[1,0,0,0],[0,0,0,1]]\n",
     "'T_cam_lidar' is given twice in one mapping (lines 1 and 2)"),
    ("--init.json", '{"T_cam_lidar": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]],'
                    ' "T_cam_lidar": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}',
     "'T_cam_lidar' is given twice in one mapping; a key may appear once"),
    ("--config", "search:\n  pop: 16\n  gens: 3\n  pop: 400\n",
     "'pop' is given twice in one mapping (lines 2 and 4)"),
])
def test_a_key_given_twice_is_refused(capfd, tmp_path, rig, where, text, expect):
    """YAML (and JSON) keep the last of two equal keys silently: one of them is a mistake."""
    if where == "calib.yaml":
        path = rig / "calib.yaml"
        path.write_text(text.format(calib=path.read_text()))
        extra = []
    else:
        option, _, suffix = where.partition(".")
        path = tmp_path / f"file.{suffix or 'yaml'}"
        path.write_text(text)
        extra = [option, path]
    bad(capfd, "calibrate", rig, *extra, "--out", tmp_path / "o", *FAST,
        expect=(str(path), expect))


def test_a_manifest_key_given_twice_is_refused(tmp_path):
    from paretocal.apps.batch import read_manifest

    path = tmp_path / "m.yaml"
    path.write_text("- {id: a, source: x, source: y}\n")
    with pytest.raises(ParetocalError, match="'source' is given twice in one mapping"):
        read_manifest(path)


def test_a_manifest_yaml_error_quotes_no_line(tmp_path):
    """PyYAML's own message quotes the line it stopped at; the manifest's error used to carry
    it, now only its line and column."""
    from paretocal.apps.batch import read_manifest

    path = tmp_path / "m.yaml"
    path.write_text("- {id: a, source: [" + "secret" * 100 + "\n")
    with pytest.raises(ParetocalError) as info:
        read_manifest(path)
    assert str(info.value).startswith(f"{path}: not valid YAML (line 2, column 1: ")
    assert "secret" not in str(info.value)


def test_yaml_merge_keys_may_be_overridden():
    from paretocal.io.text import load_yaml

    doc = load_yaml("base: &b {pop: 16, gens: 3}\nsearch:\n  <<: *b\n  gens: 5\n", "x")
    assert doc["search"] == {"pop": 16, "gens": 5}


def test_devices_and_fifos_are_named_and_never_opened(capfd, tmp_path, rig, raw_frames):
    """A mask that is /dev/zero was said to be "not found"; a FIFO given as an input must not
    be opened (reading it waits for a writer)."""
    from paretocal.apps import batch

    _edit_calib(rig, lambda c: c["camera"].update(mask="/dev/zero"))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect=(f"{rig / 'calib.yaml'}: camera.mask file /dev/zero is a character device, "
                "not a regular file"))
    _edit_calib(rig, lambda c: c["camera"].pop("mask"))
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    try:
        bad(capfd, "calibrate", rig, "--init", fifo, "--out", tmp_path / "o", *FAST,
            expect=f"{fifo}: file expected, but this is a named pipe (FIFO)")
        bad(capfd, "batch", fifo, "--out", tmp_path / "b",
            expect=f"{fifo}: a manifest expected, but this is a named pipe (FIFO)")
        # The batch fingerprint hashes an entry's init file: not a FIFO.
        entry = batch.Entry(id="a", source=str(rig), init=str(fifo))
        assert batch.entry_fingerprint(entry, Settings().to_dict())
        stem = _stem(raw_frames)
        for sub, name in (("points", f"{stem}.bin"), ("images", f"{stem}.png")):
            kept = (rig / sub / name).read_bytes()
            (rig / sub / name).unlink()
            os.mkfifo(rig / sub / name)
            bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
                expect=f"{rig / sub / name}: {'point cloud' if sub == 'points' else 'image'} "
                       "file expected, but this is a named pipe (FIFO)")
            (rig / sub / name).unlink()
            (rig / sub / name).write_bytes(kept)
        (rig / "calib.yaml").unlink()
        os.mkfifo(rig / "calib.yaml")
        bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
            expect=f"{rig / 'calib.yaml'}: file expected, but this is a named pipe (FIFO)")
    finally:
        # Should anything have opened a FIFO, let it go: open the write end and close it.
        for path in (fifo, rig / "calib.yaml"):
            if path.exists() and not path.is_file():
                with contextlib.suppress(OSError):
                    os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))


def test_a_path_too_long_in_calib_yaml_is_named(capfd, tmp_path, rig):
    """A mask name longer than the system allows used to escape as an OSError (exit 1) and
    print the whole name; one holding a NUL character as a ValueError."""
    _edit_calib(rig, lambda c: c["camera"].update(mask="m" * 5000))
    line = bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
               expect="camera.mask file ")
    assert line.endswith("cannot be reached (File name too long)") and len(line) < 1500
    _edit_calib(rig, lambda c: c["camera"].update(mask="a\0b.png"))
    bad(capfd, "calibrate", rig, "--out", tmp_path / "o", *FAST,
        expect="camera.mask file ")


def test_a_read_only_file_system_is_not_called_no_permission(capfd, tmp_path, rig,
                                                             monkeypatch):
    """os.access says no for a folder on a read-only mount as for one without permission;
    the file system's flags tell which (no read-only mount is available to the tests)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real_access, real_statvfs = os.access, os.statvfs

    def access(path, mode, *args, **kwargs):
        return False if str(path).startswith(str(ro)) else real_access(path, mode, *args, **kwargs)

    def statvfs(path):
        if str(path).startswith(str(ro)):
            return SimpleNamespace(f_flag=os.ST_RDONLY)
        return real_statvfs(path)
    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(os, "statvfs", statvfs)
    bad(capfd, "calibrate", rig, "--out", ro / "run", *FAST,
        expect=f"--out {ro / 'run'}: read-only file system")
    bad(capfd, "perturb", rig, "--out", ro / "init.yaml",
        expect=f"--out {ro / 'init.yaml'}: read-only file system")

    out, real_replace = tmp_path / "o", os.replace

    def replace(src, dst, *args, **kwargs):                 # the file system went read-only
        if str(dst).startswith(str(out)):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))
        return real_replace(src, dst, *args, **kwargs)
    monkeypatch.setattr(os, "access", real_access)
    monkeypatch.setattr(os, "replace", replace)
    bad(capfd, "calibrate", rig, "--out", out, *FAST, "-q",
        expect=(str(out), "cannot write (Read-only file system)"))


def _caught(pid: int) -> int:
    """The signals process ``pid`` catches (a handler is installed), as a bit mask (bit
    signum - 1), from /proc; 0 when it has gone."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            return next(int(ln.split()[1], 16) for ln in fh if ln.startswith("SigCgt:"))
    except (OSError, StopIteration):
        return 0


@pytest.mark.parametrize("command", ["calibrate", "check"])
def test_a_closed_stdout_ends_the_command_quietly(tmp_path, rig, command):
    """stdout a pipe whose reader is gone (``calibrate ... | true``): the command did its work
    and exited 1 without a word; now it finishes (the run folder whole) and exits 141, the
    status of a writer whose reader left (128 + SIGPIPE), with no error line."""
    from paretocal.cli import PIPE_EXIT

    args = (["calibrate", rig, "--out", tmp_path / "o", *FAST] if command == "calibrate" else
            ["check", rig, "--frames", "0:2"])
    code, err = run_with_stdout_closed(*args)
    assert code == PIPE_EXIT == 141, err
    assert "error" not in err and "Traceback" not in err, err
    if command == "calibrate":
        names = {p.name for p in (tmp_path / "o").iterdir()}
        assert {"result.json", "run_args.json", "pareto.csv"} <= names, names
        assert not {".staging", ".lock"} & names


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs Linux's /proc")
@pytest.mark.parametrize("how", ["-m", "console"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("delay", [0, 0.02, 0.05, 0.1, 0.2])
def test_a_signal_while_starting_prints_one_line(tmp_path, raw_date, how, sig, delay):
    """SIGINT, SIGTERM or SIGHUP while the command line starts (it imports typer and click,
    some 0.1 s, before cli.main takes over): one line and exit 130, 143 or 129, no traceback;
    from then on SIGTERM and SIGHUP are a Ctrl-C, as before (exit 130, "interrupted before the
    run started" or how the run stopped; test_resume.py
    ``test_ctrl_c_at_any_time_prints_one_line_and_no_traceback``).

    The delays count from the moment the process catches SIGTERM, i.e. from the first lines
    of paretocal/__main__.py (before them the interpreter starts, about 15 ms of site and
    runpy that no code of the package can reach: a signal then kills the process, or Python
    prints its own traceback). Without those lines the command line caught it only once
    cli.main ran, and a signal before that ended the process with a traceback (SIGINT) or
    silently (SIGTERM)."""
    args = ["calibrate", str(raw_date), "--out", str(tmp_path / "run"), "--gens", "3000",
            "--frames", "0:2", "--no-figures"]
    start = (["-m", "paretocal"] if how == "-m"
             else ["-c", "from paretocal.__main__ import console; console()"])
    proc = subprocess.Popen([sys.executable, *start, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, preexec_fn=default_sigint)
    term = 1 << (signal.SIGTERM - 1)
    deadline = time.monotonic() + 60
    while not _caught(proc.pid) & term and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.0005)
    time.sleep(delay)
    proc.send_signal(sig)
    out, _ = proc.communicate(timeout=120)
    lines = out.strip().splitlines()
    assert "Traceback" not in out and len(lines) == 1, out
    starting = {signal.SIGINT: (130, "paretocal: interrupted while starting; nothing was written"),
                signal.SIGTERM: (143, "paretocal: terminated while starting; nothing was written"),
                signal.SIGHUP: (129, "paretocal: hung up while starting; nothing was written")}
    if delay > 0.02 and (proc.returncode, lines[0]) != starting[sig]:
        # The command line took over (after importing typer and click, some 0.1 s): as today.
        assert proc.returncode == 130 and lines[0].startswith("paretocal: interrupted"), out
    else:
        assert (proc.returncode, lines[0]) == starting[sig], out
    assert not (tmp_path / "run" / "result.json").exists()
