"""A calibration into a run folder as the commands run it: the checks of ``--out`` before any
work, the run (new, or continued from its checkpoint by ``calibrate --resume``), what the
console says of its result and the line an interrupted run ends with."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from ..errors import ParetocalError
from ._common import StageProgress, fmt_err, report

if TYPE_CHECKING:
    from ..verdict import Reliability


#: Exit status of ``calibrate --strict`` for a result judged unreliable.
STRICT_EXIT = 3


def check_run_out(out: Path, force: bool, option: str = "--out") -> None:
    """Fail before any work when ``out`` cannot take a calibration run: not a writable
    folder, a non-empty folder that is no run folder (unless ``force``), or a run folder
    holding what a run must not follow (:func:`paretocal.rundir.check_run_folder`)."""
    from ..io.atomic import check_output_dir, check_own_folder
    from ..rundir import MARKS, check_run_folder

    check_output_dir(out, option)
    if not force:
        check_own_folder(out, MARKS, "run", option)
    check_run_folder(out)


def run_calibration(loaded, source, T_init, settings, out: Path, figures: bool, quiet: bool,
                    checkpoint_every: int, strict: bool = False, resume: bool = False,
                    dataset_options: bool = True) -> None:
    """Calibrate into the run folder ``out`` (:mod:`paretocal.rundir`); on an interrupt say
    where the partial front and the checkpoint are, and exit 130."""
    from ..errors import Interrupted
    from ..rundir import calibrate_run, resume_run, run_arguments

    try:
        with StageProgress(quiet) as progress:
            if resume:
                recorded = run_arguments(out)
                result = resume_run(out, checkpoint_every, progress=progress)
                if recorded["joint"]:
                    from ..apps.rig import write_joint_summary

                    write_joint_summary(result, out, recorded["joint"], recorded["source"])
            else:
                result = calibrate_run(source, out, T_init, settings, frames=loaded,
                                       figures=figures, checkpoint_every=checkpoint_every,
                                       progress=progress, dataset_options=dataset_options)
    except Interrupted as exc:
        report(interrupted_line(exc, out))
        raise typer.Exit(130) from None
    ref = result.reference_error
    typer.echo(f"paretocal: {len(result.frames)} frames, {result.evaluations} evaluations in "
               f"{result.wall_s:.1f} s; chosen n = {result.n_points} ({result.decision.rule}), "
               f"chamfer {result.objectives()['chamfer']:.4f}, "
               f"{result.objectives()['ms']:.4g} ms/eval modelled "
               f"({result.decision.measured_ms:.4g} measured now); "
               f"error vs reference: {fmt_err(ref)}; "
               f"wrote {out}")
    from ..verdict import interval_text

    if ref is not None:
        typer.echo(f"paretocal: error vs reference per axis (LiDAR frame): {_fmt_axes(ref)}")
    if result.board is not None:
        typer.echo(f"paretocal: {result.board.summary_line()}")
    rel = result.reliability
    if rel is None:                     # the pipeline judges every result it returns
        raise ParetocalError(f"{out}: the run's result carries no verdict")
    intervals = interval_text(rel)         # only for a result judged ok
    if intervals:
        typer.echo(f"paretocal: 95 % intervals per axis (LiDAR frame): {intervals}")
    typer.echo(verdict_line(rel))
    if strict and not rel.ok:
        raise typer.Exit(STRICT_EXIT)


def _fmt_axes(e: dict) -> str:
    """The per-axis errors of :func:`paretocal.geometry.pose_error` in the LiDAR frame (the
    correction's axes, those of the intervals): ``"x +0.47 cm, ..., roll -0.03 deg"``."""
    keys = ("x_lidar_cm", "y_lidar_cm", "z_lidar_cm", "yaw_deg", "pitch_deg", "roll_deg")
    return ", ".join(f"{k.split('_')[0]} {e[k]:+.3g} {k.rsplit('_', 1)[1]}" for k in keys)


def interrupted_line(exc, out: Path) -> str:
    """The one line an interrupted calibration prints: where it stopped, what it wrote and how
    to continue (``exc`` is a :class:`~paretocal.errors.Interrupted`)."""
    from ..rundir import PARTIAL_FRONT

    where = exc.phase + (f" (after generation {exc.generation})"
                         if exc.generation is not None else "")
    wrote = f"wrote {out / PARTIAL_FRONT}; " if exc.X is not None else ""
    if exc.checkpoint is not None:
        then = (f"the search state is kept in {exc.checkpoint}; continue with: "
                f"paretocal calibrate --resume {out}")
    elif exc.X is not None:
        then = "no checkpoint (--checkpoint-every 0): run the command again to finish"
    else:
        then = f"nothing was written to {out}; run the same command again"
    return f"paretocal: interrupted while {where}; {wrote}{then}"


def verdict_line(reliability: Reliability) -> str:
    """The CLI's last line: the verdict and its main reason, for a person."""
    from ..verdict import verdict_text

    return f"paretocal: verdict {verdict_text(reliability)}"


def continue_run(run_dir: Path, verbose: bool, quiet: bool, checkpoint_every: int,
                 strict: bool = False) -> None:
    """Rebuild an interrupted run from ``run_dir/run_args.json`` and continue it."""
    from ..io.atomic import check_output_dir
    from ..rundir import check_run_folder, run_arguments

    args = run_arguments(run_dir)              # a one-line error before anything is loaded
    check_output_dir(run_dir, "--resume")
    check_run_folder(run_dir)
    run_calibration(None, args["source"], args["T_init"], args["settings"], run_dir,
                    args["figures"], quiet, max(checkpoint_every, 1), strict, resume=True)
