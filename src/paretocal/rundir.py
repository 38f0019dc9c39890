"""Run folders: a calibration written to a folder that can be resumed after an interrupt.

``calibrate_run`` saves the search to ``checkpoint.npz`` every few generations, with
``checkpoint_args.json`` beside it (what a resume needs: the source, the initial extrinsic, every
setting, whether figures are drawn), and on completion publishes the run's files
(``report.results.write_outputs``) with its arguments as ``run_args.json``, and removes the
checkpoint. An interrupt (SIGINT, or SIGTERM turned into one by the caller) during the search
writes ``partial_front.csv`` and raises :class:`~paretocal.search.checkpoint.SearchInterrupted`;
``resume_run`` rebuilds the run from the folder and continues from the checkpoint to the result
the uninterrupted run gives.

A folder holds one run:

* one process at a time: ``.lock`` is held (``flock``) for the whole run and names the process
  holding it; a second run into the folder is refused with that name (a run that locked the
  file just as the holder removed it checks that it is still the folder's, and tries again);
* nothing is written before the search starts: a run refused for its input (a bad scene, a
  checkpoint of another run) leaves the folder as it was, so an interrupted run in it can still
  be resumed; ``checkpoint_args.json`` is written with the first checkpoint;
* the outputs are written to ``.staging/`` first, then the previous run's outputs (listed in
  ``.outputs``) are removed, the new ones (``run_args.json`` among them) moved in, and
  ``result.json`` moved last: a folder with ``result.json`` holds exactly one complete run, and
  its ``run_args.json`` is that run's; one without it no complete run. Publishing also removes
  the temporaries that a kill during an atomic write of the run's files left.

Nothing read from the folder reaches outside it (:func:`check_run_folder`, before the run and
again before publishing; nothing is touched when it refuses): the run's own files are never
followed through a symbolic link (one, a folder or a special file in their place is refused),
``.outputs`` may name only plain files of the folder itself, and a checkpoint's every field is
checked against the run's settings (:meth:`~paretocal.search.checkpoint.Checkpoint.load`).
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import stat
from pathlib import Path

import numpy as np

from .config import Settings, dataset_settings, settings_from_mapping
from .errors import InputError, Interrupted, ParetocalError
from .geometry import check_rigid
from .inputs import load_joint
from .io import load_frames, rig_source, source_options
from .io.atomic import (atomic_write_text, check_output_dir, check_own_folder,
                        temporary_pattern)
from .io.frame import Frame
from .io.paths import not_plain, odd_kind, open_plain
from .io.text import load_json
from .pipeline import calibrate
from .report.results import partial_front_csv, write_outputs
from .result import CalibrationResult
from .search.checkpoint import Checkpoint

log = logging.getLogger(__name__)

RUN_ARGS = "run_args.json"   #: the published run's arguments, published with its outputs
CHECKPOINT_ARGS = "checkpoint_args.json"   #: the arguments of the run the checkpoint is of
CHECKPOINT = "checkpoint.npz"
PARTIAL_FRONT = "partial_front.csv"
LOCK = ".lock"
STAGING = ".staging"
OUTPUTS = ".outputs"         #: the names the last published run wrote, one per line
RESULT = "result.json"       #: published last: the completion marker

#: Names only a paretocal run folder holds: a folder with one of them is a run folder (an
#: interrupted or killed run leaves at least ``.lock``); the CLI refuses to write a run into a
#: folder that is not empty and holds none of them unless told to (``--force``).
MARKS = (OUTPUTS, RESULT, RUN_ARGS, CHECKPOINT_ARGS, CHECKPOINT, PARTIAL_FRONT, LOCK, STAGING)
#: The folder's bookkeeping: never an output, so never removed as the previous run's.
_OWN = (LOCK, STAGING, OUTPUTS, CHECKPOINT, CHECKPOINT_ARGS)
#: Bytes: the run's own text files hold a few kB; a larger one is not one a run wrote.
_TEXT_LIMIT = 1 << 20
_FILE = "a file of a paretocal run"


def check_run_folder(out: Path) -> list[str]:
    """Check what a run reads from its folder ``out``; return the names ``.outputs`` lists
    (the files the last published run wrote, which the next one removes).

    Raises :class:`InputError` naming the file, before anything is touched, when one of the
    run's own files (:data:`MARKS`) is a symbolic link, a folder or a special file
    (``.staging``: anything but a folder), or when a line of ``.outputs`` is not a plain file
    name (a path separator, ``..``, a control character), names the folder's bookkeeping, or
    names something that is not a plain file.
    """
    out = Path(out)
    for name in MARKS:
        kind = odd_kind(out / name, folder=name == STAGING)
        if kind:
            raise not_plain(out / name, kind, "the staging folder of a paretocal run"
                            if name == STAGING else _FILE)
    path = out / OUTPUTS
    try:
        text = _read_own(path)
    except FileNotFoundError:
        return []
    names = []
    for k, name in enumerate(text.split("\n"), 1):
        if not name:
            continue
        why = None
        if (name in (".", "..") or "/" in name or "\\" in name
                or any(ord(c) < 32 or ord(c) == 127 for c in name)):
            why = "is not a plain file name"
        elif name in _OWN:
            why = "is the run folder's own bookkeeping, not an output"
        elif odd_kind(out / name):
            why = f"is {odd_kind(out / name)}, not a file"
        if why:
            raise InputError(f"{path}: line {k}: {name!r} {why}; this file lists the files "
                             "the folder's last run wrote (correct or remove the line)")
        names.append(name)
    return names


def check_inner_run_folder(folder: Path, what: str) -> None:
    """Refuse a run folder that paretocal makes inside another (a batch entry's
    ``runs/<id>``, a rig camera's ``OUT/<name>`` or ``OUT/joint``; ``what`` names it) when
    something else stands there: a symbolic link (the run's files would go, and a run folder
    there be replaced, wherever it leads), a file or a special file. Absent, or a plain
    folder, is fine. Raises :class:`InputError` (:func:`~paretocal.io.paths.not_plain`)."""
    kind = odd_kind(Path(folder), folder=True)
    if kind:
        raise not_plain(Path(folder), kind, what)


def _read_own(path: Path) -> str:
    """The text of one of the run's own small files, read without following a link. Raises
    FileNotFoundError when it is absent, :class:`InputError` when it cannot be one a run
    wrote."""
    with open_plain(path, _FILE) as fh:
        data = fh.read(_TEXT_LIMIT + 1)
    if len(data) > _TEXT_LIMIT:
        raise InputError(f"{path}: more than {_TEXT_LIMIT} bytes; not a file a paretocal run "
                         "wrote")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {data[exc.start]:#04x} at offset "
                         f"{exc.start}); not a file a paretocal run wrote") from None


def _open_lock(lock: Path) -> int:
    """The descriptor of the lock file ``lock``, created when absent; never through a link,
    never a folder or a special file (refused naming it)."""
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(lock, flags, 0o644)
    except OSError as exc:
        if exc.errno not in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
            raise
        raise not_plain(lock, odd_kind(lock) or "a special file",
                        "the lock file of a paretocal run") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise not_plain(lock, odd_kind(lock) or "a special file",
                        "the lock file of a paretocal run")
    return fd


def _is_file_at(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is the file at ``path`` (not followed through a link)."""
    try:
        here = os.lstat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (here.st_dev, here.st_ino) == (mine.st_dev, mine.st_ino)


@contextlib.contextmanager
def locked(out: Path):
    """Hold ``out/.lock`` for the duration (``out`` is created if needed and removed again
    when it was created here and is left empty). Raises :class:`ParetocalError` naming the
    process that holds the lock, or the ``.lock`` that is not a plain file."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        yield
        return
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    fd = None
    try:
        fd = _acquire(out, fcntl)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}".encode(), 0)
        try:
            yield
        finally:
            # Removed, then unlocked: a run that opened it meanwhile sees it gone (_acquire).
            (out / LOCK).unlink(missing_ok=True)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        if fd is not None:
            os.close(fd)
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()                # only when nothing else was written


def _acquire(out: Path, fcntl) -> int:
    """The descriptor of ``out/.lock``, locked (``flock``) by this process, and still the
    folder's lock file once locked. Raises :class:`ParetocalError` naming the holder."""
    while True:
        fd = _open_lock(out / LOCK)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown"
            os.close(fd)
            raise ParetocalError(f"{out}: another paretocal run is writing this folder "
                                 f"({holder}); wait for it to finish or use another --out"
                                 ) from None
        if _is_file_at(fd, out / LOCK):
            return fd
        # The holder removed .lock between our opening and our locking it (it removes the
        # file, then unlocks): the lock held is on a removed file, not the folder's. Again.
        os.close(fd)


def publish_run(result: CalibrationResult, out: Path, frames: list[Frame] | None,
                figures: bool = True, args: dict | None = None) -> list[Path]:
    """Write the run's files into ``out`` so that it never holds parts of two runs (module
    docstring); ``args``, the run's arguments (:func:`run_record`), are published as
    ``run_args.json`` (without them a previous run's is removed). Returns the published
    paths.

    Raises :class:`InputError` (:func:`check_run_folder`, or a link, folder or special file
    where a new output goes) before anything in ``out`` is removed.
    """
    out = Path(out)
    previous = check_run_folder(out)
    staging = out / STAGING
    shutil.rmtree(staging, ignore_errors=True)         # a real folder: checked above
    try:
        os.mkdir(staging)
        written = write_outputs(result, staging, frames, figures=figures)
        if args is not None:
            atomic_write_text(staging / RUN_ARGS, json.dumps(args, indent=1) + "\n")
            written.append(staging / RUN_ARGS)
        names = [p.relative_to(staging).as_posix() for p in written]
        for name in names:                             # os.replace cannot put a file there
            kind = odd_kind(out / name)
            if kind:
                raise not_plain(out / name, kind, _FILE)
    except BaseException:
        # A failed or interrupted write (a full disk, Ctrl-C) leaves no half run behind.
        shutil.rmtree(staging, ignore_errors=True)
        raise
    # The marker goes first, then everything the previous run published or left behind.
    (out / RESULT).unlink(missing_ok=True)
    for name in set(previous) | {PARTIAL_FRONT, RUN_ARGS}:     # write_outputs writes files only
        (out / name).unlink(missing_ok=True)
    atomic_write_text(out / OUTPUTS, "\n".join(names) + "\n")
    for name in sorted(names, key=lambda n: n == RESULT):
        os.replace(staging / name, out / name)
    shutil.rmtree(staging, ignore_errors=True)
    _remove_temporaries(out, set(names) | set(MARKS))
    return [out / n for n in names]


def write_run(result: CalibrationResult, out_dir: str | Path,
              frames: list[Frame] | None = None, figures: bool = True,
              force: bool = False) -> list[Path]:
    """Write a calibration's run folder, as ``paretocal calibrate --out`` does: the files of
    docs/conventions.md section 3, published whole (:func:`publish_run`).

    A folder that holds a run already (of the command line, :func:`calibrate_run` or this
    function) is replaced whole: its previous run's outputs, its ``run_args.json`` (which
    would describe another run) and any partial front are removed, so that it never mixes two
    runs. A folder of other files is refused, as ``--out`` refuses it without ``--force``.

    Parameters
    ----------
    result : CalibrationResult
        The calibration (:func:`paretocal.calibrate`).
    out_dir : str or Path
        The run folder (made when missing).
    frames : list of Frame, optional
        The frames calibrated: needed for the overlays and ``interactive.html``.
    figures : bool
        Write ``pareto.png``, the overlays and ``interactive.html``.
    force : bool
        Write into a folder that is not empty and holds no run (its files of the same names
        are replaced).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    SettingsError
        ``out_dir`` cannot take a run: not a writable folder, or a folder of other files
        without ``force``.
    ParetocalError
        Another process is writing the folder.
    """
    out = Path(out_dir)
    check_output_dir(out, "write_run: out_dir")
    if not force:
        check_own_folder(out, MARKS, "run", "write_run: out_dir", "pass force=True")
    # The frames as calibrated (de-skewed) for the overlays, as calibrate_run draws them.
    drawn = None if frames is None else (result.sweeps or frames)
    with locked(out):
        return publish_run(result, out, drawn, figures=figures)


def _remove_temporaries(out: Path, names) -> None:
    """Remove the temporaries that a kill during an atomic write of one of ``names`` left in
    ``out`` (exactly :func:`~paretocal.io.atomic.temporary_pattern`'s names, plain files)."""
    patterns = [temporary_pattern(out / n) for n in names]
    with os.scandir(out) as entries:
        for entry in entries:
            if (entry.is_file(follow_symlinks=False)
                    and any(p.fullmatch(entry.name) for p in patterns)):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(entry.path)


class _RunCheckpoint(Checkpoint):
    """A checkpoint that writes the run's arguments beside itself the first time it saves."""

    def __init__(self, path: Path, every: int, args: dict):
        super().__init__(path, every)
        self.args: dict | None = args          # None once written

    def save(self, state, history: list) -> None:
        if self.args is not None:
            atomic_write_text(Path(self.path).parent / CHECKPOINT_ARGS,
                              json.dumps(self.args, indent=1) + "\n")
            self.args = None
        super().save(state, history)


def calibrate_run(  # noqa: PLR0913 - dataset_options is keyword-only
        source: str | Path, out: str | Path, T_init: np.ndarray | None = None,
        settings: Settings | None = None, frames: list[Frame] | None = None,
        figures: bool = True, checkpoint_every: int = 5, progress=None,
        rig_camera: str | None = None, lidar=None, *,
        dataset_options: bool = True, joint: list[str] | None = None) -> CalibrationResult:
    """Calibrate ``source`` into the run folder ``out``, resumable.

    Parameters
    ----------
    source : path
        The dataset folder (recorded for the resume).
    out : path
        The run folder.
    T_init : ndarray, shape (4, 4), optional
    settings : Settings, optional
        What ``source``'s calib.yaml states (``init_error``) replaces the defaults these leave
        (:func:`~paretocal.config.dataset_settings`); the settings used are recorded for the
        resume.
    frames : list of Frame, optional
        The frames already loaded from ``source`` (loaded here when omitted).
    figures : bool
    checkpoint_every : int
        Generations between checkpoints; 0 for none (the run then cannot be resumed).
    progress : callable, optional
        As for :func:`paretocal.calibrate`.
    rig_camera : str, optional
        ``source`` is a rig folder (:func:`paretocal.io.rig_cameras`) and this is the camera
        calibrated (recorded for the resume).
    lidar : LidarSteps, optional
        The LiDAR-only steps already done on ``frames``' clouds (see
        :func:`paretocal.calibrate`).
    dataset_options : bool
        False: the settings are final (they state ``init_error`` even where it is the
        default, or were recorded after adoption: a resumed run).
    joint : list of str, optional
        ``source`` is a rig folder and these of its cameras are calibrated at once, one
        extrinsic for all (:func:`paretocal.inputs.load_joint`; recorded for the resume);
        ``T_init`` is then the first camera's.

    Raises
    ------
    paretocal.errors.Interrupted
        On an interrupt (SIGINT, or SIGTERM turned into one by the caller) in any phase, naming
        it; once the search has produced a front, ``partial_front.csv`` is written first, and
        ``checkpoint`` is set when the run can be resumed (``SearchInterrupted`` during the
        search itself).
    """
    settings = dataset_settings(settings, source_options(source) if dataset_options else {})
    out = Path(out)
    if frames is None:
        try:
            if joint:
                frames, lidar = load_joint(source, settings, joint)
            else:
                src = source if rig_camera is None else rig_source(source, rig_camera)
                frames = load_frames(src, settings.frames, settings.camera)
        except KeyboardInterrupt:
            raise Interrupted("loading the frames") from None
    args = run_record(source, T_init, settings, figures, rig_camera, joint)
    with locked(out):
        check_run_folder(out)              # refused before the search, not after it
        ckpt = None
        if checkpoint_every > 0:
            ckpt = _RunCheckpoint(out / CHECKPOINT, checkpoint_every, args)
        try:
            # The settings are final here (the dataset's options decided above).
            result = calibrate(frames, T_init, settings, progress=progress, checkpoint=ckpt,
                               lidar=lidar, dataset_options=False)
            try:
                if progress is not None:
                    progress("writing", 0, 1)
                publish_run(result, out, result.sweeps or frames, figures=figures, args=args)
            except KeyboardInterrupt:
                X, F = result.nsga_front if result.nsga_front is not None else (None, None)
                raise Interrupted("writing the results", result.history[-1]["gen"], X, F) from None
        except Interrupted as exc:
            if exc.X is not None:
                atomic_write_text(out / PARTIAL_FRONT, partial_front_csv(exc.X, exc.F))
            # Resumable when the search state and the run's arguments are on disk (an
            # interrupt before the first checkpoint leaves the folder as it was; a folder of
            # the previous release keeps them in run_args.json).
            exc.checkpoint = None
            if (ckpt is not None and Path(ckpt.path).is_file()
                    and ((out / CHECKPOINT_ARGS).is_file() or (out / RUN_ARGS).is_file())):
                exc.checkpoint = Path(ckpt.path)
            raise
        # A finished run needs no checkpoint (nor one an earlier run left); run_args.json
        # records its arguments.
        (out / CHECKPOINT).unlink(missing_ok=True)
        (out / CHECKPOINT_ARGS).unlink(missing_ok=True)
    return result


def run_record(source: str | Path, T_init: np.ndarray | None, settings: Settings,
               figures: bool, rig_camera: str | None = None,
               joint: list[str] | None = None) -> dict:
    """A run's arguments as ``run_args.json`` holds them (what :func:`run_arguments` reads
    back): the source's absolute path, ``T_init`` (4, 4) or None, the settings by section,
    whether figures are drawn, the rig camera, if any, and the cameras of a joint run."""
    return {"source": str(Path(source).resolve()),
            "T_init": None if T_init is None else np.asarray(T_init).tolist(),
            "settings": settings.to_dict(), "figures": bool(figures),
            **({} if rig_camera is None else {"rig_camera": rig_camera}),
            **({"joint": list(joint)} if joint else {})}


def run_arguments(run_dir: str | Path) -> dict:
    """What the run in ``run_dir`` recorded (``checkpoint_args.json`` of an unfinished run,
    else ``run_args.json``): ``source`` (Path), ``T_init`` (ndarray or None), ``settings``
    (Settings), ``figures`` (bool), ``rig_camera`` (the camera of a rig folder, or None) and
    ``joint`` (the cameras of a joint run, or None).
    One-line error naming the file when it is not a run folder or a field is malformed."""
    run_dir = Path(run_dir)
    path = next((run_dir / n for n in (CHECKPOINT_ARGS, RUN_ARGS)
                 if os.path.lexists(run_dir / n)), None)
    if path is None:
        runs: dict[str, str] = {}
        if run_dir.is_dir():
            for n in (RUN_ARGS, CHECKPOINT_ARGS):
                for p in run_dir.glob(f"*/{n}"):
                    camera = _rig_camera_of(p)
                    if camera is not None:
                        runs[p.parent.name] = camera
        if runs:
            first = sorted(runs)[0]
            one = "the cameras at once" if "," in runs[first] else "one camera"
            raise ParetocalError(f"{run_dir}: the run folder of a rig (cameras "
                                 f"{', '.join(sorted(set(runs.values())))}); resume {one} "
                                 f"with --resume {run_dir / first}")
        raise ParetocalError(f"{run_dir}: no {RUN_ARGS} here; not a run directory of paretocal "
                             "calibrate (or its run stopped before the first checkpoint, or "
                             "ran with --checkpoint-every 0)")
    args = load_json(_read_own(path), path)
    if not isinstance(args, dict):
        raise InputError(f"{path}: malformed: not a mapping of the run's arguments")

    def malformed(field: str, want: str) -> InputError:
        got = f"got {args[field]!r}"[:60] if field in args else "missing"
        return InputError(f"{path}: malformed: {field} must be {want} ({got})")

    source = args.get("source")
    if not isinstance(source, str) or not source or "\0" in source:
        raise malformed("source", "the dataset folder's path (text)")
    T_init = (None if args.get("T_init") is None
              else check_rigid(args["T_init"], str(path), key="T_init", orthonormalise=False))
    if not isinstance(args.get("settings"), dict):
        raise malformed("settings", "a mapping of settings by section")
    if not isinstance(args.get("figures"), bool):
        raise malformed("figures", "true or false")
    camera = args.get("rig_camera")
    if camera is not None and not isinstance(camera, str):
        raise malformed("rig_camera", "a camera's name (text)")
    joint = args.get("joint")
    if joint is not None and not (isinstance(joint, list) and joint
                                  and all(isinstance(n, str) for n in joint)):
        raise malformed("joint", "a list of camera names")
    try:
        settings = settings_from_mapping(args["settings"], str(path))
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: malformed ({type(exc).__name__}: {exc})") from None
    return {"source": Path(source), "T_init": T_init, "settings": settings,
            "figures": args["figures"], "rig_camera": camera, "joint": joint}


def _rig_camera_of(run_args: Path) -> str | None:
    """The rig camera a run's arguments record (a joint run: its cameras, joined), or None
    (a single-camera run, or a file that cannot be read: the caller then reports the folder
    as it is)."""
    try:
        args = load_json(_read_own(run_args), run_args)
        found, joint = args.get("rig_camera"), args.get("joint")
    except (OSError, AttributeError, ParetocalError):
        return None
    if isinstance(joint, list) and all(isinstance(n, str) for n in joint):
        return ", ".join(joint)
    return found if isinstance(found, str) else None


def resume_run(run_dir: str | Path, checkpoint_every: int = 5,
               progress=None) -> CalibrationResult:
    """Continue the run in ``run_dir`` from its checkpoint (from the start when there is
    none), with the arguments it recorded; the same result as the uninterrupted run.

    Parameters
    ----------
    run_dir : str or Path
        The run folder of an interrupted :func:`calibrate_run` (``paretocal calibrate --out``).
    checkpoint_every : int
        Generations between checkpoints; 0 for none.
    progress : callable, optional
        As for :func:`paretocal.calibrate`.

    Returns
    -------
    CalibrationResult
    """
    args = run_arguments(run_dir)
    if not os.path.lexists(Path(run_dir) / CHECKPOINT):
        log.warning("%s: no checkpoint; the run starts over", run_dir)
    # The recorded settings are those the run used, the dataset's init_error already in them.
    return calibrate_run(args["source"], run_dir, args["T_init"], args["settings"],
                         figures=args["figures"], checkpoint_every=max(checkpoint_every, 1),
                         progress=progress, rig_camera=args["rig_camera"],
                         dataset_options=False, joint=args["joint"])
