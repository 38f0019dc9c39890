"""Atomic output: a reader never sees a half-written file, and a failed write keeps the old one."""

from __future__ import annotations

import errno
import os
import threading

import pytest

from paretocal.errors import InputError
from paretocal.io.atomic import atomic_path, atomic_write_text


def test_failed_write_keeps_the_previous_file_and_no_temporary(tmp_path):
    target = tmp_path / "result.json"
    atomic_write_text(target, "old\n")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("new but incomplete")
            raise RuntimeError("disk full")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]


def test_concurrent_reader_sees_only_whole_versions(tmp_path):
    target = tmp_path / "pareto.csv"
    versions = [f"{k}\n" * 200_000 for k in range(8)]      # 400 kB each, distinct
    atomic_write_text(target, versions[0])
    seen, stop = set(), threading.Event()

    def reader():
        while not stop.is_set():
            text = target.read_text()
            seen.add(text[:2] if text in versions else "TORN")

    t = threading.Thread(target=reader)
    t.start()
    try:
        for _ in range(5):
            for v in versions:
                atomic_write_text(target, v)
    finally:
        stop.set()
        t.join()
    assert "TORN" not in seen and len(seen) >= 2


def test_write_run_failure_leaves_previous_run_whole(tmp_path, monkeypatch, raw_frames):
    import json

    import numpy as np

    from paretocal import Settings, calibrate
    from paretocal.geometry import correction_matrix
    from paretocal.report import results

    T = raw_frames[0].T_ref @ correction_matrix(np.array([0.02, 0, 0, 0.5, 0, 0]))
    r = calibrate(raw_frames[:1], T, Settings().replace(search={"pop": 12, "gens": 2},
                                                         decision={"polish": False}))
    out = tmp_path / "run"
    results.write_outputs(r, out, raw_frames[:1], figures=False)
    before = (out / "result.json").read_text()

    def broken(*a, **k):
        raise OSError("no space left on device")

    monkeypatch.setattr(results, "write_extrinsic", broken)
    r.wall_s += 1.0                        # the new result.json differs from the old one
    with pytest.raises(OSError):
        results.write_outputs(r, out, raw_frames[:1], figures=False)
    # result.json was replaced whole (new) or not at all; nothing half-written anywhere.
    text = (out / "result.json").read_text()
    assert text == before or json.loads(text)["wall_s"] == pytest.approx(r.wall_s, abs=1e-3)
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES])
def test_a_write_the_user_can_fix_names_the_file(tmp_path, code):
    target = tmp_path / "sub" / "result.json"
    with pytest.raises(InputError) as err:
        with atomic_path(target) as tmp:
            tmp.write_text("partial")
            raise OSError(code, os.strerror(code))
    assert str(err.value) == f"{target}: cannot write ({os.strerror(code)})"
    assert not target.exists() and list(target.parent.iterdir()) == []    # no temporary left


def test_other_os_errors_stay_bugs(tmp_path):
    with pytest.raises(OSError) as err:
        with atomic_path(tmp_path / "x.csv"):
            raise OSError(errno.EIO, os.strerror(errno.EIO))
    assert not isinstance(err.value, InputError) and err.value.errno == errno.EIO


def test_write_run_into_a_used_folder_replaces_the_run_whole(tmp_path, raw_date, raw_frames,
                                                             capfd):
    """``paretocal.write_run`` into a folder a command-line run wrote replaces that run whole
    (issue 45: its run_args.json and .outputs stayed beside the new result, two runs mixed);
    a folder of other files is refused as ``--out`` refuses it, unless ``force``."""
    import json

    from paretocal import Settings, calibrate, write_run
    from paretocal.errors import SettingsError

    from .helpers import run_cli

    out = tmp_path / "run"
    code, _, err = run_cli(capfd, "calibrate", raw_date, "--frames", "0:1", "--pop", 12,
                           "--gens", 2, "--no-polish", "--no-figures", "--quiet", "--out", out)
    assert code == 0, err
    assert (out / "run_args.json").exists()
    r = calibrate(raw_frames[:1], settings=Settings().replace(
        search={"pop": 12, "gens": 2, "seed": 5}, decision={"polish": False}))
    written = write_run(r, out, raw_frames[:1], figures=False)
    assert json.loads((out / "result.json").read_text())["seed"] == 5
    assert not (out / "run_args.json").exists()           # the command line's run is gone
    listed = (out / ".outputs").read_text().split()
    assert sorted(listed) == sorted(p.name for p in written)
    assert {p.name for p in out.iterdir()} == set(listed) | {".outputs"}
    # A folder of the user's own files: refused, naming how to write there all the same.
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    with pytest.raises(SettingsError, match=r"not a paretocal run folder .* pass force=True"):
        write_run(r, mine, figures=False)
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    write_run(r, mine, figures=False, force=True)
    assert (mine / "notes.txt").exists() and (mine / "result.json").exists()
