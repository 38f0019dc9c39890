"""Options shared by several commands, declared once."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer


def output_path(text: str) -> Path:
    """The value of an option that names where to write (``--out``, ``--resume``, ``--page``):
    an empty one is refused, as ``Path("")`` is the current folder, which would be written
    into unnoticed (``--out ''`` from an unset shell variable)."""
    if text == "":
        raise typer.BadParameter("the path is empty (it would be the current folder; give . if "
                                 "that is meant)")
    return Path(text)


Verbose = Annotated[bool, typer.Option("--verbose", "-v", help="More log output.")]
Force = Annotated[bool, typer.Option(
    "--force", help="Write into --out even when it is a folder of other files (those of the "
                    "same names are replaced).")]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="Errors only.")]
Frames = Annotated[Optional[str], typer.Option("--frames", help="Frames: '0:10', '0,3,7' or stems.")]
ConfigFile = Annotated[Optional[Path], typer.Option("--config",
                                                    help="Settings file (YAML/JSON) by section.")]
Seed = Annotated[Optional[int], typer.Option("--seed", help="Random seed (default 0).")]
CameraOrConfig = Annotated[Optional[int], typer.Option(
    "--camera", help="KITTI camera index 0-3 (default 2).")]
Camera = Annotated[int, typer.Option("--camera", help="KITTI camera index 0-3.")]
CameraOrName = Annotated[Optional[str], typer.Option(
    "--camera", help="KITTI camera index 0-3 (default 2), or the name of one camera of a rig "
                     "folder (calib.yaml with cameras:).")]
