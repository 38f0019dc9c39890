"""``paretocal batch``: every entry of a manifest calibrated as a task on Dask."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..errors import SettingsError
from . import app
from ._common import StageProgress, report, setup_logging
from .options import ConfigFile, Force, Gens, Pop, Quiet, Seed, Verbose, output_path


@app.command()
def batch(
    manifest: Annotated[Path, typer.Argument(help="YAML or CSV manifest of entries (id, source, "
                                                  "frames, init, vehicle, camera, order).")],
    out: Annotated[Path, typer.Option(
        "--out", parser=output_path, metavar="PATH", help="Batch directory (runs/<id>/, summary).")],
    scheduler: Annotated[Optional[str], typer.Option(
        help="Address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786; default: a local "
             "cluster.")] = None,
    workers: Annotated[int, typer.Option(help="Worker processes of the local cluster.")] = 1,
    check: Annotated[bool, typer.Option("--check/--no-check", help="Also check each initial "
                                                                  "extrinsic.")] = True,
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="PNG figures per run.")] = False,
    pop: Pop = None,
    gens: Gens = None,
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
