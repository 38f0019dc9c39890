"""``paretocal compare``: two extrinsics against each other, and which one a dataset prefers."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..errors import InputError, SettingsError
from . import app
from ._common import StageProgress, setup_logging
from .options import Camera, ConfigFile, Frames, Quiet, Verbose, one_camera, output_path


@app.command()
def compare(
    a: Annotated[Path, typer.Argument(help="Extrinsic A (any --init form: YAML/JSON with "
                                           "T_cam_lidar, a result.json, a KITTI calibration "
                                           "file with SOURCE).")],
    b: Annotated[Path, typer.Argument(help="Extrinsic B, in any of the same forms.")],
    source: Annotated[Optional[Path], typer.Argument(
        help="Dataset folder: also say which of the two its frames prefer.")] = None,
    frames: Frames = None,
    camera: Camera = None,
    out: Annotated[Optional[Path], typer.Option(
        parser=output_path, metavar="PATH", help="Write the comparison (JSON) here.")] = None,
    page: Annotated[Optional[Path], typer.Option(
        parser=output_path, metavar="PATH",
        help="With SOURCE: write a page (HTML) showing every frame with both extrinsics' "
             "projections, to judge by eye.")] = None,
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
    if page is not None and source is None:
        raise SettingsError("--page needs SOURCE: the page shows its frames")
    for path in (out, page):
        if path is not None:
            check_output_file(path)
    settings = load_settings(config)
    for path in (a, b):
        if source is None and needs_kitti_rect(path):
            raise InputError(f"{path}: holds KITTI's Tr_velo_to_cam (LiDAR -> unrectified "
                             "camera 0); pass the KITTI SOURCE it belongs to, whose "
                             "rectification turns it into T_cam_lidar")
    src, index = one_camera(source, camera)
    loaded = load_frames(src, frames, index) if src is not None else None
    T_a = read_init(a, loaded, index)
    T_b = read_init(b, loaded, index)
    with StageProgress(quiet or loaded is None) as progress:
        c = compare_extrinsics(T_a, T_b, loaded, settings, progress=progress)
    if out is not None:
        atomic_write_text(out, json.dumps(c.to_dict(), indent=2) + "\n")
    if page is not None:
        from ..report.interactive import write_comparison

        write_comparison(c, list(c.sweeps), settings, page)
    typer.echo(f"paretocal: B = A @ D, in A's LiDAR frame: {c.axes_text()}")
    typer.echo(f"paretocal: {c.rotation_deg:.3f} deg / {100 * c.translation_m:.2f} cm apart"
               + ("" if c.pixels is None else f", {c.pixels:.1f} px in the images"))
    if c.prefer is not None:
        typer.echo(f"paretocal: on {len(c.frames)} frame(s) of {source}: {c.reason}")
