"""benchmarks/basin.py: the objective's basin at a pose, measured without a search."""

from __future__ import annotations

import numpy as np
import pytest

from paretocal.config import Settings
from paretocal.geometry import correction_matrix

from .helpers import load_benchmark


@pytest.fixture(scope="module")
def basin_bench():
    return load_benchmark("basin")


def test_the_basin_is_at_the_reference_and_not_at_a_pose_beside_it(basin_bench, raw_frames):
    """On the KITTI drive the objective's optimum lies next to the reference and few grid
    neighbours beat it; at a pose 1.5 deg off in yaw the optimum lies about that far away and
    many neighbours beat it (the figures can tell a basin from a pose beside it)."""
    frames = raw_frames[::4]
    T = frames[0].T_ref
    at = basin_bench.basin(frames, T, Settings())
    assert at["deg"] < 0.4 and at["cm"] < 4 and at["better"] <= 0.05
    assert at["centre_deg"] < 0.4 and at["centre_cm"] < 4 and at["spread_cm"] < 4
    assert set(at["points_per_frame"]) == {"depth_edge", "intensity_edge", "smooth"}
    off = basin_bench.basin(frames, T @ correction_matrix([0, 0, 0, 1.5, 0, 0]), Settings())
    assert 1.0 < off["deg"] < 2.0 and off["better"] > 0.2
    assert abs(off["correction"][3] + 1.5) < 0.4 and np.isfinite(off["px"])


def test_cameras_measured_at_once_share_one_correction(basin_bench, raw_frames):
    """One camera given twice is that camera's basin (the sum doubles the objective: Newton
    steps and comparisons do not change); two cameras both 1.5 deg off in yaw are corrected
    together by one shared correction of -1.5 deg."""
    frames = raw_frames[::4]
    T = frames[0].T_ref
    one = basin_bench.basin(frames, T, Settings())
    twice = basin_bench.joint_basin([(frames, T, None), (frames, T, None)], Settings())
    assert np.allclose(twice["correction"], one["correction"], atol=1e-4)
    alone = basin_bench.joint_basin([(frames, T, None)], Settings())
    assert np.isclose(twice["value"], 2 * alone["value"])
    assert twice["deg"] < 0.4 and twice["cm"] < 4 and twice["better"] <= 0.05
    T_off = T @ correction_matrix([0, 0, 0, 1.5, 0, 0])
    both = basin_bench.joint_basin([(frames, T_off, None), (frames[1:], T_off, None)],
                                   Settings())
    assert abs(both["correction"][3] + 1.5) < 0.4 and 1.0 < both["deg"] < 2.0


def test_the_table_has_a_row_per_set_and_group(basin_bench):
    row = {"deg": 0.1, "cm": 1.0, "px": 2.0, "better": 0.01, "centre_deg": 0.12,
           "centre_cm": 1.1, "spread_deg": 0.05, "spread_cm": 0.5, "correction": [0] * 6,
           "points_per_frame": {}}
    text = basin_bench.table({"a": {"frames": 3, "groups": {"all": row, "depth": row}}})
    lines = text.splitlines()
    assert len(lines) == 4 and lines[2].startswith(
        "| a | 3 | all | 0.10 | 1.0 | 2.0 | 0.12 / 1.1 | 0.05 / 0.5 |")
