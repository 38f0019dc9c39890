"""A dataset's own init_error (calib.yaml) is applied alike by every path that calibrates a
folder: the library's calibrate, calibrate_run (and its resume), batch and the command line;
settings the user gave win."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from paretocal import Settings, calibrate, calibrate_run, load_frames, resume_run
from paretocal.config import dataset_settings, states_init_error
from paretocal.io import source_options

from .helpers import run_cli, write_generic

STATED = (2.0, 0.05)                   #: the folder's calib.yaml init_error (deg, m)
DEFAULT = (10.0, 0.3)
#: A tiny run: a few seconds per calibration.
TINY = Settings().replace(keep_none=True,
                          search={"pop": 12, "gens": 2, "seed_grid_deg": None},
                          decision={"polish": False, "restarts": 0})
CLI_TINY = ["--pop", "12", "--gens", "2", "--no-polish", "--no-figures", "--quiet"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory, raw_frames):
    """A generic folder of one KITTI frame whose calib.yaml states ``init_error: [2, 0.05]``."""
    root = write_generic(tmp_path_factory.mktemp("stated") / "g", raw_frames[:1])
    calib = yaml.safe_load((root / "calib.yaml").read_text())
    calib["init_error"] = list(STATED)
    (root / "calib.yaml").write_text(yaml.safe_dump(calib))
    return root


def _used(settings) -> tuple[float, float]:
    """``(init_error_deg, init_error_m)`` of a Settings or of result.json's config."""
    s = settings["search"] if isinstance(settings, dict) else settings.search.__dict__
    return s["init_error_deg"], s["init_error_m"]


def test_the_rule(folder, tmp_path):
    options = source_options(folder)
    assert options == {"init_error": STATED}
    assert _used(dataset_settings(None, options)) == STATED
    assert _used(dataset_settings(TINY, options)) == STATED
    assert dataset_settings(TINY, options).search.pop == 12      # the rest as given
    # Changed from the default on either axis: the settings' own, both axes.
    mine = TINY.replace(search={"init_error_m": 0.2})
    assert _used(dataset_settings(mine, options)) == (10.0, 0.2)
    assert _used(dataset_settings(TINY, options, adopt=False)) == DEFAULT
    assert _used(dataset_settings(TINY, {})) == DEFAULT
    # A config file that names init_error set it, even to the default values.
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"search": {"init_error_deg": 10.0}}))
    assert states_init_error(config)
    config.write_text(yaml.safe_dump({"search": {"pop": 12}}))
    assert not states_init_error(config) and not states_init_error(None)


def test_library_calibrate_of_a_folder(folder, raw_frames):
    assert _used(calibrate(folder, settings=TINY).settings) == STATED
    mine = TINY.replace(search={"init_error_deg": 5.0, "init_error_m": 0.2})
    assert _used(calibrate(folder, settings=mine).settings) == (5.0, 0.2)
    # Frames loaded from the folder carry what it states: calibrating them is calibrating it.
    loaded = load_frames(folder)
    assert source_options(loaded) == {"init_error": STATED}
    assert _used(calibrate(loaded, settings=TINY).settings) == STATED
    assert _used(calibrate(loaded, settings=mine).settings) == (5.0, 0.2)
    assert _used(calibrate(loaded, settings=TINY, dataset_options=False).settings) == DEFAULT
    # KITTI states nothing: the settings as given.
    assert source_options(raw_frames[:1]) == {}
    assert _used(calibrate(raw_frames[:1], settings=TINY).settings) == DEFAULT


def test_the_library_on_loaded_frames_is_the_command_line(folder, tmp_path, capfd):
    """README's snippet, ``calibrate(load_frames(folder))``, and ``paretocal calibrate
    folder`` with the same settings and seed give the same result (issue 45: the snippet
    searched a 10 deg / 0.3 m box where the command line searched calib.yaml's 5 deg /
    0.2 m, and ended elsewhere)."""
    settings = Settings().replace(search={"pop": 12, "gens": 2}, decision={"polish": False})
    result = calibrate(load_frames(folder), settings=settings)
    code, _, err = run_cli(capfd, "calibrate", folder, "--out", tmp_path / "a", *CLI_TINY)
    assert code == 0, err
    doc = json.loads((tmp_path / "a" / "result.json").read_text())
    assert doc["config"] == json.loads(json.dumps(result.settings.to_dict()))
    assert _used(doc["config"]) == STATED
    np.testing.assert_array_equal(np.array(doc["T_cam_lidar"]), result.T_cam_lidar)
    assert doc["n_points"] == result.n_points
    assert doc["reliability"]["verdict"] == result.reliability.verdict


def test_calibrate_run_records_what_it_used_and_resumes_with_it(folder, tmp_path):
    from paretocal.rundir import run_arguments

    calibrate_run(folder, tmp_path / "a", settings=TINY, figures=False)
    assert _used(json.loads((tmp_path / "a" / "result.json").read_text())["config"]) == STATED
    assert _used(run_arguments(tmp_path / "a")["settings"]) == STATED
    # The user's default values, stated: recorded as such, and a resume does not take the
    # dataset's in their place (the same run again, bit for bit).
    first = calibrate_run(folder, tmp_path / "b", settings=TINY, figures=False,
                          dataset_options=False)
    assert _used(run_arguments(tmp_path / "b")["settings"]) == DEFAULT
    again = resume_run(tmp_path / "b")
    assert _used(again.settings) == DEFAULT
    np.testing.assert_array_equal(again.T_cam_lidar, first.T_cam_lidar)
    np.testing.assert_array_equal(again.front.F, first.front.F)


def test_batch(folder, tmp_path):
    pytest.importorskip("distributed")
    from paretocal.apps.batch import Entry, entry_fingerprint, entry_settings, run_batch

    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump({"entries": [{"id": "e", "source": str(folder)}]}))
    r = run_batch(manifest, tmp_path / "out", TINY, workers=1, check=False)
    assert r["ok"] == 1, r["records"]
    doc = json.loads((tmp_path / "out" / "runs" / "e" / "result.json").read_text())
    assert _used(doc["config"]) == STATED
    # Explicit settings win; the fingerprint covers the settings each entry runs with.
    entry = Entry("e", str(folder))
    mine = TINY.replace(search={"init_error_deg": 5.0})
    assert _used(entry_settings(entry, mine)) == (5.0, 0.3)
    assert _used(entry_settings(entry, TINY, dataset_options=False)) == DEFAULT
    assert (entry_fingerprint(entry, entry_settings(entry, TINY))
            != entry_fingerprint(entry, entry_settings(entry, TINY, dataset_options=False)))
    # An unreadable source adds nothing (the entry fails on it when it runs).
    assert _used(entry_settings(Entry("x", str(tmp_path / "missing")), TINY)) == DEFAULT


def test_command_line(folder, tmp_path, capfd):
    code, _, err = run_cli(capfd, "calibrate", folder, "--out", tmp_path / "a", *CLI_TINY)
    assert code == 0, err
    doc = json.loads((tmp_path / "a" / "result.json").read_text())
    assert _used(doc["config"]) == STATED
    # --init-error wins, also at the default values; so does a config file that names it.
    code, _, err = run_cli(capfd, "calibrate", folder, "--out", tmp_path / "b", *CLI_TINY,
                           "--init-error", "10,0.3")
    assert code == 0, err
    assert _used(json.loads((tmp_path / "b" / "result.json").read_text())["config"]) == DEFAULT
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"search": {"init_error_deg": 4.0}}))
    code, _, err = run_cli(capfd, "calibrate", folder, "--out", tmp_path / "c", *CLI_TINY,
                           "--config", config)
    assert code == 0, err
    assert _used(json.loads((tmp_path / "c" / "result.json").read_text())["config"]) == (4.0, 0.3)


def test_command_line_batch_passes_a_config_files_init_error(folder, tmp_path, capfd,
                                                               monkeypatch):
    import paretocal.apps.batch

    seen = []

    def fake(*args, dataset_options=True, **kw):
        seen.append(dataset_options)
        return {"entries": 0, "ok": 0, "failed": 0, "skipped": 0, "entries_per_minute": None}

    monkeypatch.setattr(paretocal.apps.batch, "run_batch", fake)
    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump({"entries": [{"id": "e", "source": str(folder)}]}))
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"search": {"init_error_m": 0.3}}))
    assert run_cli(capfd, "batch", manifest, "--out", tmp_path / "o1")[0] == 0
    assert run_cli(capfd, "batch", manifest, "--out", tmp_path / "o2", "--config", config)[0] == 0
    assert seen == [True, False]


@pytest.mark.parametrize("text, pair", [
    ("5,0.2", (5.0, 0.2)), (" 20 , 1.5 ", (20.0, 1.5)), ([3, 0.1], (3.0, 0.1)),
    ("5", None), ("5,0", None), ("-1,0.2", None), ("nan,0.2", None), ("a,b", None),
    ("1,2,3", None),
])
def test_the_stated_error_is_read_alike_from_the_option_and_calib_yaml(tmp_path, text, pair):
    """``--init-error`` and calib.yaml's ``init_error`` accept the same pairs (two finite
    positive numbers) and refuse the same, each naming its own option or file."""
    from paretocal.config import parse_init_error
    from paretocal.errors import InputError, SettingsError

    items = text if isinstance(text, list) else [v for v in text.split(",")]
    root = tmp_path / "rig"
    root.mkdir()
    (root / "calib.yaml").write_text(yaml.safe_dump({"init_error": items}))
    if pair is None:
        with pytest.raises(SettingsError, match=r"--init-error .*expected DEG,M, two positive"):
            parse_init_error(text, "--init-error")
        with pytest.raises(InputError, match=r"calib.yaml: init_error must be \[DEG, M\]"):
            source_options(root)
    else:
        assert parse_init_error(text, "--init-error") == pair
        assert source_options(root)["init_error"] == pair
    assert parse_init_error(None, "--init-error") == (None, None)
