"""paretocal: targetless camera-LiDAR extrinsic calibration as a Pareto search.

The pipeline reads frames, extracts image and LiDAR edge features, and searches the 6-DoF
correction of an initial extrinsic together with the number of LiDAR points used, minimising
an alignment error and the computational cost of evaluating it (NSGA-II). A knee point (or the
best solution within a time budget) is chosen from the resulting Pareto front.

Quick use::

    from paretocal import calibrate, load_frames, read_extrinsic, write_run
    frames = load_frames("path/to/2011_09_26_drive_0001_sync", frames="0:20")
    result = calibrate(frames, T_init=read_extrinsic("init.yaml"))
    print(result.T_cam_lidar, result.n_points, result.reference_error)
    write_run(result, "runs/0001", frames)          # the files `paretocal calibrate` writes

The other commands have their functions too: :func:`check_extrinsic` (``paretocal check``),
:func:`run_study` (``paretocal study``), :func:`write_depth` / :func:`depth_map`
(``paretocal depth``), :func:`extract_bag` (``paretocal extract``). Every array is numpy;
transforms are 4x4 ``T_cam_lidar`` (LiDAR -> camera, metres); angles in files and results are
degrees.
"""

# Nothing is imported here: the command line's start-up (python -m paretocal, the console
# script) runs this module before paretocal.__main__ can install its signal handlers, so it must
# take no time. __version__ too is looked up on first use (importlib.metadata takes 20 ms).

#: Public names and the modules that define them, imported on first use (PEP 562) so that
#: ``import paretocal.cli`` stays light: the command line answers --help and interrupts at once.
_LAZY = {"check_extrinsic": "check", "Settings": "config", "load_settings": "config",
         "depth_map": "depth", "write_depth": "depth", "ParetocalError": "errors",
         "extract_bag": "extract",
         "load_frames": "io", "read_extrinsic": "io", "read_init": "io", "write_extrinsic": "io",
         "write_run": "rundir", "CalibrationResult": "pipeline",
         "calibrate": "pipeline", "calibrate_run": "rundir", "resume_run": "rundir",
         "StudyPlan": "apps.study", "run_study": "apps.study",
         "run_batch": "apps.batch", "calibrate_rig": "apps.rig"}


def __getattr__(name: str):
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("paretocal")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            value = "0.0.0"
        globals()[name] = value
        return value
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | {"__version__"})


__all__ = ["CalibrationResult", "ParetocalError", "Settings", "StudyPlan", "__version__",
           "calibrate", "calibrate_rig", "calibrate_run", "check_extrinsic", "depth_map",
           "extract_bag", "load_frames", "load_settings", "read_extrinsic", "read_init", "resume_run",
           "run_batch", "run_study", "write_depth", "write_extrinsic", "write_run"]
