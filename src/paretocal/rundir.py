"""Run folders: a calibration written to a folder that can be resumed after an interrupt.

``calibrate_run`` writes ``run_args.json`` (what a resume needs: the source, the initial
extrinsic, every setting, whether figures are drawn), saves the search to ``checkpoint.npz``
every few generations, and on completion writes the run's files (``report.results.write_run``)
and removes the checkpoint. An interrupt (SIGINT, or SIGTERM turned into one by the caller) during
the search writes ``partial_front.csv`` and raises
:class:`~paretocal.search.checkpoint.SearchInterrupted`; ``resume_run`` rebuilds the run from the
folder and continues from the checkpoint to the result the uninterrupted run gives.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from .config import Settings, settings_from_mapping
from .errors import ParetocalError
from .io import load_frames
from .io.atomic import atomic_write_text
from .io.frame import Frame
from .pipeline import calibrate
from .report.results import partial_front_csv, write_run
from .result import CalibrationResult
from .search.checkpoint import Checkpoint, SearchInterrupted

log = logging.getLogger(__name__)

RUN_ARGS = "run_args.json"
CHECKPOINT = "checkpoint.npz"
PARTIAL_FRONT = "partial_front.csv"


def calibrate_run(source: str | Path, out: str | Path, T_init: np.ndarray | None = None,
                  settings: Settings | None = None, frames: list[Frame] | None = None,
                  figures: bool = True, checkpoint_every: int = 5,
                  progress=None) -> CalibrationResult:
    """Calibrate ``source`` into the run folder ``out``, resumable.

    Parameters
    ----------
    source : path
        The dataset folder (recorded for the resume).
    out : path
        The run folder.
    T_init : ndarray, shape (4, 4), optional
    settings : Settings, optional
    frames : list of Frame, optional
        The frames already loaded from ``source`` (loaded here when omitted).
    figures : bool
    checkpoint_every : int
        Generations between checkpoints; 0 for none (the run then cannot be resumed).
    progress : callable, optional
        As for :func:`paretocal.calibrate`.

    Raises
    ------
    SearchInterrupted
        On an interrupt during the search, after writing ``partial_front.csv``.
    """
    settings = settings or Settings()
    out = Path(out)
    if frames is None:
        frames = load_frames(source, settings.frames, settings.camera)
    ckpt = None
    if checkpoint_every > 0:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / RUN_ARGS, json.dumps({
            "source": str(Path(source).resolve()),
            "T_init": None if T_init is None else np.asarray(T_init).tolist(),
            "settings": settings.to_dict(), "figures": bool(figures)}, indent=1) + "\n")
        ckpt = Checkpoint(out / CHECKPOINT, every=checkpoint_every)
    try:
        result = calibrate(frames, T_init, settings, progress=progress, checkpoint=ckpt)
        write_run(result, out, result.sweeps or frames, figures=figures)
    except SearchInterrupted as exc:
        atomic_write_text(out / PARTIAL_FRONT, partial_front_csv(exc.X, exc.F))
        raise
    if ckpt is not None:
        # A finished run needs no checkpoint; its arguments stay as a record.
        Path(ckpt.path).unlink(missing_ok=True)
    return result


def run_arguments(run_dir: str | Path) -> dict:
    """What ``run_dir/run_args.json`` recorded: ``source`` (Path), ``T_init`` (ndarray or
    None), ``settings`` (Settings) and ``figures`` (bool). One-line error when it is not a run
    folder or the file is damaged."""
    path = Path(run_dir) / RUN_ARGS
    if not path.is_file():
        raise ParetocalError(f"{run_dir}: no {RUN_ARGS} here; not a run directory of paretocal "
                             "calibrate (or it was run with --checkpoint-every 0)")
    try:
        args = json.loads(path.read_text())
        settings = settings_from_mapping(args["settings"], str(path))
        T_init = None if args["T_init"] is None else np.asarray(args["T_init"], dtype=float)
        return {"source": Path(args["source"]), "T_init": T_init, "settings": settings,
                "figures": bool(args["figures"])}
    except (ValueError, KeyError, TypeError) as exc:
        raise ParetocalError(f"{path}: malformed ({type(exc).__name__}: {exc})") from None


def resume_run(run_dir: str | Path, checkpoint_every: int = 5,
               progress=None) -> CalibrationResult:
    """Continue the run in ``run_dir`` from its checkpoint (from the start when there is
    none), with the arguments it recorded; the same result as the uninterrupted run."""
    args = run_arguments(run_dir)
    if not (Path(run_dir) / CHECKPOINT).exists():
        log.warning("%s: no checkpoint; the run starts over", run_dir)
    return calibrate_run(args["source"], run_dir, args["T_init"], args["settings"],
                         figures=args["figures"], checkpoint_every=max(checkpoint_every, 1),
                         progress=progress)
