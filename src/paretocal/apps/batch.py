"""Calibrating a fleet's logs: one task per manifest entry on a Dask cluster.

A manifest lists sources (dataset folders), optional frame selections, initial extrinsics and
vehicle ids. Each entry is an independent task: the worker reads its own frames (no large array
crosses the network), calibrates, checks the initial extrinsic for miscalibration, publishes
the usual run directory (:func:`paretocal.rundir.publish_run`) and a small ``entry.json``
record, and returns that record. An entry whose record says ``ok`` for the same entry and
settings (a fingerprint of both) is done: rerunning the batch skips it, so a killed batch
resumes, while an edited entry or changed settings calibrate it again. A failing entry is
recorded with its reason and does not stop the others. What a task logs comes back in its
record and is logged by the driver naming the entry.

Manifest (YAML)::

    entries:
      - {id: car07_d0005, source: /logs/car07/2011_09_26_drive_0005_sync, frames: "0:20",
         init: /logs/car07/nominal.yaml, vehicle: car07, order: 1}

or CSV with the same columns (``id, source, frames, init, vehicle, camera, order``). Relative
paths are relative to the manifest.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import json
import logging
import os
import re
import shutil
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ..errors import MESSAGE_CHARS, InputError, ParetocalError, excerpt, first_line, key_list, quote
from ..io.atomic import atomic_path, atomic_write_text
from ..report.results import dumps

RECORD = "entry.json"
#: The local cluster's scratch folder (its workers' spill and lock files), inside the batch's
#: folder while the cluster runs and removed when it stops.
SCRATCH = ".dask-scratch"
#: Names a batch folder holds (runs/ from the first task on): the CLI refuses to write a batch
#: into a non-empty folder holding none of them unless told to (``--force``).
BATCH_MARKS = ("runs", "summary.csv", SCRATCH)
log = logging.getLogger(__name__)
#: An entry's id names its folder: letters, digits, '_', '-' and '.' (matched whole: ``$``
#: would take a trailing line break).
_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
SUMMARY_COLUMNS = ["id", "vehicle", "order", "status", "reason", "source", "frames",
                   "n_points", "drift_rotation_deg", "drift_translation_cm",
                   "ref_rotation_deg", "ref_translation_cm", "chamfer", "ms_per_eval",
                   "reliability", "reliability_reason", "check_verdict", "check_score",
                   "wall_s", "worker"] + \
                  [f"T_{i}{j}" for i in range(3) for j in range(4)]


class BatchInterrupted(KeyboardInterrupt):
    """The batch stopped on an interrupt (SIGINT, or SIGTERM turned into one) after stopping
    its tasks and writing the summary of the entries done so far.

    Attributes: ``done`` (entries ok), ``total`` (entries of the manifest), ``summary`` (the
    path of ``summary.csv``). A subclass of KeyboardInterrupt: code that handles interrupts
    handles this one.
    """

    def __init__(self, done: int, total: int, summary: Path):
        super().__init__(f"batch interrupted: {done} of {total} entries done")
        self.done, self.total, self.summary = done, total, summary


@dataclass(frozen=True)
class Entry:
    """One source to calibrate (paths absolute)."""

    id: str
    source: str
    frames: str | None = None
    init: str | None = None
    vehicle: str | None = None
    camera: int = 2
    order: str | None = None


def read_manifest(path: str | Path) -> list[Entry]:
    """Entries of a YAML (``entries:`` list, or a bare list) or CSV manifest.

    Raises :class:`InputError` naming the manifest (and the entry and field where there is
    one) for a file that is not UTF-8 text, malformed YAML or CSV, a missing ``id`` or
    ``source``, a duplicate or unsafe id (it names a folder), an unknown field, or a field of
    the wrong type.
    """
    from ..io.paths import kind_of, not_found

    path = Path(path)
    kind = kind_of(path)
    if kind == "a folder":
        raise InputError(f"{path}: is a folder; expected a YAML or CSV manifest")
    if kind != "a regular file":              # a FIFO is not opened: it would block
        raise InputError(f"{path}: a manifest expected, but this is {kind}" if kind
                         else not_found(path, "manifest"))
    text = _manifest_text(path)
    if path.suffix.lower() == ".csv":
        rows = _csv_rows(path, text)
    else:
        import yaml

        from ..io.text import load_yaml, yaml_error

        try:
            doc = load_yaml(text, path)      # refuses alias bombs and duplicate keys, naming it
        except yaml.YAMLError as exc:
            raise yaml_error(path, exc) from None
        listed = doc.get("entries") if isinstance(doc, dict) else doc
        if not isinstance(listed, list):
            raise InputError(f"{path}: expected a list of entries (or a mapping with 'entries')")
        rows = listed
    known = set(Entry.__dataclass_fields__)
    entries, seen = [], set()
    for k, row in enumerate(rows):
        where = f"{path}: entry {k + 1}"
        if not isinstance(row, dict):
            raise InputError(f"{where}: expected a mapping of fields")
        odd = [key for key in row if not isinstance(key, str)]
        if odd:
            raise InputError(f"{where}: field name {quote(odd[0])} is not text")
        row = {key: v for key, v in row.items() if v not in (None, "")}
        unknown = sorted(set(row) - known)
        if unknown:
            raise InputError(f"{where}: unknown field(s) {key_list(unknown)} "
                             f"(known: {', '.join(sorted(known))})")
        for key in ("id", "source"):
            if key not in row:
                raise InputError(f"{where}: missing '{key}'")
        # An Entry's fields, each of its own type (text; an integer camera).
        fields: dict[str, Any] = {key: _field(where, key, v) for key, v in row.items()}
        eid = fields["id"]
        if not _ID.fullmatch(eid):
            raise InputError(f"{where}: id {quote(eid)} must be letters, digits, '_', '-' or '.'")
        if eid in seen:
            raise InputError(f"{where}: duplicate id {quote(eid)}")
        seen.add(eid)
        for key in ("source", "init"):
            if key in fields:
                try:
                    fields[key] = str((path.parent / fields[key]).resolve())
                except (OSError, RuntimeError) as exc:       # RuntimeError: a symlink loop
                    raise InputError(f"{where}: {key} {quote(fields[key])}: "
                                     f"{first_line(exc)}") from None
        entries.append(Entry(**fields))
    if not entries:
        raise InputError(f"{path}: the manifest lists no entries")
    return entries


def _manifest_text(path: Path) -> str:
    """The manifest's text; a binary file (a NUL byte, or not UTF-8) is refused up front,
    before a parser reports it as something else."""
    from ..io.text import MAX_TEXT_BYTES

    try:
        size = path.stat().st_size
        if size > MAX_TEXT_BYTES:
            raise InputError(f"{path}: {size:,} bytes, more than the {MAX_TEXT_BYTES >> 20} MiB "
                             "a manifest may hold")
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the manifest ({exc.strerror or exc})") from None
    nul = data.find(b"\0")
    if nul >= 0:
        raise InputError(f"{path}: NUL byte at offset {nul}; a manifest is YAML or CSV text")
    try:
        return data.decode("utf-8-sig")        # -sig: spreadsheets save CSV with a BOM
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {data[exc.start]:#04x} at offset "
                         f"{exc.start}); a manifest is YAML or CSV text") from None


def _csv_rows(path: Path, text: str) -> list[dict]:
    import io as _io

    reader = csv.DictReader(_io.StringIO(text, newline=""))
    rows = []
    try:
        for row in reader:
            if None in row:                    # DictReader's key for values beyond the header
                header = reader.fieldnames or ()       # read with the first row
                raise InputError(f"{path}: line {reader.line_num}: {len(header)} "
                                 f"columns in the header, more values in this row")
            rows.append({k.strip(): v.strip() if isinstance(v, str) else v
                         for k, v in row.items()})
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: not valid CSV ({first_line(exc)})") from None
    return rows


def _field(where: str, key: str, value) -> str | int:
    """One manifest field, checked for its type: text for paths, ids and frame selections
    (YAML turns unquoted ``2:4`` into the number 124 and ``0005`` into 5), an integer for the
    camera, text or a number for the vehicle and the order."""
    if isinstance(value, str) and "\0" in value:
        raise InputError(f"{where}: {key} contains a NUL character")
    if key == "camera":
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        # ASCII digits only: str.isdigit() also takes "²", which int() refuses.
        if isinstance(value, str) and value.strip().isascii() and value.strip().isdigit():
            return int(value)
        raise InputError(f"{where}: camera {quote(value)} is not an integer")
    if key in ("vehicle", "order"):
        if isinstance(value, (str, int, float)) and not isinstance(value, bool):
            return str(value)
        raise InputError(f"{where}: {key} {quote(value)} must be text or a number")
    if isinstance(value, str):
        return value
    hint = ""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        hint = ('; quote it (frames: "2:4"): YAML reads unquoted 2:4 as the number 124'
                if key == "frames" else
                f'; quote it ({key}: "0005"): YAML reads unquoted 0005 as the number 5')
    raise InputError(f"{where}: {key} {quote(value)} must be text{hint}")


def read_record(run_dir: Path) -> dict | None:
    """The entry's record, or None when it has none, an unreadable one, or one that is not
    as :func:`write_record` wrote it for the run published beside it (its digest: an edited
    record, or a calibrated entry's result.json changed or gone)."""
    from ..io.text import load_json

    path = Path(run_dir) / RECORD
    try:
        record = load_json(path.read_text(encoding="utf-8"), path)
        if not isinstance(record, dict) or record.get("digest") != _digest(record, run_dir):
            return None
    except (OSError, ValueError, ParetocalError):           # ValueError: not UTF-8
        return None
    return record


def write_record(run_dir: Path, record: dict) -> None:
    """Write ``record`` as the entry's ``entry.json`` in ``run_dir`` (atomic), with the digest
    :func:`read_record` checks: of the record and, for a calibrated entry, of the result.json
    published beside it (which must be there)."""
    record = json.loads(dumps(record))          # as it reads back (arrays as lists)
    record["digest"] = _digest(record, run_dir)
    atomic_write_text(Path(run_dir) / RECORD, dumps(record, indent=1))


def _digest(record: dict, run_dir: Path) -> str:
    """SHA-256 of ``record`` (without its digest, as sorted JSON) and, when it says the entry
    calibrated, of ``run_dir/result.json`` (read without following a link). Raises OSError
    when that file cannot be read."""
    from ..io.paths import open_plain

    h = hashlib.sha256(json.dumps({k: v for k, v in record.items() if k != "digest"},
                                  sort_keys=True).encode())
    if record.get("status") == "ok":
        with open_plain(Path(run_dir) / "result.json", "a run's result") as fh:
            h.update(fh.read())
    return h.hexdigest()


def entry_fingerprint(entry: Entry, settings: dict, check: bool = True,
                      figures: bool = False) -> str:
    """What an entry's result depends on, hashed: its fields, the bytes of its initial
    extrinsic (so an edited ``init`` file counts too), the settings (``Settings.to_dict``) and
    whether it is checked and drawn. A record is done only for the same fingerprint."""
    from ..search.checkpoint import fingerprint

    from ..io.text import MAX_TEXT_BYTES

    init = None
    if entry.init:
        path = Path(entry.init)
        try:
            # Only a regular file of a readable size: a FIFO would block, a device never end.
            if path.is_file() and path.stat().st_size <= MAX_TEXT_BYTES:
                init = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            pass                     # the entry fails on it when it runs; nothing to compare
    return fingerprint(asdict(entry), init, settings,
                       {"check": bool(check), "figures": bool(figures)})


def entry_settings(entry: Entry, settings, dataset_options: bool = True) -> dict:
    """The settings ``entry`` runs with (:meth:`Settings.to_dict`): ``settings`` with what
    its source's calib.yaml states where they leave the default
    (:func:`~paretocal.config.dataset_settings`), as ``paretocal calibrate`` on the source
    would. A calib.yaml that cannot be read adds nothing here: the entry fails on it when it
    runs, with the reader's message in its record."""
    from ..config import dataset_settings
    from ..io import source_options

    try:
        options = source_options(entry.source) if dataset_options else {}
    except (ParetocalError, OSError):
        options = {}
    return dataset_settings(settings, options, dataset_options).to_dict()


def is_done(record: dict | None, fingerprint: str) -> bool:
    """Whether an entry's record says it calibrated, with the same entry and settings."""
    return (record is not None and record.get("status") == "ok"
            and record.get("fingerprint") == fingerprint)


def _failed(entry: Entry, reason: str, t0: float) -> dict:
    """The record of a failed entry; its reason is one line of at most MESSAGE_CHARS (the
    summary table's ``reason`` column)."""
    return {**asdict(entry), "status": "failed", "reason": excerpt(reason, MESSAGE_CHARS),
            "wall_s": round(time.perf_counter() - t0, 3), "worker": os.getpid()}


class _EntryLog(logging.Handler):
    """The paretocal log records of one entry's task, kept for its record instead of the
    worker's stderr; the driver shows them prefixed with the entry's id.

    Only the task's own thread counts: a worker may run several tasks at once. While the
    handler is attached, Python's last-resort handler stays silent, so nothing reaches the
    worker's stderr unprefixed.
    """

    def __init__(self, level: int):
        super().__init__(level)
        self.thread = threading.get_ident()
        self.records: list[list[str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread:
            try:
                self.records.append([record.levelname,
                                     excerpt(record.getMessage(), MESSAGE_CHARS)])
            except Exception:  # noqa: BLE001 - a bad format string must not fail the entry
                self.handleError(record)

    def __enter__(self) -> list[list[str]]:
        logger = logging.getLogger("paretocal")
        if logger.getEffectiveLevel() > self.level:
            logger.setLevel(self.level)
        logger.addHandler(self)
        return self.records

    def __exit__(self, *exc) -> None:
        logging.getLogger("paretocal").removeHandler(self)


def run_entry(entry: Entry, settings: dict, out_dir: str, check: bool = True,
              threads: int = 1, figures: bool = False, fingerprint: str | None = None,
              log_level: int = logging.WARNING) -> dict:
    """Calibrate one entry into ``out_dir/runs/<id>``; never raises (runs on a Dask worker).

    Parameters
    ----------
    entry : Entry
    settings : dict
        :meth:`Settings.to_dict` of the batch's settings.
    out_dir : str
    check : bool
        Also check the initial extrinsic for miscalibration (``paretocal check``).
    threads : int
        Threads of the evaluation kernel in this task.
    figures : bool
        Write the PNG figures of each run.
    fingerprint : str, optional
        :func:`entry_fingerprint` of the entry and settings, stored in the record.
    log_level : int
        Log records at this level or above are kept in the record's ``log``.

    Returns
    -------
    dict
        The record written to ``entry.json``: the entry's fields, ``status`` ("ok" or
        "failed"), ``reason``, the chosen ``T_cam_lidar``, ``drift_*`` (how far the
        calibration moved the initial extrinsic), reference errors when known, the check's
        verdict and score, ``reliability`` ("ok" or "unreliable") with ``reliability_reason``
        (the reasons, joined), ``wall_s``, ``fingerprint`` and ``log`` (``[level, message]``
        pairs logged while the entry ran).
    """
    from ..rundir import check_inner_run_folder, check_run_folder, locked

    t0 = time.perf_counter()
    run_dir = Path(out_dir) / "runs" / entry.id
    with _EntryLog(log_level) as messages:
        try:
            # The batch makes its entries' folders: one that is a link leads elsewhere.
            check_inner_run_folder(run_dir, "an entry's run folder")
            # One writer per run folder: a task left running by an interrupted batch on a
            # remote cluster must not mix its files with the rerun's.
            with locked(run_dir):
                check_run_folder(run_dir)          # refused before calibrating, not after
                # The record describes the last attempt: drop the old one before starting,
                # so a task killed half-way leaves no record that says "ok".
                (run_dir / RECORD).unlink(missing_ok=True)
                record = _attempt(entry, settings, run_dir, check, threads, figures, t0)
                record.update({"fingerprint": fingerprint, "log": messages})
                write_record(run_dir, record)
        except (ParetocalError, OSError) as exc:   # the folder is locked or cannot be written
            record = _failed(entry, str(exc), t0)
            record.update({"fingerprint": fingerprint, "log": messages})
    return record


def _attempt(entry: Entry, settings: dict, run_dir: Path, check: bool, threads: int,
             figures: bool, t0: float) -> dict:
    """The entry's record: calibrated, or failed with the reason."""
    try:
        from ..objective.kernel import set_threads

        set_threads(threads)
        record = _calibrate_entry(entry, settings, run_dir, check, figures)
        record.update({"wall_s": round(time.perf_counter() - t0, 3), "worker": os.getpid()})
    except ParetocalError as exc:
        record = _failed(entry, str(exc), t0)
    except Exception as exc:  # noqa: BLE001 - one bad entry must not stop the batch
        record = _failed(entry, f"unexpected {type(exc).__name__}: {exc}", t0)
    return record


def _calibrate_entry(entry: Entry, settings_dict: dict, run_dir: Path, check: bool,
                     figures: bool) -> dict:
    import dataclasses

    from ..check import check_extrinsic
    from ..config import settings_from_mapping
    from ..geometry import pose_error
    from ..io import load_frames, read_init
    from ..pipeline import calibrate
    from ..rundir import publish_run, run_record

    settings = dataclasses.replace(settings_from_mapping(settings_dict, "batch settings"),
                                   camera=entry.camera, frames=entry.frames)
    frames = load_frames(entry.source, entry.frames, entry.camera)
    T_init = read_init(entry.init, frames) if entry.init else None
    result = calibrate(frames, T_init, settings, dataset_options=False)   # entry_settings'
    # Staged and published with result.json last: the folder never mixes two runs, and its
    # run_args.json is always the run's own.
    publish_run(result, run_dir, result.sweeps or frames, figures=figures,
                args=run_record(entry.source, T_init, settings, figures))
    drift = pose_error(result.T_cam_lidar, result.T_init)
    ref = result.reference_error or {}
    rel = result.reliability
    if rel is None:                     # the pipeline judges every result it returns
        raise ParetocalError(f"{run_dir}: the result carries no verdict")
    record = {**asdict(entry), "status": "ok", "reason": "",
              "T_cam_lidar": result.T_cam_lidar, "n_points": result.n_points,
              "drift_rotation_deg": float(drift["rotation_deg"]),
              "drift_translation_cm": float(drift["translation_cm"]),
              "ref_rotation_deg": ref.get("rotation_deg"),
              "ref_translation_cm": ref.get("translation_cm"),
              "chamfer": result.objectives()["chamfer"],
              "ms_per_eval": result.objectives().get("ms"),
              "reliability": rel.verdict,
              "reliability_reason": "; ".join(rel.reasons)}
    if check:
        c = check_extrinsic(frames, result.T_init, settings)
        record.update({"check_verdict": c.verdict, "check_score": c.score})
    return record


def summary_rows(records: list[dict]) -> list[dict]:
    """Flat rows (SUMMARY_COLUMNS) for the summary table, sorted by vehicle, order, id."""
    rows = []
    for r in records:
        row = {k: r.get(k) for k in SUMMARY_COLUMNS if not k.startswith("T_")}
        T = r.get("T_cam_lidar")
        for i in range(3):
            for j in range(4):
                row[f"T_{i}{j}"] = None if T is None else float(T[i][j])
        rows.append(row)
    return sorted(rows, key=lambda r: (str(r["vehicle"] or ""), str(r["order"] or ""),
                                       str(r["id"])))


def write_summary(rows: list[dict], out_dir: Path) -> list[Path]:
    """``summary.csv`` and ``summary.parquet`` (atomic); returns the paths."""
    import io as _io

    import pyarrow as pa
    import pyarrow.parquet as pq

    out_dir = Path(out_dir)
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r[k]) for k in SUMMARY_COLUMNS})
    atomic_write_text(out_dir / "summary.csv", buf.getvalue())
    cols = {k: [r.get(k) for r in rows] for k in SUMMARY_COLUMNS}
    for k in ("id", "vehicle", "order", "status", "reason", "source", "frames",
              "reliability", "reliability_reason", "check_verdict"):
        cols[k] = [None if v is None else str(v) for v in cols[k]]
    table = pa.table(cols)
    with atomic_path(out_dir / "summary.parquet") as tmp:
        pq.write_table(table, tmp)
    return [out_dir / "summary.csv", out_dir / "summary.parquet"]


def require_fleet() -> None:
    """Raise :class:`ParetocalError` saying how to install the ``fleet`` extra (Dask and
    pyarrow, which only ``batch`` needs) when it is missing."""
    import importlib.util

    missing = [m for m in ("distributed", "pyarrow") if importlib.util.find_spec(m) is None]
    if missing:
        raise ParetocalError(f"paretocal batch needs {' and '.join(missing)}: install the fleet "
                             "extra, pip install 'paretocal[fleet]'")


def run_batch(manifest: str | Path, out_dir: str | Path, settings=None,
              scheduler: str | None = None, workers: int | None = None, check: bool = True,
              figures: bool = False, progress=None, dataset_options: bool = True) -> dict:
    """Calibrate every entry of ``manifest`` on a Dask cluster.

    An entry is skipped when its ``entry.json`` says ``ok`` with the fingerprint
    (:func:`entry_fingerprint`) of the same entry fields and settings; an edited entry, an
    edited ``init`` file or other settings calibrate it again. What the entries' tasks log
    is logged here (logger ``paretocal.apps.batch``) as ``[<id>] message`` when each finishes,
    and so is each failure.

    Parameters
    ----------
    manifest : path
    out_dir : path
    settings : Settings, optional
        For each entry, what its source's calib.yaml states (``init_error``) replaces the
        defaults these leave (:func:`~paretocal.config.dataset_settings`); the entry's
        fingerprint covers the settings it runs with.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); by default a local
        cluster of ``workers`` processes (one thread each) is started and stopped.
    workers : int, optional
        Local worker processes (default: 1). The kernel threads of each task are the CPU
        count divided by the workers.
    check, figures : bool
        See :func:`run_entry`.
    progress : callable, optional
        ``progress(done, total)`` as entries finish.
    dataset_options : bool
        False: the settings are final for every entry (they state ``init_error`` even where
        it is the default).

    Returns
    -------
    dict
        ``entries``, ``skipped`` (already done), ``ran``, ``ok``, ``failed``, ``wall_s``,
        ``entries_per_minute`` (of the entries run), ``records`` and the written ``files``.

    Raises
    ------
    InputError
        For a bad manifest (before anything runs) or a scheduler that cannot be reached.
    BatchInterrupted
        On KeyboardInterrupt (SIGINT, or SIGTERM turned into one by the caller), after the
        tasks and the cluster are stopped and the summary of the entries finished is written.
    """
    from ..config import Settings

    require_fleet()
    t0 = time.perf_counter()
    entries = read_manifest(manifest)
    settings = (settings or Settings()).validate()
    by_entry = {e.id: entry_settings(e, settings, dataset_options) for e in entries}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prints = {e.id: entry_fingerprint(e, by_entry[e.id], check, figures) for e in entries}
    done: dict[str, dict] = {}
    for e in entries:
        rec = read_record(out / "runs" / e.id)
        if rec is not None and is_done(rec, prints[e.id]):
            done[e.id] = rec
    pending = [e for e in entries if e.id not in done]
    records = dict(done)
    run_s = 0.0
    if pending:                                # nothing to run: no cluster to start
        try:
            run_s = _run_pending(pending, records, prints, by_entry, out, scheduler,
                                 workers, check, figures, progress)
        except KeyboardInterrupt:
            finished = [records[e.id] for e in entries if e.id in records]
            write_summary(summary_rows(finished), out)
            raise BatchInterrupted(sum(r["status"] == "ok" for r in finished), len(entries),
                                   out / "summary.csv") from None
    ordered = [records[e.id] for e in entries]
    rows = summary_rows(ordered)
    files = write_summary(rows, out)
    from ..report.fleet import fleet_figure

    fleet_figure(rows, out / "fleet.png")
    files.append(out / "fleet.png")
    ok = sum(r["status"] == "ok" for r in ordered)
    return {"entries": len(entries), "skipped": len(done), "ran": len(pending), "ok": ok,
            "failed": len(entries) - ok, "wall_s": time.perf_counter() - t0,
            "run_s": run_s,
            "entries_per_minute": 60.0 * len(pending) / run_s if pending and run_s > 0 else None,
            "records": ordered, "files": files}


def _run_pending(pending: list[Entry], records: dict, prints: dict, by_entry: dict,
                 out: Path, scheduler, workers, check: bool, figures: bool,
                 progress) -> float:
    """Run the entries' tasks (``by_entry``: each entry's settings as a dict), adding their
    records to ``records`` as they finish; returns the seconds from the cluster's start to
    its close."""
    from distributed import as_completed

    log_level = logging.getLogger("paretocal").getEffectiveLevel()
    futures: dict = {}
    with _deferred_interrupts():
        client, cluster, threads = _connect(scheduler, workers, log_level, out / SCRATCH)
    t_run = time.perf_counter()
    try:
        futures = {client.submit(run_entry, e, by_entry[e.id], str(out.resolve()), check,
                                 threads, figures, prints[e.id], log_level,
                                 key=f"paretocal-{e.id}-{time.time_ns()}", pure=False): e
                   for e in pending}
        for k, fut in enumerate(as_completed(futures)):
            e = futures[fut]
            try:
                rec = fut.result()
            except Exception as exc:  # noqa: BLE001 - a crashed worker fails its entry only
                rec = _failed(e, f"worker crashed: {type(exc).__name__}: {exc}",
                              time.perf_counter())
                rec["fingerprint"] = prints[e.id]
                run_dir = out / "runs" / e.id
                run_dir.mkdir(parents=True, exist_ok=True)
                write_record(run_dir, rec)
            records[e.id] = rec
            _relay(rec)
            if progress is not None:
                progress(k + 1, len(pending))
    except BaseException:
        # An interrupt (or a bug here): drop the queued tasks and stop the cluster, which kills
        # the running ones; Dask's account of that (tasks cancelled, workers killed) is noise.
        with _silenced("distributed"):
            client.cancel(list(futures))
            _close(client, cluster, out / SCRATCH)
        raise
    _close(client, cluster, out / SCRATCH)
    return time.perf_counter() - t_run


def _close(client, cluster, scratch: Path) -> None:
    """Close the client and the local cluster, then remove its scratch folder ``scratch``."""
    client.close()
    if cluster is not None:
        cluster.close()
        shutil.rmtree(scratch, ignore_errors=True)


@contextlib.contextmanager
def _deferred_interrupts():
    """Hold SIGINT, SIGTERM and SIGHUP until the block is done, then raise KeyboardInterrupt if one
    came: a cluster interrupted while it starts cannot be closed (its workers have no state to
    close from) and Dask reports that with a traceback at exit."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield                                  # signals reach the main thread only
        return
    caught = []
    # A signal ignored (nohup: SIGHUP) stays ignored.
    previous = {sig: signal.signal(sig, lambda signum, frame: caught.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
                if signal.getsignal(sig) is not signal.SIG_IGN}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            if handler is not None:            # None: set outside Python, nothing to restore
                signal.signal(sig, handler)
    if caught:
        raise KeyboardInterrupt


@contextlib.contextmanager
def _silenced(name: str):
    """Nothing below CRITICAL from logger ``name`` (in this process) for the duration."""
    logger = logging.getLogger(name)
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _connect(scheduler: str | None, workers: int | None, log_level: int, scratch: Path):
    """``(client, cluster, kernel threads per task)``; ``cluster`` is the local one started
    here (None with ``scheduler``), its scheduler's and workers' scratch in the folder
    ``scratch`` (Dask's default is ``$TMPDIR/dask-scratch-space``, outside the batch's folder,
    where a stopped worker leaves its lock file)."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            return Client(scheduler, timeout="20s"), None, 1
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    workers = max(1, int(workers or 1))
    # Dask's own warnings (a worker restarted, a task cancelled) repeat what the records
    # say; they are shown with --verbose only.
    quiet = logging.WARNING if log_level <= logging.INFO else logging.ERROR
    # The scheduler (in this process) takes its folder from Dask's configuration, the workers
    # from local_directory. Without a dashboard it still serves HTTP (health, metrics), on
    # port 8787 unless told otherwise, and warns when another Dask holds that port: any free
    # port does.
    with dask.config.set({"temporary-directory": str(scratch)}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, host="127.0.0.1", silence_logs=quiet,
                               local_directory=str(scratch),
                               scheduler_kwargs={"dashboard": False,
                                                 "dashboard_address": "127.0.0.1:0"})
    return Client(cluster), cluster, max(1, (os.cpu_count() or 1) // workers)


def _relay(record: dict) -> None:
    """Log what the entry's task logged, and its failure, each line naming the entry."""
    for level, message in record.get("log") or []:
        levelno = logging.getLevelName(level)
        log.log(levelno if isinstance(levelno, int) else logging.WARNING, "[%s] %s",
                record["id"], message)
    if record["status"] != "ok":
        log.warning("[%s] failed: %s", record["id"], record["reason"])
