"""Command line: a thin layer that parses options, calls the library and maps errors to exits.

Exit status: 0 success, 2 bad input or usage (one line on stderr naming the file or option),
1 anything unexpected, 130 interrupted; 3 ``calibrate --strict`` with a result judged
unreliable; 4 ``batch`` with at least one failed entry (the others are done and summary.csv
is written).
"""

from __future__ import annotations

import logging
import sys
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional, cast

import click
import typer

from ..errors import MESSAGE_CHARS, STOP, InputError, ParetocalError, SettingsError, excerpt
from ._common import STOP_HANDLER, StageProgress, fmt_err, report, setup_logging
from .options import (Camera, CameraOrConfig, CameraOrName, ConfigFile, Force, Frames, Quiet, Seed,
                      Verbose)


app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  context_settings={"help_option_names": ["-h", "--help"]},
                  help="Targetless camera-LiDAR calibration as a Pareto search over accuracy "
                       "and computational cost.")
log = logging.getLogger("paretocal")


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"paretocal {__version__}")
        raise typer.Exit(0)


@app.callback()
def _main(version: Annotated[bool, typer.Option(
        "--version", callback=_version, is_eager=True,
        help="Print the version and exit.")] = False) -> None:
    """Targetless camera-LiDAR calibration as a Pareto search over accuracy and computational
    cost. Units: metres, degrees and milliseconds unless an option says otherwise."""


def _choices(section: str, name: str, cls: str) -> type[Enum]:
    """The command line's choices of a setting, from the one list in the configuration."""
    from ..config import CHOICES

    # Enum's functional API makes a class; mypy reads a call with a computed name as a member.
    return cast(type[Enum],
                Enum(cls, [(v.replace("-", "_"), v) for v in CHOICES[(section, name)]], type=str))


if TYPE_CHECKING:
    from ..verdict import Reliability

    # Classes made at run time from the configuration's lists, which the type checker cannot
    # read: to it they are enums of strings like any other.
    Rule = Enum
    Chamfer = Enum
    Cost = Enum
    Evaluator = Enum
    Wide = Enum
else:
    Rule = _choices("decision", "rule", "Rule")
    Chamfer = _choices("objective", "chamfer", "Chamfer")
    Cost = _choices("objective", "cost", "Cost")
    Evaluator = _choices("objective", "evaluator", "Evaluator")
    Wide = _choices("search", "wide", "Wide")


def _fmt_axes(e: dict) -> str:
    """The per-axis errors of :func:`paretocal.geometry.pose_error` in the LiDAR frame (the
    correction's axes, those of the intervals): ``"x +0.47 cm, ..., roll -0.03 deg"``."""
    keys = ("x_lidar_cm", "y_lidar_cm", "z_lidar_cm", "yaw_deg", "pitch_deg", "roll_deg")
    return ", ".join(f"{k.split('_')[0]} {e[k]:+.3g} {k.rsplit('_', 1)[1]}" for k in keys)


@app.command()
def calibrate(
    source: Annotated[Optional[Path], typer.Argument(
        help="Dataset folder: KITTI raw drive or date folder, KITTI object 'training', or a "
             "generic folder (not needed with --resume); for a ROS bag, run paretocal extract "
             "first.")] = None,
    out: Annotated[Optional[Path], typer.Option("--out", help="Run directory to write.")] = None,
    resume: Annotated[Optional[Path], typer.Option(
        help="Continue the interrupted run in this run directory (same data, start and "
             "settings; the result equals an uninterrupted run).")] = None,
    checkpoint_every: Annotated[int, typer.Option(
        "--checkpoint-every", help="Save the search state every N generations (0: never).")] = 5,
    init: Annotated[Optional[Path], typer.Option(help="Initial extrinsic (YAML/JSON with "
                                                      "T_cam_lidar); default: the dataset's.")] = None,
    frames: Frames = None,
    seed: Seed = None,
    pop: Annotated[Optional[int], typer.Option(help="Population size.")] = None,
    gens: Annotated[Optional[int], typer.Option(help="Generations.")] = None,
    camera: CameraOrName = None,
    config: ConfigFile = None,
    budget_ms: Annotated[Optional[float], typer.Option(
        "--budget-ms", help="Choose the best Chamfer whose modelled evaluation time is within "
                            "this many ms, instead of the knee.")] = None,
    rule: Annotated[Optional[Rule], typer.Option(help="Decision rule.")] = None,
    max_deviation: Annotated[Optional[float], typer.Option(
        "--max-deviation", help="Knee rule: consider only solutions whose calibration moves "
                                "projections at most this many px from the best-supported "
                                "one (default 1).")] = None,
    n_min: Annotated[Optional[int], typer.Option("--n-min", help="Fewest feature points per frame.")] = None,
    n_max: Annotated[Optional[int], typer.Option("--n-max", help="Most feature points per frame.")] = None,
    init_error: Annotated[Optional[str], typer.Option(
        "--init-error", metavar="DEG,M",
        help="How far off the initial extrinsic may be, per axis (default 10,0.3; also "
             "init_error in calib.yaml). The search box is 1.5 times this.")] = None,
    bound_t: Annotated[Optional[float], typer.Option("--bound-t", help="Translation bound (+- m).")] = None,
    bound_r: Annotated[Optional[float], typer.Option("--bound-r", help="Rotation bound (+- deg).")] = None,
    wide: Annotated[Optional[Wide], typer.Option(
        help="The wide start from the recording's motion: auto (default) when --init-error "
             "exceeds 10 deg or 0.3 m, on, off.")] = None,
    chamfer: Annotated[Optional[Chamfer], typer.Option(help="Alignment objective.")] = None,
    w_edge: Annotated[Optional[float], typer.Option("--w-edge", help="w1 of the edge term; "
                                                    "w2 = 1 - w1 weighs the intensity term.")] = None,
    cost: Annotated[Optional[Cost], typer.Option(help="Cost objective: fitted model or the "
                                                      "paper's per-evaluation psutil.")] = None,
    evaluator: Annotated[Optional[Evaluator], typer.Option(help="Objective evaluator.")] = None,
    polish: Annotated[Optional[bool], typer.Option("--polish/--no-polish",
                                                    help="Locally polish the front.")] = None,
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="Write PNG figures.")] = True,
    strict: Annotated[bool, typer.Option(
        "--strict", help="Exit with status 3 when the result is judged unreliable (the outputs "
                         "are written either way).")] = False,
    joint: Annotated[bool, typer.Option(
        "--joint", help="A rig folder: calibrate every camera at once, one LiDAR correction "
                        "for all, the cameras' relative poses kept as calib.yaml states them "
                        "(--init: the first camera's start).")] = False,
    force: Force = False,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Calibrate SOURCE and write result.json, pareto.csv, extrinsic.yaml and figures to --out."""
    from ..config import load_settings
    from ..io import load_frames

    setup_logging(verbose, quiet)
    if resume is not None:
        given = {"SOURCE": source, "--out": out, "--init": init, "--frames": frames,
                 "--seed": seed, "--pop": pop, "--gens": gens, "--camera": camera,
                 "--config": config, "--budget-ms": budget_ms, "--rule": rule,
                 "--max-deviation": max_deviation, "--n-min": n_min, "--n-max": n_max,
                 "--init-error": init_error, "--bound-t": bound_t, "--bound-r": bound_r,
                 "--wide": wide, "--chamfer": chamfer, "--w-edge": w_edge, "--cost": cost,
                 "--evaluator": evaluator, "--polish/--no-polish": polish,
                 "--no-figures": None if figures else False, "--force": force or None,
                 "--joint": joint or None}
        clash = [name for name, value in given.items() if value is not None]
        if clash:
            raise SettingsError(f"--resume {resume} continues the run with the data, start and "
                                f"settings it recorded; remove {', '.join(clash)} (only "
                                "--checkpoint-every, --strict, --verbose and --quiet apply)")
        return _resume(resume, verbose, quiet, checkpoint_every, strict)
    if source is None or out is None:
        raise SettingsError("calibrate needs SOURCE and --out (or --resume RUN_DIR)")
    if checkpoint_every < 0:
        raise SettingsError("--checkpoint-every must be 0 or more")
    settings = load_settings(config)
    if budget_ms is not None and rule is None:
        rule = Rule("budget")
    from ..config import parse_init_error
    err_deg, err_m = parse_init_error(init_error, "--init-error")
    settings = settings.replace(
        search={"pop": pop, "gens": gens, "seed": seed, "n_min": n_min, "n_max": n_max,
                "bound_t_m": bound_t, "bound_r_deg": bound_r, "init_error_deg": err_deg,
                "init_error_m": err_m, "wide": wide.value if wide else None},
        objective={"chamfer": chamfer.value if chamfer else None, "w_edge": w_edge,
                   "cost": cost.value if cost else None,
                   "evaluator": evaluator.value if evaluator else None},
        decision={"rule": rule.value if rule else None, "budget_ms": budget_ms,
                  "polish": polish, "max_deviation_px": max_deviation})
    import dataclasses

    from ..config import states_init_error
    from ..io import detect_source, is_rig

    # The dataset's own init_error (calib.yaml) applies unless the user set it: the library
    # decides (config.dataset_settings) with the rest of the settings.
    adopt = err_deg is None and not states_init_error(config)
    if is_rig(source):
        return _calibrate_rig(source, out, init, camera, frames, settings, adopt,
                              figures, quiet, checkpoint_every, strict, force, joint)
    if joint:
        raise SettingsError(f"--joint: {source} is not a rig folder (calib.yaml with cameras:)")
    camera_index = _camera_index(camera) if camera is not None else None
    if camera_index is not None or frames is not None:
        settings = dataclasses.replace(settings, camera=camera_index if camera_index is not None
                                       else settings.camera,
                                       frames=frames if frames is not None else settings.frames)
    settings.validate()
    # Detected once: its warnings are said once.
    detected = detect_source(Path(source), settings.camera)
    _check_run_out(out, force)
    from ..io import read_init
    T_init = read_init(init, detected, settings.camera) if init is not None else None
    loaded = load_frames(detected, settings.frames, settings.camera)
    _run_calibration(loaded, source, T_init, settings, out, figures, quiet, checkpoint_every,
                     strict, dataset_options=adopt)


def _check_run_out(out: Path, force: bool, option: str = "--out") -> None:
    """Fail before any work when ``out`` cannot take a calibration run: not a writable
    folder, a non-empty folder that is no run folder (unless ``force``), or a run folder
    holding what a run must not follow (:func:`paretocal.rundir.check_run_folder`)."""
    from ..io.atomic import check_output_dir, check_own_folder
    from ..rundir import MARKS, check_run_folder

    check_output_dir(out, option)
    if not force:
        check_own_folder(out, MARKS, "run", option)
    check_run_folder(out)


def _camera_index(text: str) -> int:
    """``--camera`` of a single-camera source: a KITTI camera index."""
    try:
        return int(text)
    except ValueError:
        raise SettingsError(f"--camera {text}: a KITTI camera index 0-3; camera names apply "
                            "to a rig folder (calib.yaml with cameras:)") from None


def _calibrate_rig(source: Path, out: Path, init, camera: str | None, frames, settings,  # noqa: PLR0913
                   dataset_options: bool, figures: bool, quiet: bool, checkpoint_every: int,
                   strict: bool, force: bool, joint: bool = False) -> None:
    """``calibrate`` on a rig folder: every camera (or ``--camera NAME``) into ``out/NAME/``
    and ``out/rig.json``, or with ``joint`` all cameras at once into ``out/joint/``
    (:mod:`paretocal.apps.rig`)."""
    import dataclasses

    from ..errors import Interrupted
    from ..io import rig_cameras
    from ..io.atomic import check_output_dir, check_own_folder
    from ..apps.rig import JOINT_RUN, RIG_JSON, calibrate_rig, pair_line

    cams = rig_cameras(source)
    names = [n for n, _ in cams]
    if joint and camera is not None:
        raise SettingsError(f"--camera {camera}: --joint calibrates every camera of the rig at "
                            "once")
    if camera is not None and camera not in names:
        raise SettingsError(f"--camera {camera}: {source / 'calib.yaml'} lists the cameras "
                            f"{', '.join(names)}")
    if init is not None and camera is None and not joint:
        raise SettingsError(f"--init {init}: a rig's initial extrinsics are its calib.yaml's "
                            "cameras.NAME.T_cam_lidar; --init applies to one camera, with "
                            "--camera NAME")
    if frames is not None:
        settings = dataclasses.replace(settings, frames=frames)
    settings.validate()
    check_output_dir(out)
    if not force:       # a rig's run folder holds rig.json and a run folder per camera
        check_own_folder(out, (RIG_JSON, *names, JOINT_RUN), "rig run")
    for name in [JOINT_RUN] if joint else [camera] if camera is not None else names:
        _check_run_out(out / name, force)
    # --init names one camera: --camera NAME, or with --joint the first (refused above else).
    first = names[0] if joint or camera is None else camera
    from ..io import read_init
    T_inits = {first: read_init(init, source, None)} if init is not None else None
    unreliable = []

    def said(name, result):
        if joint and name != names[0]:
            return
        ref = result.reference_error
        verdict = None if result.reliability is None else result.reliability.verdict
        what = f"cameras {', '.join(names)} at once" if joint else f"camera {name}"
        typer.echo(f"paretocal: {what}: {len(result.frames)} frames, chosen n = "
                   f"{result.n_points}; error vs reference: {fmt_err(ref)}; verdict "
                   f"{verdict}; wrote {out / (JOINT_RUN if joint else name)}")
        if verdict != "ok":
            unreliable.append(name)

    try:
        with StageProgress(quiet) as progress:
            summary = calibrate_rig(source, out, settings, T_inits,
                                    [camera] if camera is not None else None, figures,
                                    checkpoint_every, progress, on_camera=said,
                                    dataset_options=dataset_options, joint=joint)
    except Interrupted as exc:
        report(interrupted_line(exc, exc.run_dir if exc.run_dir is not None else out))
        raise typer.Exit(130) from None
    for pair in summary["pairs"]:
        typer.echo(f"paretocal: {pair_line(pair)}")
    if summary["pairs"] or joint:
        typer.echo(f"paretocal: wrote {out / RIG_JSON}")
    if strict and unreliable:
        raise typer.Exit(STRICT_EXIT)


def _run_calibration(loaded, source, T_init, settings, out: Path, figures: bool, quiet: bool,
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
    rel = result.reliability
    if rel is None:                     # the pipeline judges every result it returns
        raise ParetocalError(f"{out}: the run's result carries no verdict")
    intervals = interval_text(rel)         # only for a result judged ok
    if intervals:
        typer.echo(f"paretocal: 95 % intervals per axis (LiDAR frame): {intervals}")
    typer.echo(verdict_line(rel))
    if strict and not rel.ok:
        raise typer.Exit(STRICT_EXIT)


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


#: Exit status of ``calibrate --strict`` for a result judged unreliable.
STRICT_EXIT = 3


def verdict_line(reliability: Reliability) -> str:
    """The CLI's last line: the verdict and its main reason, for a person."""
    from ..verdict import verdict_text

    return f"paretocal: verdict {verdict_text(reliability)}"


def _resume(run_dir: Path, verbose: bool, quiet: bool, checkpoint_every: int,
            strict: bool = False) -> None:
    """Rebuild an interrupted run from ``run_dir/run_args.json`` and continue it."""
    from ..io.atomic import check_output_dir
    from ..rundir import check_run_folder, run_arguments

    args = run_arguments(run_dir)              # a one-line error before anything is loaded
    check_output_dir(run_dir, "--resume")
    check_run_folder(run_dir)
    _run_calibration(None, args["source"], args["T_init"], args["settings"], run_dir,
                     args["figures"], quiet, max(checkpoint_every, 1), strict, resume=True)


@app.command()
def perturb(
    source: Annotated[Path, typer.Argument(help="Dataset whose own extrinsic is perturbed.")],
    out: Annotated[Path, typer.Option("--out", help="YAML file to write (an --init file).")],
    rot: Annotated[float, typer.Option(help="Per-axis rotation bound (+- deg).")] = 5.0,
    trans: Annotated[float, typer.Option(help="Per-axis translation bound (+- m).")] = 0.2,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    camera: Camera = 2,
) -> None:
    """Write a decalibrated copy of the dataset's extrinsic as an --init file.

    A correction is drawn uniform per axis in +-ROT deg and +-TRANS m; the file holds the
    extrinsic that this correction brings back to the dataset's (T_init = T_ref @ D^-1), so the
    correction to find lies in the box.
    """
    from ..geometry import decalibrate, pose_error
    from ..io import detect_source, write_extrinsic
    from ..io.atomic import check_output_file

    _check_perturbation(rot, trans)
    check_output_file(out)
    src = detect_source(source, camera)
    T_ref = src.frames[0].T_ref
    if T_ref is None:
        raise ParetocalError(f"{source}: the dataset has no extrinsic to perturb")
    T, p = decalibrate(T_ref, rot, trans, seed)
    e = pose_error(T, T_ref)
    write_extrinsic(out, T, comment=(
        f"{source} extrinsic decalibrated (seed {seed}); the correction back is x y z = "
        f"{p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f} m, yaw pitch roll = {p[3]:+.2f} {p[4]:+.2f} "
        f"{p[5]:+.2f} deg\n"
        f"error vs reference: {e['rotation_deg']:.3f} deg, {e['translation_cm']:.2f} cm"))
    typer.echo(f"paretocal: wrote {out} ({fmt_err({k: float(v) for k, v in e.items()})} "
               "from the reference)")


def _check_perturbation(rot: float, trans: float) -> None:
    """``perturb``'s bounds: finite and not negative; a rotation within a half turn (a larger
    per-axis angle only repeats the same rotations) and a translation whose box +-TRANS spans
    a finite range of floats (the uniform draw needs its width)."""
    import math

    for name, value in (("--rot", rot), ("--trans", trans)):
        if not math.isfinite(value):
            raise SettingsError(f"{name} {value}: must be a finite number")
        if value < 0:
            raise SettingsError(f"{name} {value:g}: must not be negative")
    if rot > 180:
        raise SettingsError(f"--rot {rot:g}: at most 180 degrees per axis")
    if not math.isfinite(2.0 * trans):
        raise SettingsError(f"--trans {trans:g}: too large (the box +-TRANS must have a "
                            "finite width)")


@app.command()
def check(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    extrinsic: Annotated[Optional[Path], typer.Option(
        help="Extrinsic to check (YAML/JSON with T_cam_lidar); default: the dataset's.")] = None,
    frames: Frames = None,
    camera: Camera = 2,
    out: Annotated[Optional[Path], typer.Option(help="Write the full report (JSON) here.")] = None,
    rot_tol: Annotated[float, typer.Option("--rot-tol", help="Rotation tolerance (deg).")] = 0.5,
    trans_tol: Annotated[float, typer.Option("--trans-tol", help="Translation tolerance (cm).")] = 5.0,
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
    if rot_tol <= 0 or trans_tol <= 0:
        raise SettingsError("--rot-tol and --trans-tol must be positive")
    if out is not None:
        check_output_file(out)
    settings = load_settings(config)
    from ..io import read_init
    T = read_init(extrinsic, source, camera) if extrinsic is not None else None
    loaded = load_frames(source, frames, camera)
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
    typer.echo(f"paretocal: {which}: {r.verdict.upper()} (score {r.score:.2f}; the local "
               f"optimum is {r.moved_deg:.3f} deg / {100 * r.moved_m:.2f} cm / "
               f"{r.moved_px:.1f} px away, tolerances {rot_tol:g} deg / {trans_tol:g} cm; "
               f"{100 * r.neighbour_fraction:.1f} % of grid neighbours score better)")
    typer.echo(f"paretocal: {_features_line(r.features)}")
    for note in r.notes:
        typer.echo(f"paretocal: WEAK CHECK: {note}")


@app.command()
def compare(
    a: Annotated[Path, typer.Argument(help="Extrinsic A (any --init form: YAML/JSON with "
                                           "T_cam_lidar, a result.json, a KITTI calibration "
                                           "file with SOURCE).")],
    b: Annotated[Path, typer.Argument(help="Extrinsic B, in any of the same forms.")],
    source: Annotated[Optional[Path], typer.Argument(
        help="Dataset folder: also say which of the two its frames prefer.")] = None,
    frames: Frames = None,
    camera: Camera = 2,
    out: Annotated[Optional[Path], typer.Option(help="Write the comparison (JSON) here.")] = None,
    config: ConfigFile = None,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Compare two extrinsics: B relative to A per axis in A's LiDAR frame, as an angle and a
    distance, and with SOURCE which one the frames prefer (the verdict's paired test)."""
    import json

    from ..check import compare_extrinsics
    from ..config import load_settings
    from ..io import load_frames, read_init
    from ..io.atomic import atomic_write_text, check_output_file
    from ..io.extrinsic import needs_kitti_rect

    setup_logging(verbose, quiet)
    if out is not None:
        check_output_file(out)
    settings = load_settings(config)
    for path in (a, b):
        if source is None and needs_kitti_rect(path):
            raise InputError(f"{path}: holds KITTI's Tr_velo_to_cam (LiDAR -> unrectified "
                             "camera 0); pass the KITTI SOURCE it belongs to, whose "
                             "rectification turns it into T_cam_lidar")
    loaded = load_frames(source, frames, camera) if source is not None else None
    T_a = read_init(a, loaded, camera)
    T_b = read_init(b, loaded, camera)
    with StageProgress(quiet or loaded is None) as progress:
        c = compare_extrinsics(T_a, T_b, loaded, settings, progress=progress)
    if out is not None:
        atomic_write_text(out, json.dumps(c.to_dict(), indent=2) + "\n")
    d = c.to_dict()["correction"]
    typer.echo(f"paretocal: B = A @ D, in A's LiDAR frame: x {d['x_cm']:+.2f} cm, y "
               f"{d['y_cm']:+.2f} cm, z {d['z_cm']:+.2f} cm, yaw {d['yaw_deg']:+.3f} deg, "
               f"pitch {d['pitch_deg']:+.3f} deg, roll {d['roll_deg']:+.3f} deg")
    typer.echo(f"paretocal: {c.rotation_deg:.3f} deg / {100 * c.translation_m:.2f} cm apart"
               + ("" if c.pixels is None else f", {c.pixels:.1f} px in the images"))
    if c.prefer is not None:
        typer.echo(f"paretocal: on {len(c.frames)} frame(s) of {source}: {c.reason}")


def _features_line(features: dict) -> str:
    """What the objective compared, in one line: the feature points per frame by group, the
    rings, and the frames whose depth edges look like noise (``stage.feature_counts``)."""
    mean = features["per_frame_mean"]
    rings = features["rings"]
    ring_text = ("no rings" if not rings else
                 f"{'/'.join(str(r) for r in rings)} rings")
    rec = features.get("ring_recovery")
    if rec:
        ring_text += f" ({', '.join(rec['methods'])}, purity >= {rec['min_purity']:.2f})"
    line = (f"features per frame: {mean['depth_edge']:g} depth edges, "
            f"{mean['intensity_edge']:g} intensity edges, {mean['smooth']:g} smooth points "
            f"in view; {ring_text}; {features['frames_contributing']} of "
            f"{len(features['per_frame'])} frames contribute")
    noise = features["noise"]
    if noise:
        line += (f"; the depth edges of {len(noise)} frame(s) look like noise (frame "
                 f"{noise[0]['frame']}: {noise[0]['reason']})")
    return line


@app.command()
def study(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    out: Annotated[Path, typer.Option("--out", help="Directory for the studies and report.html.")],
    init: Annotated[Optional[Path], typer.Option(help="Initial extrinsic (YAML/JSON with "
                                                      "T_cam_lidar); default: the dataset's.")] = None,
    frames: Frames = None,
    seed: Seed = None,
    pop: Annotated[Optional[int], typer.Option(help="Population of NSGA-II and the DE "
                                                    "(default 1000, the paper's).")] = None,
    gens: Annotated[Optional[int], typer.Option(help="Generations (default 200).")] = None,
    quick: Annotated[bool, typer.Option("--quick", help="Small budgets on a quarter of the "
                                                        "frames: a smoke test.")] = False,
    camera: CameraOrConfig = None,
    config: ConfigFile = None,
    force: Force = False,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Run the paper's studies (front, solution space, single-objective and epsilon-constraint
    checks, decision, innovization, weight robustness) and write report.html to --out."""
    import dataclasses

    from ..config import load_settings
    from ..io import load_frames
    from ..apps.study import STUDY_MARKS, StudyPlan, run_study

    from ..io.atomic import check_output_dir, check_own_folder

    setup_logging(verbose, quiet)
    check_output_dir(out)
    if not force:
        check_own_folder(out, STUDY_MARKS, "study")
    plan = StudyPlan.quick() if quick else StudyPlan()
    budgets: dict[str, Any] = {k: v for k, v in (("pop", pop), ("gens", gens)) if v is not None}
    plan = dataclasses.replace(plan, **budgets)
    if plan.pop < 4 or plan.gens < 1:
        raise SettingsError("--pop must be at least 4 and --gens at least 1")
    settings = load_settings(config).replace(search={"seed": seed})
    settings = dataclasses.replace(settings, camera=camera if camera is not None
                                   else settings.camera)
    from ..io import read_init
    T_init = read_init(init, source, settings.camera) if init is not None else None
    loaded = load_frames(source, frames, settings.camera)
    with StageProgress(quiet) as progress:
        doc = run_study(loaded, out, T_init, settings, plan, progress=progress)
    cal = doc["calibration"]
    rb = doc["robustness"]
    typer.echo(f"paretocal: study of {len(doc['frames'])} frames in "
               f"{doc['timings_s']['total']:.0f} s; chosen n = {cal['n_points']}, error vs "
               f"reference {fmt_err(cal['reference_error'])}; best w1 = {rb['best_w1']}; "
               f"wrote {out / 'report.html'}")


@app.command()
def depth(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    out: Annotated[Path, typer.Option("--out", help="Directory for the depth maps.")],
    extrinsic: Annotated[Optional[Path], typer.Option(
        help="T_cam_lidar to project with (YAML/JSON); default: the dataset's.")] = None,
    frames: Frames = None,
    camera: Camera = 2,
    max_depth: Annotated[float, typer.Option("--max-depth", help="Colour scale of the "
                                                                 "overlays (m).")] = 50.0,
    quiet: Quiet = False,
) -> None:
    """Write per frame the sparse depth map: <stem>.png (KITTI depth benchmark: uint16, metres x
    256, 0 = no return), <stem>.npy (float32 metres) and <stem>_overlay.png."""
    from ..depth import write_depth
    from ..io import load_frames

    from ..io.atomic import check_output_dir

    setup_logging(False, quiet)
    if max_depth <= 0:
        raise SettingsError("--max-depth must be positive")
    check_output_dir(out)
    loaded = load_frames(source, frames, camera)
    from ..io import read_init
    T = read_init(extrinsic, source, camera) if extrinsic is not None else loaded[0].T_ref
    if T is None:
        raise ParetocalError(f"{source}: the dataset has no extrinsic; pass --extrinsic")
    with StageProgress(quiet) as progress:
        for k, f in enumerate(loaded):
            write_depth(f, T, out, max_depth=max_depth)
            progress("depth maps", k + 1, len(loaded))
    typer.echo(f"paretocal: wrote {len(loaded)} depth maps to {out}")


@app.command()
def extract(
    bag: Annotated[Path, typer.Argument(help="ROS1 .bag, ROS2 .db3 or .mcap file, or rosbag2 "
                                             "folder.")],
    out: Annotated[Path, typer.Option("--out", help="Folder to create (the generic layout: "
                                                    "calib.yaml, images/, points/).")],
    image_topic: Annotated[Optional[str], typer.Option(
        "--image-topic", help="sensor_msgs/Image or CompressedImage (JPEG, PNG) topic; "
                              "default: the bag's only one.")] = None,
    cloud_topic: Annotated[Optional[str], typer.Option(
        "--cloud-topic", help="sensor_msgs/PointCloud2 topic; default: the bag's only "
                              "one.")] = None,
    camera_info_topic: Annotated[Optional[str], typer.Option(
        "--camera-info-topic", help="sensor_msgs/CameraInfo topic; default: the one beside "
                                    "the image topic, or the bag's only one.")] = None,
    calib: Annotated[Optional[Path], typer.Option(
        help="calib.yaml whose camera (and T_cam_lidar) to use instead of a CameraInfo.")] = None,
    init: Annotated[Optional[Path], typer.Option(
        help="Initial extrinsic (YAML/JSON with T_cam_lidar), written into calib.yaml.")] = None,
    max_dt: Annotated[Optional[float], typer.Option(
        "--max-dt", help="Pairing tolerance in seconds (default: half the median period of "
                         "the cloud stamps).")] = None,
    every: Annotated[int, typer.Option(help="Keep every K-th pair.")] = 1,
    limit: Annotated[Optional[int], typer.Option(help="Keep at most N pairs.")] = None,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Extract image-cloud pairs from a ROS bag into a generic folder (calib.yaml, images/,
    points/, extract.json) that calibrate, check, depth and study read.

    Without --image-topic or --cloud-topic, the bag's only image topic and only PointCloud2
    topic are used; when there are several, the topics are listed and the command exits 2."""
    from ..extract import REPORT, choose_topics, extract_bag
    from ..io import read_extrinsic

    setup_logging(verbose, quiet)
    if image_topic is None or cloud_topic is None:
        pick = choose_topics(bag, image_topic, cloud_topic)
        if pick.image_topic is None or pick.cloud_topic is None:
            typer.echo(f"paretocal: the topics of {bag}:\n{pick.listing}")
            raise ParetocalError(pick.missing(bag))
        typer.echo(f"paretocal: using {' and '.join(pick.chosen)} (the bag's only "
                   f"{'topic' if len(pick.chosen) == 1 else 'topics'} of "
                   f"{'that kind' if len(pick.chosen) == 1 else 'those kinds'})")
        image_topic, cloud_topic = pick.image_topic, pick.cloud_topic
    entries = _calib_entries(calib) if calib is not None else {}
    if init is not None:
        entries["T_cam_lidar"] = read_extrinsic(init)
    with StageProgress(quiet) as progress:
        r = extract_bag(bag, out, image_topic, cloud_topic, camera_info_topic, max_dt=max_dt,
                        every=every, limit=limit, calib=entries, progress=progress)
    c, dt = r["counts"], r["dt_ms"]
    skipped = f", {c['pairs_skipped']} skipped by --every/--limit" if c["pairs_skipped"] else ""
    typer.echo(f"paretocal: {c['pairs_kept']} frames from {c['images']} images and "
               f"{c['clouds']} clouds: {c['pairs_matched']} pairs within "
               f"{r['max_dt_s'] * 1e3:.4g} ms ({r['max_dt_rule']}){skipped}; dropped "
               f"{c['images_dropped']} images and {c['clouds_dropped']} clouds without a "
               f"partner; cloud - image dt {dt['min']:.3g} .. {dt['max']:.3g} ms (median "
               f"{dt['median']:.3g}); camera from {r['camera_from']}; wrote {out} "
               f"(report: {out / REPORT})")
    if r["has_extrinsic"]:
        typer.echo(f"paretocal: calib.yaml holds T_cam_lidar; next: paretocal calibrate {out} "
                   "--out RUN_DIR")
    else:
        typer.echo(f"paretocal: calib.yaml has no T_cam_lidar (no --init); next: paretocal "
                   f"calibrate {out} --init INIT.yaml --out RUN_DIR")


def _calib_entries(path: Path) -> dict:
    """The camera (and T_cam_lidar) of a --calib file, its mask made absolute."""
    from ..io.text import read_mapping

    data = read_mapping(path)
    cam = data.get("camera")
    if not isinstance(cam, dict):
        raise ParetocalError(f"{path}: --calib needs a 'camera' section")
    cam = dict(cam)
    if isinstance(cam.get("mask"), str):
        cam["mask"] = str((path.parent / cam["mask"]).resolve())
    entries: dict[str, Any] = {"camera": cam}
    if data.get("T_cam_lidar") is not None:
        from ..geometry import check_rigid

        entries["T_cam_lidar"] = check_rigid(data["T_cam_lidar"], str(path))
    return entries


@app.command()
def batch(
    manifest: Annotated[Path, typer.Argument(help="YAML or CSV manifest of entries (id, source, "
                                                  "frames, init, vehicle, camera, order).")],
    out: Annotated[Path, typer.Option("--out", help="Batch directory (runs/<id>/, summary).")],
    scheduler: Annotated[Optional[str], typer.Option(
        help="Address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786; default: a local "
             "cluster.")] = None,
    workers: Annotated[int, typer.Option(help="Worker processes of the local cluster.")] = 1,
    check: Annotated[bool, typer.Option("--check/--no-check", help="Also check each initial "
                                                                  "extrinsic.")] = True,
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="PNG figures per run.")] = False,
    pop: Annotated[Optional[int], typer.Option(help="Population size.")] = None,
    gens: Annotated[Optional[int], typer.Option(help="Generations.")] = None,
    seed: Seed = None,
    config: ConfigFile = None,
    force: Force = False,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Calibrate every entry of MANIFEST as a task on Dask; skip entries already done (ok
    with the same entry and settings).

    Exit status: 0 when every entry is ok or already done; 4 when any entry failed (the
    others still run; summary.csv gives each reason); 2 for a bad manifest or option; 130
    when interrupted (Ctrl-C or SIGTERM), after writing the summary of what is done: rerun the
    same command to continue.
    """
    from ..apps.batch import BATCH_MARKS, BatchInterrupted, run_batch
    from ..config import load_settings, states_init_error

    from ..io.atomic import check_output_dir, check_own_folder

    setup_logging(verbose, quiet)
    if workers < 1:
        raise SettingsError("--workers must be at least 1")
    check_output_dir(out)
    if not force:
        check_own_folder(out, BATCH_MARKS, "batch")
    settings = load_settings(config).replace(search={"pop": pop, "gens": gens, "seed": seed})
    settings.validate()
    try:
        with StageProgress(quiet) as progress:
            r = run_batch(manifest, out, settings, scheduler, workers, check, figures,
                          progress=lambda d, t: progress("entries", d, t),
                          dataset_options=not states_init_error(config))
    except BatchInterrupted as exc:
        report(f"paretocal: batch interrupted: {exc.done} of {exc.total} entries done "
               f"(summary so far in {exc.summary}); rerun the same command to continue")
        raise typer.Exit(130) from None
    rate = f", {r['entries_per_minute']:.2f} entries/min" if r["entries_per_minute"] else ""
    typer.echo(f"paretocal: {r['entries']} entries: {r['ok']} ok, {r['failed']} failed, "
               f"{r['skipped']} already done{rate}; wrote {out / 'summary.csv'}")
    if r["failed"]:
        print(f"paretocal: {r['failed']} of {r['entries']} entries failed; the reasons are in "
              f"{out / 'summary.csv'}", file=sys.stderr)
        raise typer.Exit(BATCH_FAILED_EXIT)


#: Exit status of ``batch`` when at least one entry failed.
BATCH_FAILED_EXIT = 4


#: The option parser's usage errors: click's, and those of the click that recent typer
#: releases carry inside (``typer.BadParameter`` and its kin derive from TyperException there).
_USAGE_ERRORS = tuple({click.ClickException,
                       getattr(typer.exceptions, "TyperException", click.ClickException)})


#: What an interrupted command leaves behind, when the command has not said it itself
#: (calibrate and batch say more once their work has started).
_INTERRUPTED = {
    "calibrate": "interrupted before the run started; nothing was written; run the same "
                 "command again",
    "check": "interrupted; nothing was written; run the same command again",
    "perturb": "interrupted; nothing was written; run the same command again",
    "depth": "interrupted; the depth maps already in --out are whole files, the others are "
             "missing; run the same command again",
    "study": "interrupted; the study is incomplete (no report.html); run the same command again",
    "extract": "interrupted; nothing was written to --out (the partial extraction was "
               "removed); run the same command again",
}


#: The SIGINT and SIGTERM handler that :func:`main` installs.
_STOP = STOP_HANDLER
#: The progress display under its name from before (the tests use it).
_Progress = StageProgress


def _interrupted(command: str | None) -> int:
    if not _STOP.reported:
        default = "interrupted; run the command again"
        said = default if command is None else _INTERRUPTED.get(command, default)
        report(f"paretocal: {said}")
    return 130


def main(argv: list[str] | None = None, final: bool = False) -> int:
    """Entry point of the ``paretocal`` console script; returns the exit status.

    ``final``: the process exits right after (the console script): SIGINT and SIGTERM are then
    left ignored instead of restored, so a late second Ctrl-C cannot interrupt the exit."""
    import signal
    import threading

    args = sys.argv[1:] if argv is None else list(argv)
    verbose = "--verbose" in args or "-v" in args
    name = next((a for a in args if not a.startswith("-")), None)
    _STOP.signals, _STOP.reported = 0, False
    STOP.clear()
    # SIGTERM stops a run the way Ctrl-C does: checkpoint kept, partial front written.
    main_thread = threading.current_thread() is threading.main_thread()
    # A signal ignored when the process started (a background job of a shell, nohup) stays
    # ignored, as Python itself does for SIGINT.
    previous = ({sig: signal.signal(sig, _STOP) for sig in (signal.SIGINT, signal.SIGTERM)
                 if signal.getsignal(sig) is not signal.SIG_IGN} if main_thread else {})
    unraisable, sys.unraisablehook = sys.unraisablehook, _quiet_stops(sys.unraisablehook)
    try:
        command = typer.main.get_command(app)
        rv = command.main(args=args, prog_name="paretocal", standalone_mode=False)
        # typer turns KeyboardInterrupt into exit status 130 itself.
        return _interrupted(name) if rv == 130 else int(rv) if isinstance(rv, int) else 0
    except ParetocalError as exc:
        # One line, whatever the message holds (control characters escaped, length bounded).
        print(f"paretocal: error: {excerpt(exc, MESSAGE_CHARS)}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, typer.Abort, click.exceptions.Abort):
        return _interrupted(name)
    except (typer.Exit, click.exceptions.Exit) as exc:
        return _interrupted(name) if exc.exit_code == 130 else int(exc.exit_code)
    except _USAGE_ERRORS as exc:
        # A usage error from the option parser (unknown option, bad value, ...).
        text = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        if text.strip():              # no command at all: the help was shown, nothing to add
            print(f"paretocal: error: {' '.join(text.split())}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - the last line of defence
        if STOP.requested:
            # The user's stop, wrapped by code it interrupted (a compiled function's
            # dispatch turns it into SystemError): an interrupt, not an error.
            return _interrupted(name)
        if verbose:
            import traceback

            traceback.print_exc()
        print(f"paretocal: unexpected error: {type(exc).__name__}: "
              f"{excerpt(exc, MESSAGE_CHARS)} (rerun with --verbose for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        sys.unraisablehook = unraisable
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_IGN if final else handler)


def _quiet_stops(hook):
    """``sys.unraisablehook`` that stays silent about the stop signal's KeyboardInterrupt.

    Raised while Python runs a callback from C (numba's compiler cache is one), the exception
    cannot propagate and would be printed with a traceback; the stop itself is not lost
    (``errors.STOP``: the run stops at its next phase or generation)."""
    def quiet(unraisable):
        if not (isinstance(unraisable.exc_type, type)
                and issubclass(unraisable.exc_type, KeyboardInterrupt)):
            hook(unraisable)
    return quiet

