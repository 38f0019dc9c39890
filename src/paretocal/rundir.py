"""Run folders: a calibration written to a folder that can be resumed after an interrupt.

``calibrate_run`` saves the search to ``checkpoint.npz`` every few generations, with
``run_args.json`` beside it (what a resume needs: the source, the initial extrinsic, every
setting, whether figures are drawn), and on completion publishes the run's files
(``report.results.write_run``) and removes the checkpoint. An interrupt (SIGINT, or SIGTERM
turned into one by the caller) during the search writes ``partial_front.csv`` and raises
:class:`~paretocal.search.checkpoint.SearchInterrupted`; ``resume_run`` rebuilds the run from the
folder and continues from the checkpoint to the result the uninterrupted run gives.

A folder holds one run:

* one process at a time: ``.lock`` is held (``flock``) for the whole run and names the process
  holding it; a second run into the folder is refused with that name;
* nothing is written before the search starts: a run refused for its input (a bad scene, a
  checkpoint of another run) leaves the folder as it was, so an interrupted run in it can still
  be resumed; ``run_args.json`` is written with the first checkpoint;
* the outputs are written to ``.staging/`` first, then the previous run's outputs (listed in
  ``.outputs``) are removed, the new ones moved in, and ``result.json`` moved last: a folder
  with ``result.json`` holds exactly one complete run, one without it no complete run.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from .config import Settings, dataset_settings, settings_from_mapping
from .errors import Interrupted, ParetocalError
from .io import load_frames, rig_source, source_options
from .io.atomic import atomic_write_text
from .io.frame import Frame
from .pipeline import calibrate
from .report.results import partial_front_csv, write_run
from .result import CalibrationResult
from .search.checkpoint import Checkpoint

log = logging.getLogger(__name__)

RUN_ARGS = "run_args.json"
CHECKPOINT = "checkpoint.npz"
PARTIAL_FRONT = "partial_front.csv"
LOCK = ".lock"
STAGING = ".staging"
OUTPUTS = ".outputs"         #: the names the last published run wrote, one per line
RESULT = "result.json"       #: published last: the completion marker


@contextlib.contextmanager
def locked(out: Path):
    """Hold ``out/.lock`` for the duration (``out`` is created if needed and removed again
    when it was created here and is left empty). Raises :class:`ParetocalError` naming the
    process that holds the lock."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        yield
        return
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown"
            raise ParetocalError(f"{out}: another paretocal run is writing this folder "
                                 f"({holder}); wait for it to finish or use another --out"
                                 ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}".encode(), 0)
        try:
            yield
        finally:
            (out / LOCK).unlink(missing_ok=True)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()                # only when nothing else was written


def publish_run(result: CalibrationResult, out: Path, frames: list[Frame],
                figures: bool = True) -> list[Path]:
    """Write the run's files into ``out`` so that it never holds parts of two runs (module
    docstring); returns the published paths."""
    staging = out / STAGING
    shutil.rmtree(staging, ignore_errors=True)
    try:
        written = write_run(result, staging, frames, figures=figures)
    except BaseException:
        # A failed or interrupted write (a full disk, Ctrl-C) leaves no half run behind.
        shutil.rmtree(staging, ignore_errors=True)
        raise
    names = [p.relative_to(staging).as_posix() for p in written]
    # The marker goes first, then everything the previous run published or left behind.
    (out / RESULT).unlink(missing_ok=True)
    previous = out / OUTPUTS
    old = previous.read_text(encoding="utf-8").split() if previous.is_file() else []
    for name in set(old) | {PARTIAL_FRONT}:      # write_run writes files only
        (out / name).unlink(missing_ok=True)
    atomic_write_text(previous, "\n".join(names) + "\n")
    for name in sorted(names, key=lambda n: n == RESULT):
        os.replace(staging / name, out / name)
    shutil.rmtree(staging, ignore_errors=True)
    return [out / n for n in names]


class _RunCheckpoint(Checkpoint):
    """A checkpoint that writes the run's arguments beside itself the first time it saves."""

    def __init__(self, path: Path, every: int, args: dict):
        super().__init__(path, every)
        self.args = args

    def save(self, state, history: list) -> None:
        if self.args is not None:
            atomic_write_text(Path(self.path).parent / RUN_ARGS,
                              json.dumps(self.args, indent=1) + "\n")
            self.args = None
        super().save(state, history)


def calibrate_run(  # noqa: PLR0913 - dataset_options is keyword-only
        source: str | Path, out: str | Path, T_init: np.ndarray | None = None,
        settings: Settings | None = None, frames: list[Frame] | None = None,
        figures: bool = True, checkpoint_every: int = 5, progress=None,
        rig_camera: str | None = None, lidar=None, *,
        dataset_options: bool = True) -> CalibrationResult:
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
            src = source if rig_camera is None else rig_source(source, rig_camera)
            frames = load_frames(src, settings.frames, settings.camera)
        except KeyboardInterrupt:
            raise Interrupted("loading the frames") from None
    with locked(out):
        ckpt = None
        if checkpoint_every > 0:
            ckpt = _RunCheckpoint(out / CHECKPOINT, checkpoint_every, {
                "source": str(Path(source).resolve()),
                "T_init": None if T_init is None else np.asarray(T_init).tolist(),
                "settings": settings.to_dict(), "figures": bool(figures),
                **({} if rig_camera is None else {"rig_camera": rig_camera})})
        try:
            result = calibrate(frames, T_init, settings, progress=progress, checkpoint=ckpt,
                               lidar=lidar)
            try:
                publish_run(result, out, result.sweeps or frames, figures=figures)
            except KeyboardInterrupt:
                raise Interrupted("writing the results", result.history[-1]["gen"],
                                  result.nsga_front[0], result.nsga_front[1]) from None
        except Interrupted as exc:
            if exc.X is not None:
                atomic_write_text(out / PARTIAL_FRONT, partial_front_csv(exc.X, exc.F))
            # Resumable when the search state and the run's arguments are on disk (an
            # interrupt before the first checkpoint leaves the folder as it was).
            on_disk = (ckpt is not None and Path(ckpt.path).is_file()
                       and (out / RUN_ARGS).is_file())
            exc.checkpoint = Path(ckpt.path) if on_disk else None
            raise
        if ckpt is not None:
            # A finished run needs no checkpoint; its arguments stay as a record.
            Path(ckpt.path).unlink(missing_ok=True)
    return result


def run_arguments(run_dir: str | Path) -> dict:
    """What ``run_dir/run_args.json`` recorded: ``source`` (Path), ``T_init`` (ndarray or
    None), ``settings`` (Settings), ``figures`` (bool) and ``rig_camera`` (the camera of a rig
    folder, or None). One-line error when it is not a run
    folder or the file is damaged."""
    path = Path(run_dir) / RUN_ARGS
    if not path.is_file():
        cameras = (sorted(p.parent.name for p in Path(run_dir).glob(f"*/{RUN_ARGS}")
                          if _rig_camera_of(p) is not None)
                   if Path(run_dir).is_dir() else [])
        if cameras:
            raise ParetocalError(f"{run_dir}: the run folder of a rig (cameras "
                                 f"{', '.join(cameras)}); resume one camera with --resume "
                                 f"{Path(run_dir) / cameras[0]}")
        raise ParetocalError(f"{run_dir}: no {RUN_ARGS} here; not a run directory of paretocal "
                             "calibrate (or it was run with --checkpoint-every 0)")
    try:
        args = json.loads(path.read_text())
        settings = settings_from_mapping(args["settings"], str(path))
        T_init = None if args["T_init"] is None else np.asarray(args["T_init"], dtype=float)
        return {"source": Path(args["source"]), "T_init": T_init, "settings": settings,
                "figures": bool(args["figures"]), "rig_camera": args.get("rig_camera")}
    except (ValueError, KeyError, TypeError) as exc:
        raise ParetocalError(f"{path}: malformed ({type(exc).__name__}: {exc})") from None


def _rig_camera_of(run_args: Path) -> str | None:
    """The rig camera a ``run_args.json`` records, or None (a single-camera run, or a file
    that cannot be read: the caller then reports the folder as it is)."""
    try:
        found = json.loads(run_args.read_text()).get("rig_camera")
    except (OSError, ValueError, AttributeError):
        return None
    return found if isinstance(found, str) else None


def resume_run(run_dir: str | Path, checkpoint_every: int = 5,
               progress=None) -> CalibrationResult:
    """Continue the run in ``run_dir`` from its checkpoint (from the start when there is
    none), with the arguments it recorded; the same result as the uninterrupted run."""
    args = run_arguments(run_dir)
    if not (Path(run_dir) / CHECKPOINT).exists():
        log.warning("%s: no checkpoint; the run starts over", run_dir)
    # The recorded settings are those the run used, the dataset's init_error already in them.
    return calibrate_run(args["source"], run_dir, args["T_init"], args["settings"],
                         figures=args["figures"], checkpoint_every=max(checkpoint_every, 1),
                         progress=progress, rig_camera=args["rig_camera"],
                         dataset_options=False)
