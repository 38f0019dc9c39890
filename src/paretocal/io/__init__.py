"""Input layouts, file readers and the extrinsic file formats (the input edge of the pipeline)."""

from .extrinsic import read_extrinsic, write_extrinsic
from .frame import Frame
from .layouts import detect_source, load_frames, select_frames

__all__ = ["Frame", "detect_source", "load_frames", "read_extrinsic", "select_frames",
           "write_extrinsic"]
