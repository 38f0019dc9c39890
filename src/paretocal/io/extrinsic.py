"""Reading and writing a lone extrinsic (``--init`` files, ``extrinsic.yaml``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError
from ..geometry import check_rigid
from .atomic import atomic_write_text
from .readers import read_mapping


def read_extrinsic(path: str | Path) -> np.ndarray:
    """Read ``T_cam_lidar`` (4x4, LiDAR -> camera) from a YAML or JSON file.

    Raises :class:`InputError` naming the file when the key is missing or the matrix is not a
    finite rigid transform.
    """
    path = Path(path)
    data = read_mapping(path)
    if "T_cam_lidar" not in data:
        raise InputError(f"{path}: missing key 'T_cam_lidar'")
    return check_rigid(data["T_cam_lidar"], str(path))


def extrinsic_yaml(T: np.ndarray, comment: str = "") -> str:
    """YAML text holding ``T_cam_lidar`` alone, readable by :func:`read_extrinsic`."""
    rows = [[float(f"{v:.10g}") for v in row] for row in np.asarray(T, dtype=np.float64)]
    head = "".join(f"# {line}\n" for line in comment.splitlines()) if comment else ""
    return head + yaml.safe_dump({"T_cam_lidar": rows}, default_flow_style=None, sort_keys=False)


def write_extrinsic(path: str | Path, T: np.ndarray, comment: str = "") -> None:
    """Write ``T_cam_lidar`` to a YAML file atomically."""
    atomic_write_text(Path(path), extrinsic_yaml(T, comment))
