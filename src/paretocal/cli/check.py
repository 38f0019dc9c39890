"""``paretocal check``: whether an extrinsic is calibrated for a dataset, without ground truth."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from ..errors import ParetocalError, SettingsError
from . import app
from ._common import StageProgress, setup_logging
from .options import Camera, ConfigFile, Frames, Quiet, Verbose, one_camera, output_path

if TYPE_CHECKING:  # pragma: no cover
    from ..crosscheck import MotionAgreement
    from ..stage import FeatureCounts


@app.command()
def check(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    extrinsic: Annotated[Optional[Path], typer.Option(
        help="Extrinsic to check (YAML/JSON with T_cam_lidar); default: the dataset's.")] = None,
    frames: Frames = None,
    camera: Camera = None,
    out: Annotated[Optional[Path], typer.Option(
        parser=output_path, metavar="PATH", help="Write the full report (JSON) here.")] = None,
    rot_tol: Annotated[float, typer.Option(
        "--rot-tol-deg", "--rot-tol", help="Rotation tolerance (deg; default 0.5).")] = 0.5,
    trans_tol_m: Annotated[Optional[float], typer.Option(
        "--trans-tol-m", help="Translation tolerance (m; default 0.05), in metres as every "
                              "length on the command line.")] = None,
    trans_tol_cm: Annotated[Optional[float], typer.Option(
        "--trans-tol", help="Deprecated: the translation tolerance in cm; use --trans-tol-m.")
    ] = None,
    config: ConfigFile = None,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Say whether an extrinsic (--extrinsic, or the dataset's own) is calibrated for SOURCE,
    without ground truth."""
    import json

    from ..check import check_extrinsic
    from ..config import load_settings
    from ..io import load_frames
    from ..io.atomic import atomic_write_text, check_output_file

    setup_logging(verbose, quiet)
    trans_tol = _translation_tolerance_cm(trans_tol_m, trans_tol_cm)
    if rot_tol <= 0 or trans_tol <= 0:
        raise SettingsError("--rot-tol-deg and --trans-tol-m must be positive")
    if out is not None:
        check_output_file(out)
    settings = load_settings(config)
    from ..io import read_init
    src, index = one_camera(source, camera)
    T = read_init(extrinsic, src, index) if extrinsic is not None else None
    loaded = load_frames(src, frames, index)
    if T is None:
        T = loaded[0].T_ref
        if T is None:
            raise ParetocalError(f"{source}: the dataset has no extrinsic of its own "
                                 "(T_cam_lidar in calib.yaml); pass --extrinsic FILE")
    with StageProgress(quiet) as progress:
        r = check_extrinsic(loaded, T, settings, rot_tol, trans_tol, progress=progress)
    r = r.with_source(str(extrinsic) if extrinsic is not None else "dataset")
    if out is not None:
        atomic_write_text(out, json.dumps(r.to_dict(), indent=2) + "\n")
    which = f"{extrinsic}" if extrinsic is not None else "the dataset's own extrinsic"
    judged = r.verdict.upper() + (", but the frames are too few to judge (WEAK CHECK below)"
                                  if r.too_few else "")
    typer.echo(f"paretocal: {which}: {judged}; score {r.score:.2f} ({r.SCORE}): the local "
               f"optimum is {r.moved_deg:.3f} deg / {100 * r.moved_m:.2f} cm / "
               f"{r.moved_px:.1f} px away, tolerances {rot_tol:g} deg / {trans_tol:g} cm; "
               f"{100 * r.neighbour_fraction:.1f} % of grid neighbours score better")
    typer.echo(f"paretocal: {features_line(r.features)}")
    if r.motion is not None:
        typer.echo(f"paretocal: {motion_line(r.motion)}")
    if r.board is not None:
        typer.echo(f"paretocal: {board_line(r.board)}")
    for note in r.notes:
        typer.echo(f"paretocal: WEAK CHECK: {note}")


def _translation_tolerance_cm(metres: float | None, cm: float | None) -> float:
    """The translation tolerance (cm, as the library takes it) from ``--trans-tol-m`` or the
    deprecated ``--trans-tol`` (cm), which still works and says so."""
    import logging

    if metres is not None and cm is not None:
        raise SettingsError("--trans-tol (cm, deprecated) and --trans-tol-m both given; "
                            "keep --trans-tol-m")
    if cm is not None:
        logging.getLogger("paretocal").warning(
            "--trans-tol is in cm and deprecated: use --trans-tol-m %g (metres, as every "
            "length on the command line)", cm / 100.0)
        return float(cm)
    return 5.0 if metres is None else 100.0 * float(metres)


def features_line(features: FeatureCounts) -> str:
    """What the objective compared, in one line: the feature points per frame by group, the
    rings, and the frames whose depth edges look like noise (``stage.feature_counts``)."""
    mean = features.per_frame_mean
    rings = features.rings
    ring_text = ("no rings" if not rings else
                 f"{'/'.join(str(r) for r in rings)} rings")
    rec = features.ring_recovery
    if rec is not None:
        ring_text += f" ({', '.join(rec.methods)}, purity >= {rec.min_purity:.2f})"
    line = (f"features per frame: {mean['depth_edge']:g} depth edges, "
            f"{mean['intensity_edge']:g} intensity edges, {mean['smooth']:g} smooth points "
            f"in view; {ring_text}; {features.frames_contributing} of "
            f"{len(features.per_frame)} frames contribute")
    noise = features.noise
    if noise:
        line += (f"; the depth edges of {len(noise)} frame(s) look like noise (frame "
                 f"{noise[0].frame}: {noise[0].reason})")
    return line


def board_line(board: dict) -> str:
    """What the board gave a check, in one line (:func:`paretocal.board.board_summary`)."""
    n = board["frames_total"]
    line = (f"board: in {board['found_in_images']} of {n} images and "
            f"{board['found_in_clouds']} of {n} sweeps, {board['used']} in the objective")
    if board.get("board_optimum_moved_deg") is not None:
        line += (f"; the board alone prefers a pose {board['board_optimum_moved_deg']:.3f} deg / "
                 f"{board['board_optimum_moved_cm']:.2f} cm away")
    if board.get("reasons"):
        line += "; " + "; ".join(board["reasons"])
    return line


def motion_line(motion: MotionAgreement) -> str:
    """The rotation against the recording's motion, in one line
    (:class:`~paretocal.crosscheck.MotionAgreement`)."""
    if not motion.applied:
        return f"motion: not compared: {motion.reason}"
    seen = (f"{motion.change_deg:.2f} deg apart about the axes the motion observes, "
            f"tolerance {motion.tolerance_deg:.2g} deg from {motion.directions} direction(s) "
            f"of travel and {motion.turns} turn(s)")
    if motion.agree:
        return f"motion: the rotation agrees with the recording's motion ({seen})"
    return (f"motion: the rotation DISAGREES with the recording's motion ({seen}): it is "
            "off about an axis the motion observes, whatever the edges say; calibrate again")
