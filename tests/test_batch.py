"""Fleet batches on a local Dask cluster (worker processes on loopback): a broken entry is
recorded and does not stop the others; a rerun skips what is done."""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from paretocal import Settings
from paretocal.apps.batch import Entry, entry_fingerprint, is_done, read_manifest, run_batch
from paretocal.cli import main
from paretocal.errors import InputError
from paretocal.geometry import correction_matrix
from paretocal.io import write_extrinsic

TINY = Settings().replace(search={"pop": 16, "gens": 3}, decision={"polish": False})


@pytest.fixture(scope="module")
def manifest(tmp_path_factory, raw_date, raw_frames):
    root = tmp_path_factory.mktemp("fleet")
    T = raw_frames[0].T_ref @ correction_matrix(np.array([0.04, -0.02, 0.03, 1.0, -0.8, 0.6]))
    write_extrinsic(root / "nominal.yaml", T)
    doc = {"entries": [
        {"id": "car1_a", "source": str(raw_date), "frames": "0:2", "init": "nominal.yaml",
         "vehicle": "car1", "order": 1},
        {"id": "car1_b", "source": str(raw_date), "frames": "2:4", "init": "nominal.yaml",
         "vehicle": "car1", "order": 2},
        {"id": "car2_broken", "source": "does/not/exist", "vehicle": "car2", "order": 1},
    ]}
    path = root / "fleet.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.fixture(scope="module")
def first_run(manifest, tmp_path_factory):
    """The manifest's batch, run once: (out, result, the log records of ``paretocal``)."""
    out = tmp_path_factory.mktemp("batch") / "out"
    records = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = records.append
    logger = logging.getLogger("paretocal")
    logger.addHandler(handler)
    try:
        r = run_batch(manifest, out, TINY, workers=2, check=True)
    finally:
        logger.removeHandler(handler)
    return out, r, records


def test_batch_records_failures_and_resumes(manifest, first_run):
    out, r, _ = first_run
    assert (r["entries"], r["ran"], r["ok"], r["failed"], r["skipped"]) == (3, 3, 2, 1, 0)
    with open(out / "summary.csv") as fh:
        rows = {row["id"]: row for row in csv.DictReader(fh)}
    assert rows["car2_broken"]["status"] == "failed"
    assert "does/not/exist" in rows["car2_broken"]["reason"]
    for eid in ("car1_a", "car1_b"):
        row = rows[eid]
        assert row["status"] == "ok" and row["vehicle"] == "car1"
        assert (out / "runs" / eid / "result.json").exists()
        # Published as a run folder: staged, with the list of what it wrote.
        assert not (out / "runs" / eid / ".staging").exists()
        assert {"result.json", "run_args.json"} <= set(
            (out / "runs" / eid / ".outputs").read_text().split())
        # ... with the run's arguments, as calibrate --resume reads them.
        from paretocal.rundir import run_arguments

        args = run_arguments(out / "runs" / eid)
        assert args["settings"].frames == row["frames"] and args["T_init"] is not None
        assert float(row["drift_rotation_deg"]) > 0.1          # the start was 1.5 deg off
        assert row["check_verdict"] in ("calibrated", "miscalibrated")
        assert float(row["ref_rotation_deg"]) >= 0
        # The run's own verdict, as in its result.json.
        doc = json.loads((out / "runs" / eid / "result.json").read_text())
        assert row["reliability"] == doc["reliability"]["verdict"]
        assert row["reliability_reason"] == "; ".join(doc["reliability"]["reasons"])
    # Different worker processes ran the two good entries (2 workers, 1 task each at a time,
    # unless one finished before the other started); at least the records name a worker.
    assert all(rows[e]["worker"] for e in rows)
    table = pq.read_table(out / "summary.parquet").to_pydict()
    assert table["id"] == sorted(rows) and table["status"].count("ok") == 2
    assert (out / "fleet.png").stat().st_size > 10_000

    stamp = (out / "runs" / "car1_a" / "result.json").stat().st_mtime_ns
    again = run_batch(manifest, out, TINY, workers=1, check=True)
    assert (again["skipped"], again["ran"], again["ok"], again["failed"]) == (2, 1, 2, 1)
    assert (out / "runs" / "car1_a" / "result.json").stat().st_mtime_ns == stamp


def test_worker_warnings_name_their_entry(first_run):
    """Two frames per entry: each run warns that it may be unreliable, in its worker; the
    driver logs it with the entry's id, and each failure likewise."""
    out, _, records = first_run
    messages = [rec.getMessage() for rec in records]
    for eid in ("car1_a", "car1_b"):
        assert any(m.startswith(f"[{eid}] the result may be unreliable: only 2 frame(s)")
                   for m in messages), messages
        record = json.loads((out / "runs" / eid / "entry.json").read_text())
        assert any("only 2 frame(s)" in m for _, m in record["log"])
    assert any(m.startswith("[car2_broken] failed: ") and "does/not/exist" in m
               for m in messages)
    assert not any(m.startswith("the result may be unreliable") for m in messages)


def test_edited_entries_are_calibrated_again(manifest, first_run, raw_date, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(first_run[0], out)
    doc = yaml.safe_load(manifest.read_text())
    a, b, _ = doc["entries"]
    a["frames"] = "1:3"                                        # other frames
    b["source"] = str(raw_date / "2011_09_26_drive_sample_sync")   # the same data, named anew
    edited = manifest.parent / "edited.yaml"                  # beside it: same nominal.yaml
    edited.write_text(yaml.safe_dump({"entries": [a, b]}))
    r = run_batch(edited, out, TINY, workers=1, check=True)
    assert (r["ran"], r["skipped"], r["ok"]) == (2, 0, 2)
    with open(out / "summary.csv") as fh:
        rows = {row["id"]: row for row in csv.DictReader(fh)}
    assert rows["car1_a"]["frames"] == "1:3"
    assert rows["car1_b"]["source"] == b["source"]
    assert json.loads((out / "runs" / "car1_a" / "result.json").read_text())["frames"] == \
        ["0000000001", "0000000002"]
    # Unchanged: done, and no cluster is started for nothing.
    again = run_batch(edited, out, TINY, workers=1, check=True)
    assert (again["ran"], again["skipped"], again["entries_per_minute"]) == (0, 2, None)
    # The same from the command line (TINY as a config file): every entry ok, exit 0.
    assert main(["batch", str(edited), "--out", str(out), "--config", str(tiny_config(tmp_path))]) == 0
    assert "2 ok, 0 failed, 2 already done" in capsys.readouterr().out


def test_an_edited_record_is_not_taken_for_a_done_entry(manifest, first_run, tmp_path):
    """runs/<id>/entry.json edited (its extrinsic changed, its fingerprint kept), or its
    result.json deleted: the entry was counted done and the forged extrinsic went into
    summary.csv. A record is done only as written for the run published beside it."""
    from paretocal.apps.batch import RECORD, read_record

    out = tmp_path / "out"
    shutil.copytree(first_run[0], out)
    forged = np.eye(4).tolist()
    for eid, edit in (("car1_a", "record"), ("car1_b", "result")):
        run = out / "runs" / eid
        assert read_record(run) is not None                   # as written: done
        if edit == "record":
            text = json.dumps(dict(json.loads((run / RECORD).read_text()), T_cam_lidar=forged))
            (run / RECORD).write_text(text)
        else:
            (run / "result.json").unlink()
        assert read_record(run) is None
    (out / "runs" / "car1_b" / "result.json").write_bytes(
        (first_run[0] / "runs" / "car1_b" / "result.json").read_bytes())   # car1_b done again
    r = run_batch(manifest, out, TINY, workers=1, check=True)
    assert (r["ran"], r["skipped"], r["ok"]) == (2, 1, 2)
    with open(out / "summary.csv") as fh:
        row = {row["id"]: row for row in csv.DictReader(fh)}["car1_a"]
    T = json.loads((out / "runs" / "car1_a" / "result.json").read_text())["T_cam_lidar"]
    assert float(row["T_00"]) == T[0][0] != 1.0


def tiny_config(folder):
    path = folder / "tiny.yaml"
    path.write_text(yaml.safe_dump({"search": {"pop": 16, "gens": 3},
                                    "decision": {"polish": False}}))
    return path


def test_cli_exits_4_when_an_entry_failed(manifest, first_run, tmp_path, capsys):
    """Another --seed calibrates every entry again; the broken one fails: exit 4, the last
    line says how many failed and where the summary is, worker warnings name their entry."""
    out = tmp_path / "out"
    shutil.copytree(first_run[0], out)
    rc = main(["batch", str(manifest), "--out", str(out), "--config",
               str(tiny_config(tmp_path)), "--seed", "1", "--no-check"])
    captured = capsys.readouterr()
    assert rc == 4
    assert "3 entries: 2 ok, 1 failed, 0 already done" in captured.out
    err = captured.err.splitlines()
    assert err[-1] == f"paretocal: 1 of 3 entries failed; the reasons are in {out / 'summary.csv'}"
    assert any(line.startswith("paretocal: WARNING: [car1_a] the result may be unreliable")
               for line in err)
    assert any(line.startswith("paretocal: WARNING: [car2_broken] failed: ") for line in err)
    # --no-check is part of what the entry was run with: the old check's verdict is gone.
    assert "check_verdict" not in json.loads((out / "runs" / "car1_a" / "entry.json").read_text())
    with open(out / "summary.csv") as fh:
        assert {row["id"]: row["status"] for row in csv.DictReader(fh)} == \
            {"car1_a": "ok", "car1_b": "ok", "car2_broken": "failed"}


def test_interrupted_batch_stops_quietly_and_says_how_far_it_got(raw_date, tmp_path, capfd,
                                                                   monkeypatch):
    """SIGTERM once the first entry is in, while the second is calibrating: the cluster is
    shut down without a word from Dask, the summary holds what is done, one line says so,
    exit 130."""
    import os
    import signal

    from paretocal import cli

    def terminate(self, stage, done, total):
        os.kill(os.getpid(), signal.SIGTERM)       # cli.main turns it into KeyboardInterrupt

    monkeypatch.setattr(cli._Progress, "__call__", terminate)
    tmp = _own_tmpdir(tmp_path, monkeypatch)
    manifest = tmp_path / "m.yaml"                # one worker runs them in this order
    manifest.write_text(yaml.safe_dump([{"id": "broken", "source": "does/not/exist"},
                                        {"id": "long", "source": str(raw_date)}]))
    config = tmp_path / "long.yaml"               # far longer than the test waits
    config.write_text(yaml.safe_dump({"search": {"pop": 400, "gens": 200}}))
    # Dask logs in this process through its own handler (bound to the stderr of its import,
    # which capfd does not see): collect those records here.
    dask_records = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = dask_records.append
    logging.getLogger("distributed").addHandler(handler)
    out = tmp_path / "out"
    try:
        rc = main(["batch", str(manifest), "--out", str(out), "--config", str(config),
                   "--no-check", "--quiet"])
    finally:
        logging.getLogger("distributed").removeHandler(handler)
    captured = capfd.readouterr()                 # the worker processes' stderr too
    assert rc == 130
    assert [r.getMessage() for r in dask_records] == []
    assert captured.out == ""
    assert captured.err == (f"paretocal: batch interrupted: 0 of 2 entries done (summary so "
                            f"far in {out / 'summary.csv'}); rerun the same command to "
                            "continue\n")
    with open(out / "summary.csv") as fh:
        assert [(row["id"], row["status"]) for row in csv.DictReader(fh)] == \
            [("broken", "failed")]
    assert not (out / "runs" / "long" / "entry.json").exists()
    # Dask's scratch of the stopped workers (a worker-*.dirlock) was left in $TMPDIR.
    assert not list(tmp.iterdir())
    assert sorted(p.name for p in out.iterdir()) == ["runs", "summary.csv", "summary.parquet"]


def _own_tmpdir(tmp_path, monkeypatch):
    """A $TMPDIR of the test's own (for this process and the workers it starts)."""
    import tempfile

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", None)
    return tmp


def test_the_workers_scratch_stays_in_the_batch_folder_and_goes(tmp_path, monkeypatch):
    """The local cluster's workers kept their scratch in $TMPDIR/dask-scratch-space, outside
    --out; it is a folder of the batch's own now, removed when the cluster stops."""
    tmp = _own_tmpdir(tmp_path, monkeypatch)
    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump([{"id": "broken", "source": "does/not/exist"}]))
    out = tmp_path / "out"
    r = run_batch(manifest, out, TINY, workers=1)
    assert (r["ran"], r["failed"]) == (1, 1)
    assert not list(tmp.iterdir())
    assert sorted(p.name for p in out.iterdir()) == ["fleet.png", "runs", "summary.csv",
                                                      "summary.parquet"]


def test_a_busy_port_8787_does_not_stop_the_local_cluster(tmp_path):
    """Dask's scheduler serves HTTP on port 8787 by default, dashboard or not: with the port
    taken (another Dask on the machine) it warned "Port 8787 is already in use" (an error
    under the tests' warning filter: the cluster failed to start). It takes a free port."""
    import socket

    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump([{"id": "broken", "source": "does/not/exist"}]))
    with socket.socket() as busy:
        try:
            busy.bind(("", 8787))
            busy.listen()
        except OSError:
            pass                                  # taken already: the case itself
        r = run_batch(manifest, tmp_path / "out", TINY, workers=1)
    assert (r["ran"], r["failed"]) == (1, 1)


def test_fingerprint_covers_settings_entry_and_init_file(manifest):
    (e, _, _) = read_manifest(manifest)
    base = entry_fingerprint(e, TINY.to_dict())
    assert entry_fingerprint(e, TINY.to_dict()) == base
    record = {"status": "ok", "fingerprint": base}
    assert is_done(record, base)
    assert not is_done({**record, "status": "failed"}, base)
    assert not is_done({"status": "ok"}, base)                # a record from before fingerprints
    for change in ({"gens": 4}, {"seed": 1}, {"pop": 20}):
        assert not is_done(record, entry_fingerprint(e, TINY.replace(search=change).to_dict()))
    assert entry_fingerprint(e, TINY.to_dict(), check=False) != base
    assert entry_fingerprint(e, TINY.to_dict(), figures=True) != base
    assert entry_fingerprint(dataclasses.replace(e, camera=3), TINY.to_dict()) != base


def test_an_edited_init_file_changes_the_fingerprint(tmp_path):
    init = tmp_path / "nominal.yaml"
    write_extrinsic(init, np.eye(4))
    e = Entry(id="a", source=str(tmp_path), init=str(init))
    before = entry_fingerprint(e, TINY.to_dict())
    T = np.eye(4)
    T[0, 3] = 0.1
    write_extrinsic(init, T)
    assert entry_fingerprint(e, TINY.to_dict()) != before


def test_manifest_errors_name_the_entry(tmp_path):
    bad = tmp_path / "m.yaml"
    bad.write_text(yaml.safe_dump({"entries": [{"id": "a", "source": "x"},
                                               {"id": "a", "source": "y"}]}))
    with pytest.raises(InputError, match="entry 2: duplicate id"):
        read_manifest(bad)
    bad.write_text(yaml.safe_dump([{"id": "../up", "source": "x"}]))
    with pytest.raises(InputError, match="entry 1: id"):
        read_manifest(bad)
    bad.write_text(yaml.safe_dump([{"id": "a", "sauce": "x"}]))
    with pytest.raises(InputError, match="unknown field"):
        read_manifest(bad)
    csv_path = tmp_path / "m.csv"
    csv_path.write_text("id,source,frames\nd1,data/x,0:5\n")
    (e,) = read_manifest(csv_path)
    assert e.frames == "0:5" and e.source == str((tmp_path / "data" / "x").resolve())


def test_cli_bad_manifest_exits_2(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o")]) == 2
    assert "manifest not found" in capsys.readouterr().err


BAD_MANIFESTS = {
    # name: (file name, content, the message after "<manifest>: ")
    "binary yaml": ("m.yaml", b"\x00\xff\xfe\x01entries", "NUL byte at offset 0"),
    "NUL in csv": ("m.csv", b"id,source\nd1,da\x00ta\n", "NUL byte at offset 15"),
    "not utf-8": ("m.csv", b"id,source\nd\xe9,x\n", "not UTF-8 text (byte 0xe9 at offset 11)"),
    "camera list": ("m.yaml", b"- {id: a, source: x, camera: [1]}\n",
                    "entry 1: camera [1] is not an integer"),
    "camera float": ("m.yaml", b"- {id: a, source: x, camera: 2.5}\n",
                     "entry 1: camera 2.5 is not an integer"),
    "camera bool": ("m.yaml", b"- {id: a, source: x, camera: true}\n",
                    "entry 1: camera True is not an integer"),
    "camera csv": ("m.csv", b"id,source,camera\na,x,two\n", "entry 1: camera 'two' is not"),
    "camera superscript": ("m.csv", "id,source,camera\na,x,\u00b2\n".encode(),
                           "entry 1: camera '\u00b2' is not an integer"),
    "id number": ("m.yaml", b"- {id: 0005, source: x}\n",
                  "entry 1: id 5 must be text; quote it (id: \"0005\")"),
    "id list": ("m.yaml", b"- {id: [a], source: x}\n", "entry 1: id ['a'] must be text"),
    "frames sexagesimal": ("m.yaml", b"- {id: a, source: x, frames: 2:4}\n",
                           "entry 1: frames 124 must be text; quote it (frames: \"2:4\")"),
    "frames mapping": ("m.yaml", b"- {id: a, source: x, frames: {a: 1}}\n",
                       "entry 1: frames {'a': 1} must be text"),
    "source list": ("m.yaml", b"- {id: a, source: [x, y]}\n",
                    "entry 1: source ['x', 'y'] must be text"),
    "source NUL": ("m.yaml", b'- {id: a, source: "x\\0"}\n', "entry 1: source contains a NUL"),
    "source missing": ("m.yaml", b"entries:\n  - {id: a}\n", "entry 1: missing 'source'"),
    "init mapping": ("m.yaml", b"- {id: a, source: x, init: {T: 1}}\n",
                     "entry 1: init {'T': 1} must be text"),
    "vehicle list": ("m.yaml", b"- {id: a, source: x, vehicle: [1]}\n",
                     "entry 1: vehicle [1] must be text or a number"),
    "field name number": ("m.yaml", b"- {id: a, source: x, 7: y}\n",
                          "entry 1: field name 7 is not text"),
    "entry not a mapping": ("m.yaml", b"- just a string\n", "entry 1: expected a mapping"),
    "entries not a list": ("m.yaml", b"entries: 5\n", "expected a list of entries"),
    "csv row too long": ("m.csv", b"id,source\na,x,extra\n",
                         "line 2: 2 columns in the header, more values in this row"),
    "csv header only": ("m.csv", b"id,source\n", "the manifest lists no entries"),
    "id with a line break": ("m.yaml", b'- {id: "a\\n", source: x}\n',
                             "entry 1: id 'a\\n' must be letters, digits, '_', '-' or '.'"),
    "nested 100,000 deep": ("m.yaml", b"[" * 100_000 + b"]" * 100_000,
                            "its values are nested too deeply to be read"),
}


@pytest.mark.parametrize("case", BAD_MANIFESTS)
def test_bad_manifest_exits_2_naming_it(case, tmp_path, capsys):
    name, content, message = BAD_MANIFESTS[case]
    path = tmp_path / name
    path.write_bytes(content)
    assert main(["batch", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"paretocal: error: {path}: {message}") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_manifest_that_is_a_folder(tmp_path, capsys):
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert f"{tmp_path}: is a folder; expected a YAML or CSV manifest" in capsys.readouterr().err


def test_manifest_accepts_numbers_where_numbers_are_meant(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_bytes(b"- {id: a, source: x, vehicle: 7, order: 2, camera: '3'}\n")
    (e,) = read_manifest(path)
    assert (e.vehicle, e.order, e.camera) == ("7", "2", 3)
    csv_path = tmp_path / "m.csv"
    csv_path.write_bytes(b"\xef\xbb\xbfid,source,camera\nd1,x,3\n")    # a spreadsheet's BOM
    (e,) = read_manifest(csv_path)
    assert (e.id, e.camera) == ("d1", 3)


def test_batch_without_the_fleet_extra_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    import importlib.util

    from paretocal.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "distributed" else real(name, *a))
    manifest = tmp_path / "m.yaml"
    manifest.write_text("entries: []\n")
    assert main(["batch", str(manifest), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["paretocal: error: paretocal batch needs distributed: install the fleet "
                   "extra, pip install 'paretocal[fleet]'"]


def test_an_entry_record_nested_too_deeply_is_no_record(tmp_path):
    """A runs/<id>/entry.json nested 100,000 deep (RecursionError, which aborted the whole
    batch) reads as no record: the entry is calibrated again."""
    from paretocal.apps.batch import RECORD, read_record

    (tmp_path / RECORD).write_text("[" * 100_000 + "]" * 100_000)
    assert read_record(tmp_path) is None
