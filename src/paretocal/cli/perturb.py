"""``paretocal perturb``: a decalibrated copy of a dataset's extrinsic, as an --init file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import ParetocalError, SettingsError
from . import app
from ._common import fmt_err
from .options import Camera, one_camera, output_path


@app.command()
def perturb(
    source: Annotated[Path, typer.Argument(help="Dataset whose own extrinsic is perturbed.")],
    out: Annotated[Path, typer.Option(
        "--out", parser=output_path, metavar="PATH", help="YAML file to write (an --init file).")],
    rot: Annotated[float, typer.Option(help="Per-axis rotation bound (+- deg).")] = 5.0,
    trans: Annotated[float, typer.Option(help="Per-axis translation bound (+- m).")] = 0.2,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    camera: Camera = None,
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
    chosen, index = one_camera(source, camera)
    src = detect_source(chosen, index) if isinstance(chosen, Path) else chosen
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
