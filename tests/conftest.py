"""Shared fixtures: the real KITTI sample frames (read where they are) and synthetic scenes."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Measured cost models are kept in a folder of this test session, not the user's cache
    (subprocesses of the CLI inherit it)."""
    import tempfile

    if "PARETOCAL_CACHE_DIR" not in os.environ:
        os.environ["PARETOCAL_CACHE_DIR"] = tempfile.mkdtemp(prefix="paretocal-cache-")


def data_dir() -> Path:
    """``$PARETOCAL_DATA`` or ``../shared/data`` beside the project (the documented default)."""
    return Path(os.environ.get("PARETOCAL_DATA", ROOT.parent / "shared" / "data")).resolve()


@pytest.fixture(scope="session")
def data() -> Path:
    d = data_dir()
    if not (d / "kitti_raw").is_dir():
        pytest.fail(f"sample data not found at {d}; set PARETOCAL_DATA to the folder holding "
                    "kitti_raw/ and kitti_object/")
    return d


@pytest.fixture(scope="session")
def raw_date(data) -> Path:
    return data / "kitti_raw" / "2011_09_26"


@pytest.fixture(scope="session")
def raw_frames(raw_date):
    from paretocal.io import load_frames

    return load_frames(raw_date)


@pytest.fixture(scope="session")
def object_dir(data) -> Path:
    return data / "kitti_object" / "training"


@pytest.fixture(scope="session")
def pandaset_00(data):
    """The points (N, 4) of PandaSet's frame 00, in its vehicle-like frame L: the car stands in a
    traffic jam, the road holds about 15 % of the returns within 40 m."""
    from paretocal.io import load_frames

    root = data / "pandaset" / "front"
    if not (root / "calib.yaml").is_file():
        pytest.skip("PandaSet sample not present")
    return load_frames(root, "0")[0].points


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(autouse=True)
def _fresh_paretocal_logger():
    """Every test starts with the library logger as importing it leaves it: the CLI's
    ``_setup_logging`` stops propagation to the root logger, which would hide later tests'
    records from ``caplog``."""
    log = logging.getLogger("paretocal")
    log.handlers[:] = []
    log.propagate = True
    log.setLevel(logging.NOTSET)
    yield
