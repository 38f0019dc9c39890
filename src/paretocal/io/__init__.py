"""Input layouts, file readers and the extrinsic file formats (the input edge of the pipeline)."""

from .extrinsic import read_extrinsic, read_init, write_extrinsic
from .frame import Frame
from .layouts import (detect_source, is_rig, load_frames, load_rig_frames, rig_cameras,
                      rig_source, select_frames, source_options)

__all__ = ["Frame", "detect_source", "is_rig", "load_frames", "load_rig_frames", "read_extrinsic",
           "read_init", "rig_cameras", "rig_source", "select_frames", "source_options",
           "write_extrinsic"]
