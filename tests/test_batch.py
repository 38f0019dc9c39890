"""Fleet batches on a local Dask cluster (worker processes on loopback): a broken entry is
recorded and does not stop the others; a rerun skips what is done."""

from __future__ import annotations

import csv
import json

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from paretocal import Settings
from paretocal.batch import read_manifest, run_batch
from paretocal.cli import main
from paretocal.errors import InputError
from paretocal.geometry import correction_matrix
from paretocal.io import write_extrinsic

TINY = Settings().replace(search={"pop": 16, "gens": 3}, decision={"refine": False})


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


def test_batch_records_failures_and_resumes(manifest, tmp_path):
    out = tmp_path / "batch"
    r = run_batch(manifest, out, TINY, workers=2, check=True)
    assert (r["entries"], r["ran"], r["ok"], r["failed"], r["skipped"]) == (3, 3, 2, 1, 0)
    with open(out / "summary.csv") as fh:
        rows = {row["id"]: row for row in csv.DictReader(fh)}
    assert rows["car2_broken"]["status"] == "failed"
    assert "does/not/exist" in rows["car2_broken"]["reason"]
    for eid in ("car1_a", "car1_b"):
        row = rows[eid]
        assert row["status"] == "ok" and row["vehicle"] == "car1"
        assert (out / "runs" / eid / "result.json").exists()
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
