"""The command line end to end on real frames, and its handling of bad input."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

from paretocal.cli import main
from paretocal.geometry import correction_params, invert, pose_error
from paretocal.io import read_extrinsic
from paretocal.quality import TO_REPORT

from .helpers import PROGRESS_LINE, write_generic

FAST = ["--pop", "16", "--gens", "3", "--frames", "0:2", "--no-polish"]


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def init_file(tmp_path_factory, raw_date):
    p = tmp_path_factory.mktemp("init") / "init.yaml"
    assert main(["perturb", str(raw_date), "--out", str(p), "--rot", "2", "--trans", "0.1",
                 "--seed", "5"]) == 0
    return p


class TestCalibrate:
    def test_end_to_end_writes_the_run_directory(self, tmp_path, raw_date, raw_frames, init_file,
                                                 capsys):
        out = tmp_path / "run"
        code, stdout, err = _run(capsys, "calibrate", raw_date, "--init", init_file, "--out", out,
                                 "--pop", "16", "--gens", "3", "--frames", "0:2", "--seed", "1")
        assert code == 0, err
        assert "chosen n =" in stdout and "error vs reference" in stdout
        # stderr is not a terminal here: one line per stage as it begins, with the time since
        # the start; no bars.
        stages = [line.split(" s  ", 1) for line in err.splitlines() if PROGRESS_LINE.match(line)]
        assert [text for _, text in stages] == [
            "loading the frames", "locating the LiDAR", "recovering the LiDAR rings",
            "compensating the motion", "extracting features (2 frames)", "scoring the seed grid",
            "searching (3 NSGA-II generations)", "polishing the front", "choosing the solution",
            "gathering the verdict's evidence", "writing the results"], err
        times = [float(t.split()[-1]) for t, _ in stages]
        assert times == sorted(times)
        assert "\x1b" not in err                                # no terminal control codes
        for name in ("result.json", "pareto.csv", "extrinsic.yaml", "pareto.png",
                     "overlay_before.png", "overlay_after.png", "overlay_reference.png"):
            assert (out / name).stat().st_size > 0, name
        doc = json.loads((out / "result.json").read_text())
        assert doc["seed"] == 1 and doc["config"]["search"]["pop"] == 16
        assert doc["frames"] == ["0000000000", "0000000001"]
        # The reported errors are those of the written extrinsics against KITTI's reference.
        ref = raw_frames[0].T_ref
        e0 = pose_error(read_extrinsic(init_file), ref)
        assert doc["initial_error"]["rotation_deg"] == pytest.approx(float(e0["rotation_deg"]))
        e1 = pose_error(np.array(doc["T_cam_lidar"]), ref)
        assert doc["reference_error"]["translation_cm"] == pytest.approx(
            float(e1["translation_cm"]))
        # Every x, y, z says its frame: the per-axis errors in the LiDAR frame (the
        # correction's and the intervals' axes) are the correction from the reference to the
        # result; the camera frame's are named so.
        err_ref = doc["reference_error"]
        lidar = [err_ref[k] for k in ("x_lidar_cm", "y_lidar_cm", "z_lidar_cm", "yaw_deg",
                                      "pitch_deg", "roll_deg")]
        np.testing.assert_allclose(
            lidar, correction_params(invert(ref) @ np.array(doc["T_cam_lidar"])) * TO_REPORT,
            atol=1e-9)
        assert {"x_cam_cm", "y_cam_cm", "z_cam_cm"} <= set(err_ref) and "x_cm" not in err_ref
        assert doc["correction_frame"] == doc["quality"]["frame"] == "lidar"
        line = next(x for x in stdout.splitlines() if "per axis (LiDAR frame)" in x)
        assert line.startswith("paretocal: error vs reference per axis (LiDAR frame): x ")
        assert f"z {err_ref['z_lidar_cm']:+.3g} cm" in line and line.endswith(" deg")
        # Two frames: judged unreliable, so no intervals on the console or in result.json
        # (they are kept under a name that says so).
        assert doc["reliability"]["verdict"] == "unreliable"
        assert "95 % intervals" not in stdout and doc["reliability"]["intervals"] is None
        assert doc["reliability"]["intervals_not_trusted"]["frame"] == "lidar"
        T = read_extrinsic(out / "extrinsic.yaml")
        np.testing.assert_allclose(T, doc["T_cam_lidar"], atol=1e-8)
        rows = (out / "pareto.csv").read_text().splitlines()
        header = rows[0].split(",")
        for col in ("x", "y", "z", "yaw", "pitch", "roll", "n", "chamfer", "cost", "ms", "bytes",
                    "ref_rotation_deg", "ref_translation_cm", "ref_x_lidar_cm", "ref_x_cam_cm",
                    "chosen"):
            assert col in header
        assert sum(r.endswith(",1") for r in rows[1:]) == 1
        assert not list(out.glob(".*tmp*"))                     # no temporary files left

    def test_result_can_be_the_next_init(self, tmp_path, raw_date, init_file, capsys):
        a = tmp_path / "a"
        code, stdout, _ = _run(capsys, "calibrate", raw_date, "--init", init_file, "--out", a,
                               *FAST, "--no-figures")
        assert code == 0
        # Two frames: the last line gives the verdict and its main reason.
        assert stdout.strip().splitlines()[-1].startswith(
            "paretocal: verdict UNRELIABLE: only 2 frame(s)")
        b = tmp_path / "b"
        code, _, err = _run(capsys, "calibrate", raw_date, "--init", a / "extrinsic.yaml",
                            "--out", b, *FAST, "--no-figures")
        assert code == 0, err

    def test_strict_exits_3_on_an_unreliable_result(self, tmp_path, raw_date, init_file,
                                                    capsys):
        out = tmp_path / "s"
        code, stdout, err = _run(capsys, "calibrate", raw_date, "--init", init_file, "--out",
                                 out, *FAST, "--no-figures", "--strict", "--quiet")
        assert code == 3 and err == ""                           # --quiet: no progress lines
        assert "verdict UNRELIABLE" in stdout.strip().splitlines()[-1]
        doc = json.loads((out / "result.json").read_text())   # written all the same
        assert doc["reliability"]["verdict"] == "unreliable"

    def test_config_file_and_budget(self, tmp_path, raw_date, init_file, capsys):
        cfg = tmp_path / "cfg.yaml"
        cfg.write_text(yaml.safe_dump({"search": {"pop": 12, "gens": 2},
                                       "objective": {"w_edge": 0.8}}))
        out = tmp_path / "run"
        code, _, err = _run(capsys, "calibrate", raw_date, "--init", init_file, "--out", out,
                            "--config", cfg, "--frames", "0", "--budget-ms", "1000",
                            "--no-figures", "--no-polish")
        assert code == 0, err
        doc = json.loads((out / "result.json").read_text())
        assert doc["config"]["search"]["pop"] == 12
        assert doc["config"]["objective"]["w_edge"] == 0.8
        assert doc["decision"]["rule"] == "budget" and doc["objectives"]["ms"] <= 1000

    def test_version_and_short_help(self, capsys):
        from paretocal import __version__

        assert main(["--version"]) == 0
        assert capsys.readouterr().out.strip() == f"paretocal {__version__}"
        assert main(["calibrate", "-h"]) == 0
        assert "--budget-ms" in capsys.readouterr().out
        assert main([]) == 2                        # the help, and no empty error line
        assert "error" not in capsys.readouterr().err

    def test_help_shows_flags_without_a_value_and_the_search_defaults(self, capsys,
                                                                      monkeypatch):
        """A flag takes no value: no ``<bool>`` beside ``--version``, ``--help`` or any
        other flag; ``--pop`` and ``--gens`` name their defaults (issue 45)."""
        from paretocal.config import SearchSettings

        monkeypatch.setenv("COLUMNS", "200")          # each option's help on one line
        for args in (["--help"], ["calibrate", "--help"], ["check", "-h"], ["batch", "-h"]):
            assert main(args) == 0
            text = capsys.readouterr().out
            assert "<bool>" not in text, (args, text)
        assert main(["calibrate", "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        s = SearchSettings()
        assert f"Population size (default {s.pop}" in text
        assert f"Generations (default {s.gens}" in text
        # The help option keeps both its names.
        assert main(["check", "-h"]) == 0 and "--help" in capsys.readouterr().out

    def test_console_script(self, tmp_path):
        exe = shutil.which("paretocal", path=str(__import__("pathlib").Path(sys.executable).parent))
        assert exe, "console script not installed"
        r = subprocess.run([exe, "--help"], capture_output=True, text=True)
        assert r.returncode == 0 and "calibrate" in r.stdout


class TestBadInput:
    """Each exits 2 with one line on stderr that names the file or option."""

    def _bad(self, capsys, *args, expect):
        code, out, err = _run(capsys, *args)
        assert code == 2, (out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("paretocal: error:"), err
        assert expect in lines[0], lines[0]
        return lines[0]

    def test_missing_source(self, capsys, tmp_path):
        self._bad(capsys, "calibrate", tmp_path / "nope", "--out", tmp_path / "o",
                  expect="source folder not found")

    def test_missing_calibration(self, capsys, tmp_path, raw_date):
        drive = tmp_path / "2011_09_26" / "2011_09_26_drive_0001_sync"
        shutil.copytree(raw_date / "2011_09_26_drive_sample_sync", drive)
        shutil.copy(raw_date / "calib_cam_to_cam.txt", tmp_path / "2011_09_26")
        self._bad(capsys, "calibrate", drive, "--out", tmp_path / "o",
                  expect="calib_velo_to_cam.txt: calibration file not found")

    def test_corrupt_bin(self, capsys, tmp_path, raw_frames):
        root = write_generic(tmp_path / "rig", raw_frames[:1])
        p = root / "points" / f"{raw_frames[0].name}.bin"
        p.write_bytes(p.read_bytes()[:-5])
        self._bad(capsys, "calibrate", root, "--out", tmp_path / "o",
                  expect="not a multiple of 16")

    def test_images_and_points_do_not_pair(self, capsys, tmp_path, raw_frames):
        root = write_generic(tmp_path / "rig", raw_frames[:1])
        (root / "points" / f"{raw_frames[0].name}.bin").rename(root / "points" / "x.bin")
        self._bad(capsys, "calibrate", root, "--out", tmp_path / "o", expect="share no file stem")

    def test_bad_init(self, capsys, tmp_path, raw_date):
        bad = tmp_path / "init.yaml"
        bad.write_text("T_cam_lidar: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]\n")
        self._bad(capsys, "calibrate", raw_date, "--init", bad, "--out", tmp_path / "o",
                  expect="not a rotation matrix")

    def test_frames_matching_nothing(self, capsys, tmp_path, raw_date):
        self._bad(capsys, "calibrate", raw_date, "--frames", "99", "--out", tmp_path / "o",
                  expect="--frames 99")

    def test_unknown_option(self, capsys, tmp_path, raw_date):
        self._bad(capsys, "calibrate", raw_date, "--out", tmp_path / "o", "--bogus",
                  expect="--bogus")

    def test_bad_value(self, capsys, tmp_path, raw_date):
        self._bad(capsys, "calibrate", raw_date, "--out", tmp_path / "o", "--w-edge", "1.5",
                  expect="--w-edge 1.5")

    def test_unknown_config_key(self, capsys, tmp_path, raw_date):
        cfg = tmp_path / "c.yaml"
        cfg.write_text("search: {popsize: 3}\n")
        self._bad(capsys, "calibrate", raw_date, "--out", tmp_path / "o", "--config", cfg,
                  expect="popsize")


class TestCheck:
    def test_report_on_two_frames(self, tmp_path, raw_date, capsys):
        from paretocal.io import detect_source, write_extrinsic

        ref = tmp_path / "ref.yaml"
        write_extrinsic(ref, detect_source(raw_date).frames[0].T_ref)
        out = tmp_path / "check.json"
        code, stdout, err = _run(capsys, "check", raw_date, "--extrinsic", ref, "--frames", "0:2",
                                 "--out", out)
        assert code == 0, err
        assert "CALIBRATED" in stdout or "MISCALIBRATED" in stdout
        doc = json.loads(out.read_text())
        assert doc["verdict"] in ("calibrated", "miscalibrated")
        assert set(doc["quality"]["jackknife_se"]) == {"x", "y", "z", "yaw", "pitch", "roll"}
        assert doc["frames"] == ["0000000000", "0000000001"]
        # Two frames: the check says it is weak, in the JSON and on the last line.
        assert doc["weak"] and "only 2 frame(s)" in doc["notes"][0]
        assert stdout.strip().splitlines()[-1].startswith("paretocal: WEAK CHECK: only 2 frame")
        # What was compared: the features per frame as in the report, and the rings.
        mean = doc["features"]["per_frame_mean"]
        line = stdout.splitlines()[1]
        assert line.startswith(f"paretocal: features per frame: {mean['depth_edge']:g} depth "
                               f"edges, {mean['intensity_edge']:g} intensity edges, "), line
        assert "64 rings" in line and "2 of 2 frames contribute" in line
        assert "noise" not in line

    def test_without_extrinsic_the_datasets_own_is_checked(self, tmp_path, raw_date, capsys):
        from paretocal.io import detect_source

        out = tmp_path / "check.json"
        code, stdout, err = _run(capsys, "check", raw_date, "--frames", "0:2", "--out", out,
                                 "--quiet")
        assert code == 0, err
        doc = json.loads(out.read_text())
        assert doc["extrinsic_from"] == "dataset"
        np.testing.assert_array_equal(doc["T_checked"], detect_source(raw_date).frames[0].T_ref)
        assert stdout.startswith("paretocal: the dataset's own extrinsic: ")

    def test_check_takes_its_tolerance_in_metres(self, tmp_path, raw_date, capsys):
        """``--trans-tol-m`` in metres, as every length on the command line; the old
        ``--trans-tol`` (cm) still works and says it is deprecated; both at once refused."""
        docs = {}
        for name, args in (("m", ["--trans-tol-m", "0.07"]), ("cm", ["--trans-tol", "7"])):
            out = tmp_path / f"{name}.json"
            code, stdout, err = _run(capsys, "check", raw_date, "--frames", "0:2", "--out", out,
                                     "--rot-tol-deg", "0.6", *args)
            assert code == 0, err
            docs[name] = json.loads(out.read_text())
            assert "tolerances 0.6 deg / 7 cm" in stdout
            deprecated = "--trans-tol is in cm and deprecated: use --trans-tol-m 0.07"
            assert (deprecated in err) == (name == "cm"), err
        assert docs["m"]["tolerances"] == docs["cm"]["tolerances"] == {
            "rotation_deg": 0.6, "translation_cm": 7.0}
        code, _, err = _run(capsys, "check", raw_date, "--trans-tol", "7", "--trans-tol-m",
                            "0.07")
        assert code == 2 and "--trans-tol (cm, deprecated) and --trans-tol-m both given" in err

    def test_missing_extrinsic_file(self, tmp_path, raw_date, capsys):
        code, _, err = _run(capsys, "check", raw_date, "--extrinsic", tmp_path / "none.yaml")
        assert code == 2 and "none.yaml: file not found" in err


def test_the_features_line_names_frames_whose_depth_edges_look_like_noise():
    from paretocal.cli import _features_line
    from paretocal.stage import FeatureCounts

    features = {"per_frame_mean": {"depth_edge": 812.5, "intensity_edge": 90.0, "smooth": 1000.0},
                "rings": [2, 64], "ring_recovery": {"methods": ["lines"], "min_purity": 0.0},
                "frames_contributing": 2, "per_frame": [{}, {}],
                "noise": [{"frame": "000028", "reason": "2 laser rings found (a spinning LiDAR "
                                                        "has at least 8)"}]}
    line = _features_line(FeatureCounts.from_dict(features))
    assert "2/64 rings (lines, purity >= 0.00)" in line
    assert line.endswith("the depth edges of 1 frame(s) look like noise (frame 000028: 2 laser "
                         "rings found (a spinning LiDAR has at least 8))")


def test_verdict_line_names_the_main_reason_and_counts_the_rest():
    from paretocal.cli import verdict_line
    from paretocal.verdict import Reliability

    assert verdict_line(Reliability(verdict="ok", frames=20)).startswith(
        "paretocal: verdict OK")
    line = verdict_line(Reliability(verdict="unreliable", reasons=("a", "b", "c"), frames=2))
    assert line == "paretocal: verdict UNRELIABLE: a (and 2 more reasons in result.json)"


@pytest.fixture(scope="module")
def compare_run(tmp_path_factory, raw_date):
    """A short calibration from a start 2 deg / 5 cm off: its start and its result.json."""
    from paretocal.geometry import decalibrate
    from paretocal.io import detect_source, write_extrinsic

    root = tmp_path_factory.mktemp("compare")
    init = root / "init.yaml"
    write_extrinsic(init, decalibrate(detect_source(raw_date).frames[0].T_ref, 2.0, 0.05,
                                      7)[0])
    code = main(["calibrate", str(raw_date), "--init", str(init), "--out",
                 str(root / "run"), "--quiet", "--no-figures", *FAST])
    assert code == 0
    return init, root / "run" / "result.json"


class TestCompare:
    """``paretocal compare A B [SOURCE]``: the difference per axis in A's LiDAR frame, and
    which one the frames prefer; the figures are those result.json states for the same
    poses."""

    def test_start_and_result_match_the_correction(self, tmp_path, capsys, compare_run):
        init, result = compare_run
        out = tmp_path / "c.json"
        code, stdout, err = _run(capsys, "compare", init, result, "--out", out)
        assert code == 0, err
        doc, res = json.loads(out.read_text()), json.loads(result.read_text())
        for axis in ("x", "y", "z"):
            assert doc["correction"][f"{axis}_cm"] == pytest.approx(
                100 * res["correction"][axis], abs=1e-3)
        for axis in ("yaw", "pitch", "roll"):
            assert doc["correction"][f"{axis}_deg"] == pytest.approx(
                res["correction"][axis], abs=1e-4)
        assert doc["prefer"] is None and doc["preferences"] == [] and doc["pixels"] is None
        lines = stdout.strip().splitlines()
        assert len(lines) == 2 and lines[0].startswith("paretocal: B = A @ D, in A's LiDAR "
                                                       f"frame: x {doc['correction']['x_cm']:+.2f} cm")
        assert lines[1] == (f"paretocal: {doc['rotation_deg']:.3f} deg / "
                            f"{doc['translation_cm']:.2f} cm apart")

    def test_result_against_kittis_reference_on_the_frames(self, tmp_path, capsys, raw_date,
                                                           compare_run):
        _, result = compare_run
        out = tmp_path / "c.json"
        ref = raw_date / "calib_velo_to_cam.txt"          # KITTI's form: needs the source
        code, stdout, err = _run(capsys, "compare", ref, result, raw_date, "--frames", "0:3",
                                 "--out", out, "--quiet")
        assert code == 0, err
        doc, res = json.loads(out.read_text()), json.loads(result.read_text())
        e = res["reference_error"]
        for axis in ("x", "y", "z"):
            assert doc["correction"][f"{axis}_cm"] == pytest.approx(e[f"{axis}_lidar_cm"],
                                                                    abs=2e-3)
        for axis in ("yaw", "pitch", "roll"):
            assert doc["correction"][f"{axis}_deg"] == pytest.approx(e[f"{axis}_deg"], abs=2e-4)
        assert doc["rotation_deg"] == pytest.approx(e["rotation_deg"], abs=2e-4)
        assert doc["translation_cm"] == pytest.approx(e["translation_cm"], abs=2e-3)
        assert doc["frames"] == ["0000000000", "0000000001", "0000000002"]
        assert [p["view"] for p in doc["preferences"]] == ["A", "B"]
        assert all(p["frames"] == 3 for p in doc["preferences"])
        assert doc["prefer"] in ("A", "B", "neither") and doc["pixels"] > 0
        assert stdout.strip().splitlines()[-1] == (f"paretocal: on 3 frame(s) of {raw_date}: "
                                                   f"{doc['reason']}")
        # The page of both on every frame (its contents: tests/test_interactive.py).
        page = tmp_path / "compare.html"
        code, _, err = _run(capsys, "compare", ref, result, raw_date, "--frames", "0:3",
                            "--page", page, "--quiet")
        assert code == 0, err
        text = page.read_text(encoding="utf-8")
        assert 'id="paretocal-data"' in text and text.count('data-view="') == 2

    def test_a_clear_difference_is_preferred_and_a_tie_is_not(self, raw_date):
        """2 deg of yaw off the reference: every frame prefers the reference; the reference
        against itself: neither."""
        from paretocal.check import compare_extrinsics
        from paretocal.geometry import apply_correction
        from paretocal.io import load_frames

        frames = load_frames(raw_date, "0:4", 2)
        T = frames[0].T_ref
        far = compare_extrinsics(T, apply_correction(T, [0, 0, 0, 2.0, 0, 0]), frames)
        assert far.prefer == "A" and "the frames prefer A" in far.reason
        assert all(p.frames_b_better == 0 and p.p_a < 0.01 for p in far.preferences)
        assert far.rotation_deg == pytest.approx(2.0) and far.translation_m == pytest.approx(0)
        same = compare_extrinsics(T, T, frames)
        assert same.prefer == "neither" and same.pixels == pytest.approx(0.0, abs=1e-9)

    def test_bad_input_exits_2(self, tmp_path, capsys, raw_date, compare_run):
        init, _ = compare_run
        code, _, err = _run(capsys, "compare", init, tmp_path / "none.yaml")
        assert code == 2 and "none.yaml: file not found" in err
        code, _, err = _run(capsys, "compare", raw_date / "calib_velo_to_cam.txt", init)
        assert code == 2 and "pass the KITTI SOURCE it belongs to" in err
        code, _, err = _run(capsys, "compare", init, init, "--page", tmp_path / "p.html")
        assert code == 2 and "--page needs SOURCE" in err and not (tmp_path / "p.html").exists()
        assert "Traceback" not in err


def test_the_motion_line_says_what_the_motion_found():
    from paretocal.cli.check import motion_line
    from paretocal.crosscheck import MotionAgreement

    agree = MotionAgreement(True, travel_m=4.05, need_m=0.42, directions=9, residual_deg=0.62,
                            change_deg=0.52, tolerance_deg=1.5)
    assert motion_line(agree) == (
        "motion: the rotation agrees with the recording's motion (0.52 deg apart about the "
        "axes the motion observes, tolerance 1.5 deg from 9 direction(s) of travel and 0 "
        "turn(s))")
    still = MotionAgreement(False, reason="the rig barely moves: the LiDAR travels 0.03 m",
                            standing=True)
    assert motion_line(still) == ("motion: not compared: the rig barely moves: the LiDAR "
                                  "travels 0.03 m")
