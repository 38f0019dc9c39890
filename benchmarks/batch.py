"""Batch throughput on a local Dask cluster: 1 worker (2 kernel threads) against 2 workers
(1 thread each), on the bundled drive, and what a fleet of 10,000 drives would need.

Entries are 5-frame slices of the sample drive from different decalibrated starts (4 slices x
2 starts), calibrated with the default settings and checked; each configuration writes its own
batch directory, so nothing is skipped.

    .venv/bin/python benchmarks/batch.py [--entries 8] [--pop 300 --gens 120]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from paretocal import Settings
from paretocal.apps.batch import run_batch
from paretocal.geometry import decalibrate
from paretocal.io import detect_source, write_extrinsic

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DATE = DATA / "kitti_raw" / "2011_09_26"


def manifest(root: Path, n: int) -> Path:
    T_ref = detect_source(DATE).frames[0].T_ref
    entries = []
    for k in range(n):
        init = root / f"init_{k}.yaml"
        write_extrinsic(init, decalibrate(T_ref, 3.0, 0.1, 2000 + k)[0])
        a = 5 * (k % 4)
        entries.append({"id": f"e{k:02d}", "source": str(DATE), "frames": f"{a}:{a + 5}",
                        "init": str(init), "vehicle": f"car{k // 4}", "order": k % 4})
    path = root / "manifest.yaml"
    path.write_text(yaml.safe_dump({"entries": entries}))
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--entries", type=int, default=8)
    ap.add_argument("--pop", type=int, default=300)
    ap.add_argument("--gens", type=int, default=120)
    args = ap.parse_args()
    settings = Settings().replace(search={"pop": args.pop, "gens": args.gens})
    results = {}
    with tempfile.TemporaryDirectory(prefix="paretocal-batch-") as tmp:
        m = manifest(Path(tmp), args.entries)
        for workers in (1, 2):
            r = run_batch(m, Path(tmp) / f"out_{workers}", settings, workers=workers, check=True)
            per = [rec["wall_s"] for rec in r["records"] if rec["status"] == "ok"]
            results[workers] = r
            print(f"{workers} worker(s): {r['ok']}/{r['entries']} ok in {r['run_s']:.0f} s "
                  f"({r['entries_per_minute']:.2f} entries/min); per entry median "
                  f"{np.median(per):.1f} s (calibration + check, 5 frames)", flush=True)
    r1, r2 = results[1], results[2]
    print(f"speed-up with 2 workers: {r2['entries_per_minute'] / r1['entries_per_minute']:.2f}x")
    best = max(r1["entries_per_minute"], r2["entries_per_minute"])
    hours = 10_000 / best / 60
    print(f"10,000 drives (5 frames each) at {best:.2f} entries/min per 2-core machine: "
          f"{hours:.0f} machine-hours; on 100 such machines {hours / 100:.1f} h "
          f"(tasks are independent, so throughput scales with workers until the scheduler "
          f"or storage limits it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
