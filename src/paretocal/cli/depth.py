"""``paretocal depth``: a dataset's sparse depth maps under an extrinsic."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..errors import ParetocalError, SettingsError
from . import app
from ._common import StageProgress, setup_logging
from .options import Camera, Frames, Quiet, one_camera, output_path


@app.command()
def depth(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    out: Annotated[Path, typer.Option(
        "--out", parser=output_path, metavar="PATH", help="Directory for the depth maps.")],
    extrinsic: Annotated[Optional[Path], typer.Option(
        help="T_cam_lidar to project with (YAML/JSON); default: the dataset's.")] = None,
    frames: Frames = None,
    camera: Camera = None,
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
    src, index = one_camera(source, camera)
    loaded = load_frames(src, frames, index)
    from ..io import read_init
    T = read_init(extrinsic, src, index) if extrinsic is not None else loaded[0].T_ref
    if T is None:
        raise ParetocalError(f"{source}: the dataset has no extrinsic; pass --extrinsic")
    with StageProgress(quiet) as progress:
        for k, f in enumerate(loaded):
            write_depth(f, T, out, max_depth=max_depth)
            progress("depth maps", k + 1, len(loaded))
    typer.echo(f"paretocal: wrote {len(loaded)} depth maps to {out}")
