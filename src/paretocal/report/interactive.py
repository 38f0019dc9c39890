"""An interactive, self-contained HTML page of a calibration run (``interactive.html``).

The page is for judging a calibration by eye. It shows every frame the run calibrated (a list
with each frame's score: the run's edge objective for that frame alone, at the extrinsic
shown) and, for the frame picked, layers to toggle: the camera image, the image's edges (the
Canny edge pixels the objective's distance transform is taken from), and the LiDAR returns
coloured by depth (on that frame's own 5th-95th percentile of the depths in view), by
intensity, or as the feature groups the objective compares (depth edges, intensity edges,
smooth surface points; those the shown solution evaluates drawn larger). The extrinsic is the
initial, the chosen, the reference (when known) or any solution clicked on the Pareto front.
The canvas zooms (wheel) and pans (drag); a button resets the view.

The page needs no network access and no plotting library: the front is an SVG scatter drawn by
the page's own script (``front_plot.js``), and the projection is drawn client-side on a canvas
through the camera's own model (pinhole with radial-tangential distortion, fisheye, Mei) with
the arithmetic of :meth:`paretocal.camera.Camera.project_camera_points`, on the image as it
was taken.

Size. The page fits :data:`PAGE_BUDGET_BYTES` (2.9 MB) for 20 frames. Per frame it embeds the
edges as a 1-bit PNG at the camera's resolution and the first :data:`MAX_FEATURE_POINTS`
feature points (int16 xyz on a per-frame scale, a few mm at most, and a uint8 group) whole;
what they leave goes to the images (JPEG, at most :data:`MAX_IMAGE_WIDTH` px wide) at
:data:`GOOD_QUALITY` first, then to LiDAR returns (int16 xyz, uint8 intensity; between
:data:`MIN_POINTS` and :data:`MAX_POINTS` a frame, a random sample of those in view), and
the images then take the best quality and width that fit (:func:`page_data`). Measured: the
20 KITTI raw frames of ``make demo`` (1242 x 375) give a page of 2.80 MB (images at full
width, JPEG quality 70-75, 3516 returns a frame); 20 PandaSet front frames (1920 x 1080) 2.84
MB (2000 returns a frame; their edges, 100 000 pixels a frame, take 1.1 MB, and the images
are 840 x 472 at quality 55). More frames than :data:`REFERENCE_FRAMES` share the budget
with fewer points each (down to a quarter); the edges stay whole, so many frames of detailed
images outgrow it (a warning is logged).

The page's data is built by pure functions (:func:`lidar_layer`, :func:`feature_layer`,
:func:`edge_layer`, :func:`image_layer`, :func:`frame_scores`, assembled by
:func:`page_data`), the HTML by :func:`write_interactive`. The page's skeleton, style sheet
and script are package data in ``report/templates/`` (``interactive.html``,
``interactive.css``, ``front_plot.js``, ``interactive.js``); the skeleton's ``$name``
placeholders are filled with :class:`string.Template`.
"""

from __future__ import annotations

import base64
import html
import json
import logging
from pathlib import Path
from string import Template

import cv2
import numpy as np

from ..camera import Camera, project
from ..features.lidar import GROUP_NAMES
from ..geometry import correction_params, invert
from ..io.atomic import atomic_write_text
from ..io.frame import Frame
from .html import template

log = logging.getLogger(__name__)

#: Largest and smallest number of LiDAR returns embedded per frame (a random sample of those
#: in view): as many as the budget leaves once the images have :data:`GOOD_QUALITY`.
MAX_POINTS = 5000
MIN_POINTS = 2000
#: Largest number of the objective's feature points embedded per frame (the first of its
#: evaluation order: a solution with ``n`` points per frame evaluates the first ``n``).
MAX_FEATURE_POINTS = 1000
#: A run of more frames than this embeds proportionally fewer points per frame (at least a
#: quarter of the numbers above), so that its page stays near the budget.
REFERENCE_FRAMES = 20
#: Widest image embedded (px); wider images are downscaled for the page.
MAX_IMAGE_WIDTH = 1280
#: Narrowest image the page falls back to when the budget is tight (px).
MIN_IMAGE_WIDTH = 480
#: JPEG qualities tried, best first; below :data:`WIDTH_QUALITY_FLOOR` a narrower image (each
#: :data:`WIDTH_STEP` of the last) is preferred to a lower quality.
JPEG_QUALITIES = (90, 85, 80, 75, 70, 65, 60, 55, 50, 45, 40, 35, 30)
WIDTH_QUALITY_FLOOR = 50
#: The JPEG quality at :data:`MAX_IMAGE_WIDTH` the budget keeps for the images before it
#: gives LiDAR returns beyond :data:`MIN_POINTS`.
GOOD_QUALITY = 75
WIDTH_STEP = 0.9
#: The page's size the images are fitted into (bytes, the whole file).
PAGE_BUDGET_BYTES = 2_900_000
#: Percentiles of a frame's depths in view (at the chosen extrinsic) that span the depth
#: colour scale, and of its intensities that span the intensity scale.
DEPTH_PERCENTILES = (5.0, 95.0)
INTENSITY_PERCENTILES = (1.0, 99.0)
#: Depth scale (m) of a frame with no return in view.
DEFAULT_DEPTH_RANGE = (0.0, 30.0)
#: Colours (RGB) of the feature groups, in the order of ``GROUP_NAMES``, and of the image edges.
GROUP_COLORS = ((255, 212, 0), (0, 229, 255), (140, 255, 40))
EDGE_COLOR = (255, 0, 255)


def _json_script(obj) -> str:
    """JSON text safe inside ``<script type="application/json">`` (no ``<``, ``>``, ``&``)."""
    text = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _lut(name: str, n: int = 256) -> list[list[int]]:
    """A matplotlib colour map as ``n`` RGB triples (0-255)."""
    import matplotlib

    rgb = matplotlib.colormaps[name](np.linspace(0.0, 1.0, n))[:, :3]
    return np.round(rgb * 255).astype(int).tolist()


def _depth_lut(n: int = 256) -> list[list[int]]:
    """The static overlays' depth colours (matplotlib's ``turbo_r``: near is warm) as RGB."""
    return _lut("turbo_r", n)


def _b64(a: np.ndarray | bytes) -> str:
    raw = a if isinstance(a, bytes) else np.ascontiguousarray(a).tobytes()
    return base64.b64encode(raw).decode("ascii")


# --- the page's data: pure functions, arrays in, dicts out -----------------------------------

def quantise_xyz(xyz: np.ndarray) -> tuple[np.ndarray, float]:
    """Points as little-endian int16 on one scale.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Metres.

    Returns
    -------
    q : ndarray, shape (N, 3), ``<i2``
    scale : float
        Metres per unit: the largest coordinate magnitude maps to 32767, so the points are
        ``q * scale`` to within ``scale / 2`` (1.5 mm for points within 100 m).
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    big = float(np.abs(xyz).max()) if xyz.size else 0.0
    scale = max(big, 1e-3) / 32767.0
    q = np.clip(np.rint(xyz / scale), -32767, 32767).astype("<i2")
    return q, scale


def dequantise_xyz(q: np.ndarray, scale: float) -> np.ndarray:
    """The points (N, 3) float64 in metres the page draws: ``q * scale``, the same arithmetic
    as the page's script."""
    return np.asarray(q, dtype=np.float64).reshape(-1, 3) * float(scale)


def lidar_layer(xyz: np.ndarray, intensity: np.ndarray | None, camera: Camera,
                transforms: list[np.ndarray], T_chosen: np.ndarray, z_min: float,
                max_points: int = MAX_POINTS, seed: int = 0) -> dict:
    """The LiDAR returns of one frame as the page embeds them.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        The sweep in the LiDAR frame (m).
    intensity : ndarray, shape (N,), or None
        Reflectance in the file's units.
    camera : Camera
    transforms : list of ndarray (4, 4)
        The extrinsics of the page (front, initial, reference): a return is kept when it is in
        view for at least one.
    T_chosen : ndarray, shape (4, 4)
        The extrinsic the depth scale is taken at.
    z_min : float
        As :func:`paretocal.camera.project`.
    max_points : int
        The kept returns are randomly subsampled (fixed ``seed``) to at most this many.

    Returns
    -------
    dict
        ``xyz`` (P, 3) ``<i2`` and ``scale`` (m per unit, :func:`quantise_xyz`); ``intensity``
        (P,) uint8, 0-255 over ``intensity_range`` (the kept returns' 1st-99th percentile, in
        the file's units); ``depth_range`` (m): the 5th and 95th percentile of the depths (along
        the optical axis) of all the frame's returns in view at ``T_chosen``; ``in_view``: how
        many those are; ``total``: N.
    """
    xyz = np.asarray(xyz, dtype=np.float64)[:, :3]
    _, z, vis = project(xyz, camera, np.asarray(T_chosen), z_min)
    if vis.any():
        lo, hi = (float(v) for v in np.percentile(z[vis], DEPTH_PERCENTILES))
    else:
        lo, hi = DEFAULT_DEPTH_RANGE
    if not hi > lo:
        hi = lo + 1.0
    # The first max_points of a random order that are in view for some extrinsic: a uniform
    # sample of those, found by projecting a block of the order at a time (not the whole sweep
    # under every extrinsic).
    order = np.random.default_rng(seed).permutation(len(xyz))
    block = max(8 * int(max_points), 16384)
    kept, n_kept = [], 0
    for a in range(0, len(order), block):
        sel = order[a:a + block]
        keep = np.zeros(len(sel), dtype=bool)
        for T in transforms:
            keep |= project(xyz[sel], camera, np.asarray(T), z_min)[2]
        kept.append(sel[keep])
        n_kept += int(keep.sum())
        if n_kept >= max_points:
            break
    idx = np.sort(np.concatenate(kept)[:max_points]) if kept else np.zeros(0, np.int64)
    q, scale = quantise_xyz(xyz[idx])
    inten = (np.zeros(len(xyz)) if intensity is None
             else np.nan_to_num(np.asarray(intensity, dtype=np.float64)))
    if len(idx):
        ilo, ihi = (float(v) for v in np.percentile(inten[idx], INTENSITY_PERCENTILES))
    else:
        ilo = ihi = 0.0
    span = ihi - ilo
    level = ((inten[idx] - ilo) / span if span > 0 else np.zeros(len(idx)))
    return {"xyz": q, "scale": scale,
            "intensity": np.rint(np.clip(level, 0.0, 1.0) * 255).astype(np.uint8),
            "intensity_range": (ilo, ihi), "depth_range": (lo, hi),
            "in_view": int(vis.sum()), "total": int(len(xyz))}


def feature_layer(xyz: np.ndarray, group: np.ndarray,
                  max_points: int = MAX_FEATURE_POINTS) -> dict:
    """One frame's feature points (the objective's scene) as the page embeds them.

    Parameters
    ----------
    xyz : ndarray, shape (M, 3)
        The points in the LiDAR frame (m), in the objective's evaluation order.
    group : ndarray, shape (M,)
        Their groups (indices into ``GROUP_NAMES``).
    max_points : int
        The first this many of the order are kept (the ones any ``n`` evaluates first).

    Returns
    -------
    dict
        ``xyz`` (P, 3) ``<i2``, ``scale`` (:func:`quantise_xyz`), ``group`` (P,) uint8,
        ``counts`` (G,) points of each group among the P, ``total``: M.
    """
    m = min(len(xyz), int(max_points))
    q, scale = quantise_xyz(np.asarray(xyz, dtype=np.float64)[:m, :3])
    g = np.asarray(group)[:m].astype(np.uint8)
    return {"xyz": q, "scale": scale, "group": g,
            "counts": np.bincount(g, minlength=len(GROUP_NAMES)).tolist(), "total": int(len(xyz))}


def edge_layer(edges: np.ndarray) -> dict:
    """An edge map as a 1-bit PNG.

    Parameters
    ----------
    edges : ndarray, shape (H, W)
        Non-zero on edge pixels.

    Returns
    -------
    dict
        ``png`` (bytes: a bilevel PNG, 255 on edge pixels, at the map's resolution),
        ``count`` (edge pixels), ``width``, ``height``.
    """
    e = np.where(np.asarray(edges) > 0, 255, 0).astype(np.uint8)
    ok, png = cv2.imencode(".png", e, [cv2.IMWRITE_PNG_BILEVEL, 1,
                                       cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 image
        raise RuntimeError("could not encode the edge map as PNG")
    return {"png": png.tobytes(), "count": int((e > 0).sum()), "width": int(e.shape[1]),
            "height": int(e.shape[0])}


def _jpeg(image: np.ndarray, quality: int) -> bytes:
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality),
                                           cv2.IMWRITE_JPEG_OPTIMIZE, 1])
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 BGR image
        raise RuntimeError("could not encode the camera image as JPEG")
    return buf.tobytes()


def _resized(image: np.ndarray, width: int) -> np.ndarray:
    """``image`` downscaled (area interpolation) to ``width`` px, its aspect kept."""
    h, w = image.shape[:2]
    if width >= w:
        return image
    return cv2.resize(image, (int(width), max(1, int(round(h * width / w)))),
                      interpolation=cv2.INTER_AREA)


def image_layer(image: np.ndarray, max_bytes: float | None = None,
                max_width: int = MAX_IMAGE_WIDTH, min_width: int = MIN_IMAGE_WIDTH) -> dict:
    """A camera image as the page embeds it: the best JPEG that fits ``max_bytes``.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8
        BGR.
    max_bytes : float, optional
        The JPEG's size limit (None: no limit, the best quality at ``max_width``).
    max_width, min_width : int
        The image is downscaled (area interpolation) to at most ``max_width`` px. The widest
        image that fits at a quality of at least :data:`WIDTH_QUALITY_FLOOR` is taken, at the
        best quality that fits (widths step by :data:`WIDTH_STEP` down to ``min_width``, where
        the quality goes down to the last of :data:`JPEG_QUALITIES`); when none fits, the
        smallest JPEG tried.

    Returns
    -------
    dict
        ``jpeg`` (bytes), ``width`` and ``height`` (px, of the JPEG) and ``quality``.
    """
    h, w = image.shape[:2]
    widths = [min(w, int(max_width))]
    while widths[-1] > min(int(min_width), w):
        widths.append(max(int(round(widths[-1] * WIDTH_STEP)), min(int(min_width), w)))
    smallest: tuple[bytes, int, int, int] | None = None
    for k, width in enumerate(widths):
        img = _resized(image, width)
        height = img.shape[0]
        last = k == len(widths) - 1
        qs = [q for q in JPEG_QUALITIES if last or q >= WIDTH_QUALITY_FLOOR]
        # The lowest quality first: when it does not fit, the next width. Then a binary search
        # (the JPEG's size grows with the quality).
        data = _jpeg(img, qs[-1])
        if max_bytes is not None and len(data) > max_bytes:
            if smallest is None or len(data) < len(smallest[0]):
                smallest = (data, width, height, qs[-1])
            continue
        fit, lo, hi = (data, qs[-1]), 0, len(qs) - 2
        while lo <= hi:
            mid = (lo + hi) // 2
            data = _jpeg(img, qs[mid])
            if max_bytes is None or len(data) <= max_bytes:
                fit, hi = (data, qs[mid]), mid - 1
            else:
                lo = mid + 1
        return {"jpeg": fit[0], "width": width, "height": height, "quality": fit[1]}
    assert smallest is not None
    return {"jpeg": smallest[0], "width": smallest[1], "height": smallest[2],
            "quality": smallest[3]}


def frame_scores(objective, T: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The alignment objective of each frame alone for some extrinsics.

    Parameters
    ----------
    objective : CalibrationObjective
        The run's objective (``result.objective``).
    T : ndarray, shape (V, 4, 4)
        Extrinsics ``T_cam_lidar``.
    n : array_like, shape (V,)
        Points per frame each is evaluated with.

    Returns
    -------
    ndarray, shape (V, F)
        ``objective.chamfer(X, ucb_k=0)["per_frame"]`` (px, lower is better) for the rows
        ``X = (x, y, z, yaw, pitch, roll, n)``: each extrinsic as the correction of the
        objective's own ``T_init`` that gives it.
    """
    T = np.asarray(T, dtype=np.float64).reshape(-1, 4, 4)
    D = invert(np.asarray(objective.T_init, dtype=np.float64)) @ T
    X = np.column_stack([correction_params(D), np.asarray(n, dtype=np.float64).reshape(-1)])
    return np.asarray(objective.chamfer(X, ucb_k=0.0)["per_frame"], dtype=np.float64)


def _finite(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def _camera_entry(cam: Camera) -> dict:
    return {**cam.to_dict(), "params": [float(v) if np.isfinite(v) else None
                                        for v in cam.kernel_params()],
            "mount": None if cam.mount is None else np.asarray(cam.mount, dtype=float).tolist()}


def _frame_edges(result, frame: Frame, scene_index: int | None) -> np.ndarray:
    """The edge pixels (H, W) bool the objective compares ``frame`` with: where its
    distance transform is 0 in the run's scene, or computed afresh with the run's settings
    when the run kept no objective."""
    if scene_index is not None:
        return result.objective.scene.frame_dt(scene_index) == 0
    from ..features.prepare import frame_image_features

    return frame_image_features(frame, result.settings.features,
                                result.settings.objective).edges > 0


def _camera_index(cameras: list[dict], cam: Camera) -> int:
    """The index of ``cam``'s entry in ``cameras``, appended when new."""
    entry = _camera_entry(cam)
    if entry not in cameras:
        cameras.append(entry)
    return cameras.index(entry)


def _edges_entry(edges: np.ndarray) -> dict:
    """A frame's ``edges`` (H, W) bool as the page embeds them."""
    layer = edge_layer(edges)
    return {"src": "data:image/png;base64," + _b64(layer["png"]), "count": layer["count"]}


def _points_entry(pts: dict) -> dict:
    """:func:`lidar_layer`'s output as the page embeds it (arrays base64)."""
    return {"count": int(len(pts["xyz"])), "dtype": "int16", "layout": "xyz",
            "scale": pts["scale"], "xyz": _b64(pts["xyz"]), "intensity": _b64(pts["intensity"]),
            "intensity_range": list(pts["intensity_range"]),
            "depth_range": list(pts["depth_range"]), "in_view": pts["in_view"],
            "total": pts["total"]}


def _image_entry(image: np.ndarray, max_bytes: float | None) -> dict:
    """:func:`image_layer`'s JPEG as the page embeds it."""
    im = image_layer(image, max_bytes)
    return {"src": "data:image/jpeg;base64," + _b64(im["jpeg"]), "width": im["width"],
            "height": im["height"], "quality": im["quality"]}


def _colours() -> dict:
    """The colour tables and scales every page shares."""
    return {"lut": _depth_lut(), "lut_intensity": _lut("viridis"),
            "groups": {"names": [g.replace("_", " ") for g in GROUP_NAMES],
                       "colors": [list(c) for c in GROUP_COLORS]},
            "edge_color": list(EDGE_COLOR), "depth_percentiles": list(DEPTH_PERCENTILES),
            "intensity_percentiles": list(INTENSITY_PERCENTILES)}


def page_data(result, frames: list[Frame], frame: int = 0, max_points: int = MAX_POINTS,
              max_feature_points: int = MAX_FEATURE_POINTS,
              budget_bytes: int | None = PAGE_BUDGET_BYTES, overhead_bytes: int = 0,
              min_points: int = MIN_POINTS) -> dict:
    """Everything the page's script reads, JSON-ready.

    Parameters
    ----------
    result : CalibrationResult
    frames : list of Frame
        The frames as calibrated (``result.sweeps``), in the run's order.
    frame : int
        The frame shown first (clipped to the list).
    max_points, max_feature_points : int
        Per frame: :func:`lidar_layer`, :func:`feature_layer`.
    budget_bytes : int, optional
        The page's size: the data (base64) plus ``overhead_bytes`` (the page around it). The
        edges and feature points are embedded whole; what they leave goes to the images at
        :data:`GOOD_QUALITY` first, then to LiDAR returns (between ``min_points`` and
        ``max_points`` per frame), then the images take the best quality that fits
        (:func:`image_layer`). None: ``max_points`` and the best quality.
    min_points : int
        See ``budget_bytes`` (at most ``max_points``).

    Returns
    -------
    dict
        ``frames``: per frame ``name``, ``camera`` (index into ``cameras``), ``image``
        (a ``data:`` JPEG URI with its ``width``, ``height``, ``quality``), ``edges`` (a
        ``data:`` PNG URI, ``count``), ``points`` (:func:`lidar_layer`, arrays base64),
        ``features`` (:func:`feature_layer`, base64; None without an objective) and
        ``scene_index``; ``cameras``; ``scores`` (None without an objective): per frame, the
        objective of that frame alone (px, :func:`frame_scores`) at each front solution
        (``solutions``, each at its own ``n``), at ``initial`` and ``reference`` (at the
        chosen ``n``); the extrinsics, the front's solutions and plot, colour tables.
    """
    if not frames:
        raise ValueError("the interactive page needs at least one frame")
    z_min = float(result.settings.features.z_min)
    front = result.front
    T_front = [np.asarray(T, dtype=np.float64) for T in front.T]
    views = T_front + [np.asarray(result.T_init, dtype=np.float64)]
    if result.T_ref is not None:
        views.append(np.asarray(result.T_ref, dtype=np.float64))
    T_chosen = np.asarray(result.T_cam_lidar, dtype=np.float64)
    objective = getattr(result, "objective", None)
    names = list(objective.scene.names) if objective is not None else []

    scores = None
    if objective is not None:
        n_chosen = result.n_points
        Ts = np.stack(views)
        n = np.concatenate([front.X[:, 6], [n_chosen] * (len(views) - len(T_front))])
        per = frame_scores(objective, Ts, n)                        # (V, F_scene)
        k = len(T_front)

        def col(row):
            return [_finite(row[names.index(f.name)]) if f.name in names else None
                    for f in frames]

        scores = {"solutions": [col(per[i]) for i in range(k)], "initial": col(per[k]),
                  "reference": col(per[k + 1]) if result.T_ref is not None else None,
                  "n": int(n_chosen)}

    cameras: list[dict] = []
    entries = []
    for f in frames:
        si = names.index(f.name) if f.name in names else None
        feats = None
        if si is not None and objective is not None:
            sc = objective.scene
            a, b = int(sc.point_start[si]), int(sc.point_start[si + 1])
            fl = feature_layer(sc.frame_xyz(si), sc.group[a:b], max_feature_points)
            feats = {"count": int(len(fl["group"])), "scale": fl["scale"],
                     "xyz": _b64(fl["xyz"]), "group": _b64(fl["group"]),
                     "counts": fl["counts"], "total": fl["total"]}
        entries.append({
            "name": f.name, "camera": _camera_index(cameras, f.camera), "scene_index": si,
            "image": None, "edges": _edges_entry(_frame_edges(result, f, si)),
            "points": None, "features": feats})

    solutions = _solution_entries(result)
    ini = result.initial_error
    captions = {"initial": "initial extrinsic" + (
        f": error vs reference {_fmt_err(ini['rotation_deg'], ini['translation_cm'])}"
        if ini is not None else ""),
        "reference": "dataset reference extrinsic"}
    data = {
        "frames": entries, "start": min(max(int(frame), 0), len(frames) - 1),
        "cameras": cameras, "z_min": z_min, "scores": scores,
        "chosen": int(result.chosen),
        "T_init": np.asarray(result.T_init, dtype=float).tolist(),
        "T_ref": None if result.T_ref is None else np.asarray(result.T_ref, dtype=float).tolist(),
        "solutions": solutions, "plot": _plot_spec(result, solutions),
        "captions": captions, **_colours(),
    }
    # What the edges, the feature points and the rest leave of the budget: the images at a
    # good quality first, then LiDAR returns, then the images take what is left.
    min_points = min(int(min_points), int(max_points))
    n_points = int(max_points)
    per_point = 7 * 4 / 3                                 # int16 xyz + uint8 intensity, base64
    if budget_bytes is not None:
        rest = len(_json_script(data)) + overhead_bytes + 400 * len(frames)
        good = sum(len(_jpeg(_resized(f.image, MAX_IMAGE_WIDTH), GOOD_QUALITY))
                   for f in frames) * 4 / 3
        room = (budget_bytes - rest - good) / (len(frames) * per_point)
        n_points = int(np.clip(room, min_points, max_points))
    for f, e in zip(frames, entries):
        pts = lidar_layer(f.points[:, :3], f.points[:, 3] if f.points.shape[1] > 3 else None,
                          f.camera, views, T_chosen, z_min, n_points)
        e["points"] = _points_entry(pts)
    data["max_points"] = n_points
    per_image = None
    if budget_bytes is not None:
        rest = len(_json_script(data)) + overhead_bytes
        prefix = len('{"src":"data:image/jpeg;base64,","width":10000,"height":10000,'
                     '"quality":100}') - len("null")
        per_image = ((budget_bytes - rest) / len(frames) - prefix) * 3 / 4
    for f, e in zip(frames, entries):
        e["image"] = _image_entry(f.image, None if per_image is None else max(per_image, 0.0))
    return data


def _fmt_err(rot, trans) -> str:
    return f"{rot:.3f} deg, {trans:.2f} cm"


def _solution_entries(result) -> list[dict]:
    front, cols = result.front, result.front.columns
    has_ref = "ref_rotation_deg" in cols
    k = len(front.X)
    out = []
    for i in range(k):
        x = front.X[i]
        n = int(round(x[6]))
        ms, nbytes = float(cols["ms"][i]), int(round(cols["bytes"][i]))
        dev = float(cols["deviation_px"][i]) if "deviation_px" in cols else None
        tag = " (chosen)" if i == result.chosen else ""
        hover = [f"solution {i}{tag}",
                 f"x, y, z = {x[0] * 100:+.2f}, {x[1] * 100:+.2f}, {x[2] * 100:+.2f} cm",
                 f"yaw, pitch, roll = {x[3]:+.3f}, {x[4]:+.3f}, {x[5]:+.3f} deg",
                 f"n = {n} points/frame",
                 f"f1 = {front.F[i, 0]:.4f} px, f2 = {front.F[i, 1]:.4f}",
                 f"cost = {ms:.4g} ms, {nbytes:,} bytes"]
        if dev is not None:
            hover.append(f"deviation = {dev:.3f} px")
        cap = (f"solution {i} of {k}{tag}: n = {n} points/frame, f1 = {front.F[i, 0]:.3f} px, "
               f"{ms:.3g} ms")
        entry = {"T": np.asarray(front.T[i], dtype=float).tolist(), "n": n,
                 "f1": float(front.F[i, 0]), "f2": float(front.F[i, 1]), "ms": ms,
                 "bytes": nbytes, "deviation_px": dev}
        if has_ref:
            rot, tr = float(cols["ref_rotation_deg"][i]), float(cols["ref_translation_cm"][i])
            hover.append(f"error vs reference = {_fmt_err(rot, tr)}")
            cap += f"; error vs reference {_fmt_err(rot, tr)}"
            entry.update(ref_rotation_deg=rot, ref_translation_cm=tr)
        entry["hover"] = hover
        entry["caption"] = cap
        out.append(entry)
    return out


def _plot_spec(result, solutions: list[dict]) -> dict:
    """What the page's own SVG plot of the front needs besides the solutions: axis titles,
    the colour of each solution (its rotation error vs the reference, when known) and the
    chosen solution's legend entry."""
    has_ref = "ref_rotation_deg" in result.front.columns
    return {"x_title": "f1: Chamfer objective (px, lower is better)",
            "y_title": "f2: normalised cost (t_norm + m_norm)",
            "color": [s["ref_rotation_deg"] for s in solutions] if has_ref else None,
            "color_title": "rot. error (deg)",
            "chosen_label": f"chosen ({result.decision.rule or '?'}, n = {result.n_points})"}


def _run_table(result, frame: Frame) -> str:
    from .. import __version__

    obj = result.objectives()
    rows = [("frames", f"{len(result.frames)} ({html.escape(result.frames[0])}"
                       + (f" \u2026 {html.escape(result.frames[-1])})" if len(result.frames) > 1
                          else ")")),
            ("first frame shown", html.escape(frame.name)),
            ("chosen", f"solution {result.chosen} of {len(result.front.X)}, "
                       f"rule {html.escape(result.decision.rule or '?')}"),
            ("chosen n", f"{result.n_points} points/frame"),
            ("f1 / f2", f"{obj['chamfer']:.4f} px / {obj['cost']:.4f}"),
            ("cost", f"{obj.get('ms', float('nan')):.4g} ms, {int(obj.get('bytes', 0)):,} bytes")]
    if "deviation_px" in obj:
        rows.append(("deviation", f"{obj['deviation_px']:.3f} px"))
    ref, ini = result.reference_error, result.initial_error
    if ref is not None:
        rows.append(("error vs reference", _fmt_err(ref["rotation_deg"], ref["translation_cm"])))
    if ini is not None:
        rows.append(("initial error", _fmt_err(ini["rotation_deg"], ini["translation_cm"])))
    rows += [("evaluations", f"{int(result.evaluations):,}"),
             ("wall time", f"{float(result.wall_s):.1f} s"),
             ("paretocal", html.escape(str(__version__)))]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    return f'<table id="run-table">{body}</table>'


def _verdict_banner(result) -> str:
    """The run's verdict as a banner: every reason when it is unreliable."""
    rel = getattr(result, "reliability", None)
    if rel is None:
        return ""
    from ..verdict import interval_text, verdict_text

    ok = rel.ok
    items = "" if ok else "<ul>" + "".join(f"<li>{html.escape(r)}</li>"
                                            for r in rel.reasons) + "</ul>"
    head = verdict_text(rel) if ok else "UNRELIABLE: do not use this result as it is"
    iv = interval_text(rel)
    iv = "" if iv is None else (f'<div class="intervals">95 % intervals per axis (LiDAR frame): '
                                f"{html.escape(iv)}</div>")
    return (f'<div id="verdict" class="verdict {"ok" if ok else "unreliable"}">'
            f"{html.escape(head)}{items}{iv}</div>")


def write_interactive(result, frames: list[Frame], path: str | Path, frame: int = 0,
                      max_points: int = MAX_POINTS) -> Path:
    """Write the interactive report page of a calibration run.

    The page is a single self-contained HTML file that makes no network request (see the
    module docstring for what it shows and what it embeds): a frame picker over every frame
    with each frame's score, the projection of the picked frame's LiDAR returns drawn on a
    canvas over its image and edges (by depth, intensity or feature group; zoom and pan), the
    Pareto front (hover for a solution's variables, cost, deviation and reference errors;
    click to project with it), buttons for the initial, chosen and reference extrinsics, the
    verdict and a table of the run.

    Parameters
    ----------
    result : CalibrationResult
        The run (its front, chosen solution, ``T_init``, when known ``T_ref``, and its
        ``objective`` for the per-frame scores and feature points: without one, a resumed
        run's, the page says they are left out).
    frames : list of Frame
        The run's frames, as calibrated (``result.sweeps``).
    path : str or Path
        The output file (conventionally ``interactive.html`` in the run directory); written
        atomically.
    frame : int, optional
        The frame shown first (clipped to the list); the first by default.
    max_points : int, optional
        At most this many LiDAR returns per frame are embedded: those in view for at least
        one of the front's, the initial or the reference extrinsic, randomly subsampled (fixed
        seed).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If ``frames`` is empty.
    """
    from .figures import data_credit

    if not frames:
        raise ValueError("write_interactive needs at least one frame")
    path = Path(path)
    f = frames[min(max(frame, 0), len(frames) - 1)]
    buttons = ['<button type="button" data-view="initial" id="view-initial">initial</button>',
               '<button type="button" data-view="chosen" id="view-chosen">chosen</button>']
    if result.T_ref is not None:
        buttons.append('<button type="button" data-view="reference" id="view-reference">'
                       'reference</button>')
    has_objective = getattr(result, "objective", None) is not None
    if has_objective:
        scores_note = ("Score: the edge objective of the frame alone at the extrinsic shown "
                       "(px, lower is better; initial and reference at the chosen n); the bar "
                       "spans the best to the worst frame.")
    else:
        scores_note = ("No per-frame scores and no feature groups: this run did not keep its "
                       "objective (a resumed run); the edges are computed afresh with the "
                       "run's settings.")
    title = f"paretocal calibration run: {len(result.frames)} frame(s), n = {result.n_points}"
    share = min(1.0, REFERENCE_FRAMES / len(frames))
    n_points = max(MIN_POINTS // 4, int(round(MIN_POINTS * share)))
    n_features = max(MAX_FEATURE_POINTS // 4, int(round(MAX_FEATURE_POINTS * share)))

    def points_note(n: int) -> str:
        return html.escape(
            f"LiDAR: {n} returns embedded per frame at most (a random sample of those in view "
            f"for some extrinsic of the page) and the first {n_features} feature points of the "
            f"objective's order; images downscaled to at most {MAX_IMAGE_WIDTH} px wide for the "
            "page (JPEG), edges at the camera's resolution.")

    skeleton = Template(template("interactive.html"))
    fields = dict(
        title=html.escape(title), verdict=_verdict_banner(result),
        run_table=_run_table(result, f), buttons="".join(buttons),
        width=int(f.camera.width), height=int(f.camera.height),
        scores_note=html.escape(scores_note), credit=html.escape(data_credit(f)),
        css=template("interactive.css"),
        js=template("front_plot.js") + template("interactive.js"))
    # substitute() fails on a missing placeholder; the values (the script, the data) are not
    # scanned, so a $ in them is inert.
    overhead = len(skeleton.substitute(fields, points_note=points_note(max_points),
                                       data="").encode("utf-8"))
    data = page_data(result, frames, frame, max_points, n_features, overhead_bytes=overhead,
                     min_points=n_points)
    fields["points_note"] = points_note(data["max_points"])
    page = skeleton.substitute(fields, data=_json_script(data))
    size = len(page.encode("utf-8"))
    if size > PAGE_BUDGET_BYTES:
        log.warning("interactive.html is %.2f MB for %d frames (budget %.2f MB)", size / 1e6,
                    len(frames), PAGE_BUDGET_BYTES / 1e6)
    atomic_write_text(path, page)
    return path


# ------------------------------------------------------------------- two extrinsics compared


def comparison_data(comparison, frames: list[Frame], settings, max_points: int = MIN_POINTS,
                    budget_bytes: int = PAGE_BUDGET_BYTES) -> dict:
    """What the page's script reads for two extrinsics compared on frames
    (:func:`paretocal.check.compare_extrinsics`): the same frames, layers and zoom as a run's
    page, with A and B as the two poses to switch between and no front.

    Parameters
    ----------
    comparison : Comparison
        With frames (``comparison.frame_scores`` gives each frame's score at A and B).
    frames : list of Frame
        The frames compared (``comparison.sweeps``: de-skewed when they were).
    settings : Settings
        The features' and objective's settings (the image edges, ``z_min``).
    max_points : int
        LiDAR returns embedded per frame at most.
    budget_bytes : int
        The page's size the images are fitted into (bytes).

    Returns
    -------
    dict
        The keys :func:`page_data` gives, with ``solutions`` A and B, ``chosen`` B, ``plot``
        None and no feature points.
    """
    from ..features.prepare import frame_image_features

    if not frames:
        raise ValueError("the comparison page needs at least one frame")
    z_min = float(settings.features.z_min)
    T_a, T_b = (np.asarray(T, dtype=np.float64) for T in (comparison.T_a, comparison.T_b))
    cameras: list[dict] = []
    entries = []
    for f in frames:
        edges = frame_image_features(f, settings.features, settings.objective).edges > 0
        pts = lidar_layer(f.points[:, :3], f.points[:, 3] if f.points.shape[1] > 3 else None,
                          f.camera, [T_a, T_b], T_b, z_min, max_points)
        entries.append({"name": f.name, "camera": _camera_index(cameras, f.camera),
                        "scene_index": None, "edges": _edges_entry(edges),
                        "points": _points_entry(pts), "image": None, "features": None})
    sc = comparison.frame_scores
    scores = None if sc is None else {
        "solutions": [[_finite(v) for v in row] for row in sc], "initial": None,
        "reference": None, "n": None}
    move = comparison.axes_text()
    solutions = [{"T": T_a.tolist(), "n": None, "caption": "A"},
                 {"T": T_b.tolist(), "n": None, "caption": f"B = A @ D ({move})"}]
    data = {
        "frames": entries, "start": 0, "cameras": cameras, "z_min": z_min, "scores": scores,
        "chosen": 1, "T_init": T_a.tolist(), "T_ref": None, "solutions": solutions,
        "plot": None, "captions": {"initial": "A", "reference": ""}, **_colours(),
        "max_points": int(max_points)}
    # The images take what the rest leaves (40 kB: the page around the data).
    room = (budget_bytes - len(_json_script(data)) - 40_000) / len(frames) * 3 / 4
    for f, e in zip(frames, entries):
        e["image"] = _image_entry(f.image, max(room, 0.0))
    return data


def write_comparison(comparison, frames: list[Frame], settings, path: str | Path) -> Path:
    """Write the page of two extrinsics compared on frames (``paretocal compare A B SOURCE
    --page FILE``): every frame with its score at A and at B, the layers and the zoom of a
    run's page, buttons for A and B, and the comparison's figures and preference.

    Parameters
    ----------
    comparison : Comparison
        :func:`paretocal.check.compare_extrinsics`'s, with frames.
    frames : list of Frame
        The frames compared (``comparison.sweeps``).
    settings : Settings
    path : str or Path
        The output file, written atomically.

    Returns
    -------
    Path
    """
    from .figures import data_credit

    path = Path(path)
    data = comparison_data(comparison, frames, settings)
    c = comparison.to_dict()
    rows = [("frames", f"{len(frames)} ({html.escape(frames[0].name)}"
                       + (f" \u2026 {html.escape(frames[-1].name)})" if len(frames) > 1 else ")")),
            ("B from A", html.escape(comparison.axes_text())),
            ("apart", f"{c['rotation_deg']:.3f} deg, {c['translation_cm']:.2f} cm"
                      + ("" if c["pixels"] is None else f", {c['pixels']:.1f} px")),
            ("the frames prefer", html.escape(str(comparison.prefer)))]
    table = ('<table id="run-table">'
             + "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</table>")
    banner = f'<div id="verdict" class="verdict">{html.escape(comparison.reason)}</div>'
    buttons = ('<button type="button" data-view="0" id="view-a">A</button>'
               '<button type="button" data-view="1" id="view-b">B</button>')
    f = frames[0]
    page = Template(template("interactive.html")).substitute(
        title=html.escape(f"paretocal: two extrinsics compared on {len(frames)} frame(s)"),
        verdict=banner, run_table=table, buttons=buttons,
        width=int(f.camera.width), height=int(f.camera.height),
        scores_note=html.escape("Score: the edge objective of the frame alone at the "
                                "extrinsic shown, with the points A sees (px, lower is "
                                "better); the bar spans the best to the worst frame."),
        points_note=html.escape(f"LiDAR: at most {data['max_points']} returns per frame (a "
                                "random sample of those in view at A or B); no feature "
                                "groups (no calibration ran)."),
        credit=html.escape(data_credit(f)), css=template("interactive.css"),
        js=template("front_plot.js") + template("interactive.js"),
        data=_json_script(data))
    atomic_write_text(path, page)
    return path
