"""``calibrate`` on a rig folder (calib.yaml with ``cameras:``): each camera into a run folder
of its own and rig.json, or all of them at once with ``--joint``."""

from __future__ import annotations

from pathlib import Path

import typer

from ..errors import SettingsError
from ._common import StageProgress, fmt_err, report
from .run import STRICT_EXIT, check_run_out, interrupted_line


def calibrate_rig_folder(source: Path, out: Path, init, camera: str | None,  # noqa: PLR0913
                         frames, settings, dataset_options: bool, figures: bool, quiet: bool,
                         checkpoint_every: int, strict: bool, force: bool,
                         joint: bool = False) -> None:
    """``calibrate`` on a rig folder: every camera (or ``--camera NAME``) into ``out/NAME/``
    and ``out/rig.json``, or with ``joint`` all cameras at once into ``out/joint/``
    (:mod:`paretocal.apps.rig`)."""
    import dataclasses

    from ..errors import Interrupted
    from ..io import rig_cameras
    from ..io.atomic import check_output_dir, check_own_folder
    from ..apps.rig import JOINT_RUN, RIG_JSON, RUN_FOLDER, calibrate_rig, pair_line
    from ..rundir import check_inner_run_folder

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
        check_inner_run_folder(out / name, RUN_FOLDER)
        check_run_out(out / name, force)
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
