"""``paretocal calibrate``: a dataset's camera into a run folder (:mod:`.run`), a rig folder's
cameras (:mod:`.rig`), or an interrupted run continued (``--resume``)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional, cast

import typer

from ..errors import SettingsError
from . import app
from ._common import setup_logging
from .options import (CameraOrName, ConfigFile, Force, Frames, Gens, Pop, Quiet, Seed,
                      Verbose, camera_index, output_path)
from .rig import calibrate_rig_folder
from .run import check_run_out, continue_run, run_calibration


def _choices(section: str, name: str, cls: str) -> type[Enum]:
    """The command line's choices of a setting, from the one list in the configuration."""
    from ..config import CHOICES

    # Enum's functional API makes a class; mypy reads a call with a computed name as a member.
    return cast(type[Enum],
                Enum(cls, [(v.replace("-", "_"), v) for v in CHOICES[(section, name)]], type=str))


if TYPE_CHECKING:
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


@app.command()
def calibrate(
    source: Annotated[Optional[Path], typer.Argument(
        help="Dataset folder: KITTI raw drive or date folder, KITTI object 'training', or a "
             "generic folder (not needed with --resume); for a ROS bag, run paretocal extract "
             "first.")] = None,
    out: Annotated[Optional[Path], typer.Option(
        "--out", parser=output_path, metavar="PATH", help="Run directory to write.")] = None,
    resume: Annotated[Optional[Path], typer.Option(
        parser=output_path, metavar="PATH",
        help="Continue the interrupted run in this run directory (same data, start and "
             "settings; the result equals an uninterrupted run).")] = None,
    checkpoint_every: Annotated[int, typer.Option(
        "--checkpoint-every", help="Save the search state every N generations (0: never).")] = 5,
    init: Annotated[Optional[Path], typer.Option(help="Initial extrinsic (YAML/JSON with "
                                                      "T_cam_lidar); default: the dataset's.")] = None,
    frames: Frames = None,
    seed: Seed = None,
    pop: Pop = None,
    gens: Gens = None,
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
        return continue_run(resume, verbose, quiet, checkpoint_every, strict)
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
        return calibrate_rig_folder(source, out, init, camera, frames, settings, adopt,
                                    figures, quiet, checkpoint_every, strict, force, joint)
    if joint:
        raise SettingsError(f"--joint: {source} is not a rig folder (calib.yaml with cameras:)")
    index = camera_index(camera) if camera is not None else None
    if index is not None or frames is not None:
        settings = dataclasses.replace(settings, camera=index if index is not None
                                       else settings.camera,
                                       frames=frames if frames is not None else settings.frames)
    settings.validate()
    # Detected once: its warnings are said once.
    detected = detect_source(Path(source), settings.camera)
    check_run_out(out, force)
    from ..io import read_init
    T_init = read_init(init, detected, settings.camera) if init is not None else None
    loaded = load_frames(detected, settings.frames, settings.camera)
    run_calibration(loaded, source, T_init, settings, out, figures, quiet, checkpoint_every,
                    strict, dataset_options=adopt)

