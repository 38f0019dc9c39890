"""An interactive, self-contained HTML page of a calibration run (``interactive.html``).

The page needs no network access and no plotting library: the Pareto front is an SVG scatter
drawn by the page's own script (``front_plot.js``, a few kilobytes), the camera image is a base64
JPEG and the LiDAR points a base64 float32 array. The
projection of the first frame's points is drawn client-side on a canvas, with the extrinsic of
the solution clicked on the front, or the initial, chosen or reference extrinsic. The page
projects through the camera's own model (pinhole with radial-tangential distortion, fisheye,
Mei) with the arithmetic of :meth:`paretocal.camera.Camera.project_camera_points`, on the
image as it was taken.

The page's skeleton, style sheet and script are package data in ``report/templates/``
(``interactive.html``, ``interactive.css``, ``front_plot.js``, ``interactive.js``); the skeleton's ``$name``
placeholders are filled with :class:`string.Template`.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from string import Template

import cv2
import numpy as np

from ..camera import project
from ..io.atomic import atomic_write_text
from ..io.frame import Frame
from .html import template

#: Largest number of LiDAR points embedded in the page.
MAX_POINTS = 20000
#: Depth (m) at the cold end of the colour scale, as in the static overlays.
MAX_DEPTH = 30.0
JPEG_QUALITY = 88

def _json_script(obj) -> str:
    """JSON text safe inside ``<script type="application/json">`` (no ``<``, ``>``, ``&``)."""
    text = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _depth_lut(n: int = 256) -> list[list[int]]:
    """The static overlays' depth colours (matplotlib's ``turbo_r``: near is warm) as RGB."""
    import matplotlib

    cmap = matplotlib.colormaps["turbo_r"]
    rgb = cmap(np.linspace(0.0, 1.0, n))[:, :3]
    return np.round(rgb * 255).astype(int).tolist()


def _embedded_points(frame: Frame, transforms: list[np.ndarray], z_min: float,
                     max_points: int, seed: int = 0) -> np.ndarray:
    """The frame's LiDAR points (float32 xyz) in view for at least one of ``transforms``,
    randomly subsampled to at most ``max_points``."""
    xyz = np.asarray(frame.points[:, :3], dtype=np.float64)
    keep = np.zeros(len(xyz), dtype=bool)
    for T in transforms:
        keep |= project(xyz, frame.camera, T, z_min)[2]
    idx = np.flatnonzero(keep)
    if len(idx) > max_points:
        idx = np.sort(np.random.default_rng(seed).choice(idx, max_points, replace=False))
    return np.ascontiguousarray(xyz[idx], dtype="<f4")


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
            ("overlay frame", html.escape(frame.name)),
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

    The page is a single self-contained HTML file that makes no network request: its script
    draws the front as SVG, the camera image is a base64 JPEG and the LiDAR points base64
    float32.
    It shows the Pareto front (hover for a solution's variables, cost, deviation and reference
    errors; click to project with it), the projection of one frame's LiDAR points drawn on a
    canvas by depth (near is warm) with buttons for the initial, chosen and reference
    extrinsics, and a table of the run.

    Parameters
    ----------
    result : CalibrationResult
        The run (its front, chosen solution, ``T_init`` and, when known, ``T_ref``).
    frames : list of Frame
        The run's frames; ``frames[frame]`` is the one projected.
    path : str or Path
        The output file (conventionally ``interactive.html`` in the run directory); written
        atomically.
    frame : int, optional
        Which frame to project (clipped to the list); the first by default.
    max_points : int, optional
        At most this many LiDAR points are embedded: those in view for at least one of the
        front's, the initial or the reference extrinsic, randomly subsampled (fixed seed).

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
    z_min = float(result.settings.features.z_min)
    cam = f.camera
    transforms = [np.asarray(T) for T in result.front.T] + [result.T_init]
    if result.T_ref is not None:
        transforms.append(result.T_ref)
    pts = _embedded_points(f, transforms, z_min, max_points)
    ok, jpeg = cv2.imencode(".jpg", f.image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 BGR image
        raise RuntimeError("could not encode the camera image as JPEG")
    solutions = _solution_entries(result)
    ini = result.initial_error
    captions = {"initial": "initial extrinsic" + (
        f": error vs reference {_fmt_err(ini['rotation_deg'], ini['translation_cm'])}"
        if ini is not None else ""),
        "reference": "dataset reference extrinsic"}
    data = {
        "frame": f.name, "width": int(cam.width), "height": int(cam.height),
        "K": np.asarray(cam.K, dtype=float).tolist(), "z_min": z_min, "max_depth": MAX_DEPTH,
        "camera": {**cam.to_dict(), "params": [float(v) if np.isfinite(v) else None
                                               for v in cam.kernel_params()]},
        "image": "data:image/jpeg;base64," + base64.b64encode(jpeg.tobytes()).decode("ascii"),
        "points": {"count": int(len(pts)), "dtype": "float32", "layout": "xyz",
                   "b64": base64.b64encode(pts.tobytes()).decode("ascii")},
        "chosen": int(result.chosen),
        "T_init": np.asarray(result.T_init, dtype=float).tolist(),
        "T_ref": None if result.T_ref is None else np.asarray(result.T_ref, dtype=float).tolist(),
        "solutions": solutions, "plot": _plot_spec(result, solutions),
        "captions": captions, "lut": _depth_lut(),
    }
    buttons = ['<button type="button" data-view="initial" id="view-initial">initial</button>',
               '<button type="button" data-view="chosen" id="view-chosen">chosen</button>']
    if result.T_ref is not None:
        buttons.append('<button type="button" data-view="reference" id="view-reference">'
                       'reference</button>')
    # interactive.html puts the run table before the plot (the grid shows it on the right), so
    # the plot's container has its final width when the script sizes the figure.
    title = f"paretocal calibration run: {len(result.frames)} frame(s), n = {result.n_points}"
    # substitute() fails on a missing placeholder; the values (the script, the data) are not
    # scanned, so a $ in them is inert.
    page = Template(template("interactive.html")).substitute(
        title=html.escape(title), verdict=_verdict_banner(result), frame_name=html.escape(f.name),
        run_table=_run_table(result, f), buttons="".join(buttons),
        width=int(cam.width), height=int(cam.height), max_depth=f"{MAX_DEPTH:g}",
        n_points=len(pts), max_points=max_points, credit=html.escape(data_credit(f)),
        data=_json_script(data), css=template("interactive.css"),
        js=template("front_plot.js") + template("interactive.js"))
    atomic_write_text(path, page)
    return path
