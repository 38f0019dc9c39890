"""Options shared by several commands, declared once."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

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
CameraOrName = Annotated[Optional[str], typer.Option(
    "--camera", help="KITTI camera index 0-3 (default 2), or the name of one camera of a rig "
                     "folder (calib.yaml with cameras:).")]
#: The camera of a command that reads one: as ``calibrate --camera`` takes it.
Camera = CameraOrName


def _search_defaults() -> tuple[int, int]:
    """The search's default population and generations (config: the one place they are set)."""
    from ..config import SearchSettings

    s = SearchSettings()
    return s.pop, s.gens


_POP, _GENS = _search_defaults()
Pop = Annotated[Optional[int], typer.Option(
    help=f"Population size (default {_POP}, or the --config file's).")]
Gens = Annotated[Optional[int], typer.Option(
    help=f"Generations (default {_GENS}, or the --config file's).")]


def camera_index(text: str | None) -> int:
    """``--camera`` of a single-camera source: a KITTI camera index (2 when not given)."""
    from ..errors import SettingsError

    if text is None:
        return 2
    try:
        return int(text)
    except ValueError:
        raise SettingsError(f"--camera {text}: a KITTI camera index 0-3; camera names apply "
                            "to a rig folder (calib.yaml with cameras:)") from None


def one_camera(source: Path | None, camera: str | None) -> tuple[Any, int]:
    """``--camera`` of a command that reads one camera of ``source``: a KITTI camera index or,
    for a rig folder, the name of one of its cameras (which it then needs). Returns what to
    read the frames from (the folder, or that camera's source) and the KITTI camera index."""
    from ..errors import SettingsError
    from ..io import is_rig, rig_cameras, rig_source

    if source is not None and is_rig(source):
        if camera is None:
            names = ", ".join(n for n, _ in rig_cameras(source))
            raise SettingsError(f"{source}: a rig folder (calib.yaml with cameras:); name the "
                                f"camera with --camera ({names})")
        return rig_source(source, camera), 2
    return source, camera_index(camera)
