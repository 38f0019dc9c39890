"""``paretocal extract``: image-cloud pairs from a ROS bag into a generic dataset folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from ..errors import ParetocalError
from . import app
from ._common import StageProgress, setup_logging
from .options import Quiet, Verbose, output_path


@app.command()
def extract(
    bag: Annotated[Path, typer.Argument(help="ROS1 .bag, ROS2 .db3 or .mcap file, or rosbag2 "
                                             "folder.")],
    out: Annotated[Path, typer.Option(
        "--out", parser=output_path,
        help="Folder to create (the generic layout: calib.yaml, images/, points/).")],
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
