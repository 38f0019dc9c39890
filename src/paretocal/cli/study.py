"""``paretocal study``: the paper's studies on a dataset, and report.html."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from ..errors import SettingsError
from . import app
from ._common import StageProgress, fmt_err, setup_logging
from .options import CameraOrConfig, ConfigFile, Force, Frames, Quiet, Seed, Verbose, output_path


@app.command()
def study(
    source: Annotated[Path, typer.Argument(help="Dataset folder (any supported layout).")],
    out: Annotated[Path, typer.Option(
        "--out", parser=output_path, metavar="PATH", help="Directory for the studies and report.html.")],
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

    from ..config import load_settings, states_init_error
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
        doc = run_study(loaded, out, T_init, settings, plan, progress=progress,
                        dataset_options=not states_init_error(config))
    cal = doc["calibration"]
    rb = doc["robustness"]
    typer.echo(f"paretocal: study of {len(doc['frames'])} frames in "
               f"{doc['timings_s']['total']:.0f} s; chosen n = {cal['n_points']}, error vs "
               f"reference {fmt_err(cal['reference_error'])}; best w1 = {rb['best_w1']}; "
               f"wrote {out / 'report.html'}")
