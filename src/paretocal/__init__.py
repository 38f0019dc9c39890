"""paretocal: targetless camera-LiDAR extrinsic calibration as a Pareto search.

The pipeline reads frames, extracts image and LiDAR edge features, and searches the 6-DoF
correction of an initial extrinsic together with the number of LiDAR points used, minimising
an alignment error and the computational cost of evaluating it (NSGA-II). A knee point (or the
best solution within a time budget) is chosen from the resulting Pareto front.

Quick use::

    from paretocal import calibrate, load_frames, read_extrinsic
    frames = load_frames("path/to/2011_09_26_drive_0001_sync")
    result = calibrate(frames, T_init=read_extrinsic("init.yaml"))
    print(result.T_cam_lidar, result.reference_error)
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("paretocal")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"

from .config import Settings, load_settings  # noqa: E402
from .errors import ParetocalError  # noqa: E402
from .io import load_frames, read_extrinsic, write_extrinsic  # noqa: E402
from .pipeline import CalibrationResult, calibrate  # noqa: E402

__all__ = ["CalibrationResult", "ParetocalError", "Settings", "__version__", "calibrate",
           "load_frames", "load_settings", "read_extrinsic", "write_extrinsic"]
