"""Test helpers: generic-layout folders built from real frames, synthetic scenes."""

from __future__ import annotations

import importlib.util
import re
import signal
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml


def write_generic(root: Path, frames, suffix: str = ".bin", D=None, with_T: bool = True) -> Path:
    """A generic-layout folder (docs/conventions.md section 2c) holding copies of ``frames`` in a temp dir."""
    (root / "images").mkdir(parents=True, exist_ok=True)
    (root / "points").mkdir(parents=True, exist_ok=True)
    f0 = frames[0]
    calib = {"camera": {"K": f0.camera.K.tolist(), "width": f0.camera.width,
                        "height": f0.camera.height}}
    if D is not None:
        calib["camera"]["D"] = list(map(float, D))
    if with_T:
        calib["T_cam_lidar"] = f0.T_ref.tolist()
    (root / "calib.yaml").write_text(yaml.safe_dump(calib))
    for f in frames:
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), f.image)
        if suffix == ".bin":
            f.points.astype(np.float32).tofile(root / "points" / f"{f.name}.bin")
        else:
            np.save(root / "points" / f"{f.name}.npy", f.points)
    return root


def box_scene(rng, width=640, height=480, f=500.0):
    """A synthetic camera looking at a box in front of a wall.

    Returns (camera K, image (H, W, 3) uint8, LiDAR points (N, 4) in scan order with 32 rings,
    T_cam_lidar). LiDAR axes are KITTI's (x forward, y left, z up); the camera sits at the
    LiDAR origin. The wall is 20 m ahead; the box spans y in [-1, 1] m and z in [-1, 0.5] m at
    8 m.
    """
    K = np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]        # LiDAR -> camera axes
    pts = []
    for el in np.linspace(-12, 8, 32):                      # one ring per elevation, top first
        az = np.radians(np.arange(0, 360, 0.2))
        d = np.stack([np.cos(np.radians(el)) * np.cos(az), np.cos(np.radians(el)) * np.sin(az),
                      np.full_like(az, np.sin(np.radians(el)))], 1)
        r = np.full(len(az), np.inf)
        fwd = d[:, 0] > 0.1
        r_wall = np.where(fwd, 20.0 / np.maximum(d[:, 0], 1e-9), np.inf)
        r_box = np.where(fwd, 8.0 / np.maximum(d[:, 0], 1e-9), np.inf)
        hit = r_box[:, None] * d
        inbox = fwd & (np.abs(hit[:, 1]) <= 1.0) & (hit[:, 2] >= -1.0) & (hit[:, 2] <= 0.5)
        r = np.where(inbox, r_box, r_wall)
        keep = np.isfinite(r) & (r < 60)
        p = d[keep] * r[keep, None]
        refl = np.where(inbox[keep], 0.8, 0.2)
        pts.append(np.column_stack([p, refl]))
    points = np.vstack(pts).astype(np.float32)
    # Render the box silhouette as a bright rectangle on a dark wall.
    img = np.full((height, width, 3), 40, np.uint8)
    corners = np.array([[8, 1, 0.5], [8, -1, -1.0]])
    cam = corners @ T[:3, :3].T
    uv = (cam @ K.T)[:, :2] / cam[:, 2:3]
    (u0, v0), (u1, v1) = np.round(uv).astype(int)
    img[v0:v1 + 1, u0:u1 + 1] = 220
    return K, img, points, T


def run_cli(capfd, *args):
    """The command line in this process: ``(exit status, stdout, stderr)``."""
    from paretocal.cli import main

    code = main([str(a) for a in args])
    out, err = capfd.readouterr()
    return code, out, err


#: A progress line of a command whose stderr is not a terminal: the time since it started,
#: then the stage (paretocal.cli._Progress).
PROGRESS_LINE = re.compile(r"^paretocal: +\d+\.\d s  \S")


def without_progress(err: str) -> list[str]:
    """The lines of ``err`` after the progress lines, which must all come first."""
    lines = err.strip().splitlines()
    progress = [bool(PROGRESS_LINE.match(line)) for line in lines]
    assert progress == sorted(progress, reverse=True), err        # progress lines first
    return [line for line, p in zip(lines, progress) if not p]


def bad_cli(capfd, *args, expect: str | tuple[str, ...]) -> str:
    """Run the CLI; assert exit 2 and exactly one line on stderr (after any progress lines)
    holding every ``expect`` (and no traceback); returns the line."""
    code, out, err = run_cli(capfd, *args)
    assert code == 2, (code, out, err)
    lines = without_progress(err)
    assert len(lines) == 1 and lines[0].startswith("paretocal: error: "), err
    for e in (expect,) if isinstance(expect, str) else expect:
        assert e in lines[0], lines[0]
    assert "Traceback" not in err
    return lines[0]


def run_with_stdout_closed(*args, timeout: float = 600) -> tuple[int, str]:
    """The console script (``python -m paretocal``) in a child process whose stdout is a pipe
    its reader closed before anything was written (``paretocal ... | true``): ``(exit status,
    stderr)``."""
    import subprocess

    proc = subprocess.Popen([sys.executable, "-m", "paretocal", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()
    err = proc.stderr.read()
    proc.stderr.close()
    return proc.wait(timeout=timeout), err


def default_sigint() -> None:
    """``preexec_fn`` for a child process a test sends SIGINT: a test session started in the
    background (``nohup``, ``&`` in a script) has SIGINT ignored, children inherit that and
    paretocal rightly keeps it; the child starts with the default action, as from a terminal."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def load_benchmark(name: str):
    """The module ``benchmarks/<name>.py``, imported by path (the benchmarks are scripts, not a
    package) and registered as ``<name>_benchmark`` so that its dataclasses resolve."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def render_board(camera, board, T_cam_board, background: int = 110, supersample: int = 2):
    """An exact synthetic image (H, W) uint8 of ``board`` at ``T_cam_board`` (board frame as
    :class:`paretocal.io.board.Board` defines it) seen through ``camera``'s lens model: dark
    squares 30 (the corner squares), light squares and margin 210, elsewhere ``background``;
    each pixel the mean of ``supersample``^2 rays."""
    h, w = camera.height, camera.width
    k = supersample
    v, u = np.mgrid[0:h * k, 0:w * k].astype(np.float64)
    uv = np.stack([(u + 0.5) / k - 0.5, (v + 0.5) / k - 0.5], axis=-1)
    rays = camera.unproject(uv)
    R, t = T_cam_board[:3, :3], T_cam_board[:3, 3]
    n = R[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (n @ t) / (rays @ n)
    hit = rays * s[..., None]
    local = (hit - t) @ R                                   # board frame
    x, y = local[..., 0], local[..., 1]
    img = np.full(s.shape, float(background))
    on = np.isfinite(s) & (s > 0) & (np.abs(x) <= board.size_m[0] / 2) & \
        (np.abs(y) <= board.size_m[1] / 2)
    img[on] = 210.0
    sx, sy = board.squares
    i = np.floor((x + sx * board.square_m / 2) / board.square_m)
    j = np.floor((y + sy * board.square_m / 2) / board.square_m)
    sq = on & (i >= 0) & (i < sx) & (j >= 0) & (j < sy)
    img[sq & ((i + j) % 2 == 0)] = 30.0
    img = img.reshape(h, k, w, k).mean(axis=(1, 3))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
