"""The interactive report page (``interactive.html``): its embedded data (the pure functions
that build it, every frame's layers and scores), that it is self-contained and small, and (in a
real headless chromium) that it renders and responds: the front, the extrinsic buttons, the
frame picker, the layers, zoom and pan."""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import re
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import pytest

from paretocal import Settings, calibrate
from paretocal.camera import Camera, project
from paretocal.geometry import correction_matrix
from paretocal.report.results import write_outputs
from paretocal.report.interactive import (DEPTH_PERCENTILES, MAX_IMAGE_WIDTH, dequantise_xyz,
                                          frame_scores, lidar_layer, page_data,
                                          quantise_xyz, write_interactive)

CHROMIUM = os.environ.get("PARETOCAL_CHROMIUM", "/usr/bin/chromium")
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync"]
DATA_RE = re.compile(r'<script type="application/json" id="paretocal-data">(.*?)</script>', re.S)


@pytest.fixture(scope="module")
def run(raw_frames, tmp_path_factory):
    """A small real calibration (2 frames) written with its figures: (result, frames, folder)."""
    frames = raw_frames[:2]
    T_init = raw_frames[0].T_ref @ correction_matrix(np.array([0.05, -0.03, 0.02, 1, -1, 0.5]))
    settings = Settings().replace(search={"pop": 16, "gens": 3}, decision={"polish": False})
    result = calibrate(frames, T_init, settings)
    out = tmp_path_factory.mktemp("interactive_run")
    written = write_outputs(result, out, frames)
    assert out / "interactive.html" in written
    return result, frames, out


def _page_data(text: str) -> dict:
    m = DATA_RE.search(text)
    assert m, "the page has no paretocal-data JSON blob"
    return json.loads(m.group(1))


def _points(entry: dict, key: str = "points") -> np.ndarray:
    """A frame entry's embedded returns (or feature points), as the page's script reads them."""
    layer = entry[key]
    q = np.frombuffer(base64.b64decode(layer["xyz"]), dtype="<i2").reshape(-1, 3)
    return dequantise_xyz(q, layer["scale"])


def _decode(uri: str, flags=cv2.IMREAD_COLOR) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8), flags)


def _in_view(xyz: np.ndarray, frame, T, z_min: float) -> int:
    return int(project(xyz, frame.camera, np.asarray(T), z_min)[2].sum())


class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))


class TestPage:
    def test_embedded_data(self, run):
        from scipy.spatial import cKDTree

        result, frames, out = run
        data = _page_data((out / "interactive.html").read_text(encoding="utf-8"))
        front = result.front
        assert len(data["solutions"]) == len(front.X) and data["chosen"] == result.chosen
        for i, s in enumerate(data["solutions"]):
            np.testing.assert_array_equal(np.array(s["T"]), front.T[i])
            assert s["n"] == int(round(front.X[i, 6]))
            assert s["f1"] == pytest.approx(front.F[i, 0]) and s["f2"] == pytest.approx(front.F[i, 1])
            assert s["ms"] == pytest.approx(front.columns["ms"][i])
            assert s["deviation_px"] == pytest.approx(front.columns["deviation_px"][i])
            assert s["ref_rotation_deg"] == pytest.approx(front.columns["ref_rotation_deg"][i])
            assert f"solution {i} of {len(front.X)}" in s["caption"]
        np.testing.assert_array_equal(np.array(data["T_init"]), result.T_init)
        np.testing.assert_array_equal(np.array(data["T_ref"]), result.T_ref)
        assert data["z_min"] == result.settings.features.z_min
        scene = result.objective.scene

        # Every frame of the run, in its order, with its camera, image, edges, returns and
        # feature points.
        assert [e["name"] for e in data["frames"]] == [f.name for f in frames] == result.frames
        Ts = list(front.T) + [result.T_init, result.T_ref]
        for k, (e, f) in enumerate(zip(data["frames"], frames)):
            cam = data["cameras"][e["camera"]]
            assert (cam["width"], cam["height"]) == f.size
            np.testing.assert_array_equal(np.array(cam["K"]), f.camera.K)
            assert e["scene_index"] == k

            # The returns: int16 on the frame's scale, each a return of the frame (to half a
            # step), in view for at least one extrinsic of the page.
            xyz = _points(e)
            assert len(xyz) == e["points"]["count"] and 2000 <= len(xyz) <= 5000
            assert e["points"]["scale"] < 0.005
            d, _ = cKDTree(np.asarray(f.points[:, :3], np.float64)).query(xyz, p=np.inf)
            assert d.max() <= e["points"]["scale"] / 2 + 1e-9
            seen = np.zeros(len(xyz), dtype=bool)
            for T in Ts:
                seen |= project(xyz, f.camera, T, data["z_min"])[2]
            assert seen.mean() > 0.995                      # quantised: a border point may leave
            inten = np.frombuffer(base64.b64decode(e["points"]["intensity"]), np.uint8)
            assert len(inten) == len(xyz) and inten.min() == 0 and inten.max() == 255

            # The image: a JPEG at most MAX_IMAGE_WIDTH wide, the frame's image downscaled.
            img = _decode(e["image"]["src"])
            assert e["image"]["src"].startswith("data:image/jpeg;base64,")
            assert img.shape[1] == e["image"]["width"] <= min(MAX_IMAGE_WIDTH, f.size[0])
            assert abs(img.shape[0] / img.shape[1] - f.size[1] / f.size[0]) < 0.01
            small = cv2.resize(f.image, img.shape[1::-1], interpolation=cv2.INTER_AREA)
            assert np.abs(img.astype(int) - small.astype(int)).mean() < 6

            # The edges: a 1-bit PNG of exactly the pixels the objective's distance transform
            # is zero on.
            edges = _decode(e["edges"]["src"], cv2.IMREAD_GRAYSCALE) > 0
            np.testing.assert_array_equal(edges, scene.frame_dt(k) == 0)
            assert e["edges"]["count"] == int(edges.sum()) > 1000

            # The feature points: the first of the scene's order, with their groups.
            a = int(scene.point_start[k])
            fx = _points(e, "features")
            m = len(fx)
            assert m == e["features"]["count"] == min(1000, scene.points_per_frame[k])
            np.testing.assert_allclose(fx, scene.frame_xyz(k)[:m], atol=e["features"]["scale"])
            g = np.frombuffer(base64.b64decode(e["features"]["group"]), np.uint8)
            np.testing.assert_array_equal(g, scene.group[a:a + m])

        # The scores: each frame's objective at every solution, as the objective has it.
        per = result.objective.chamfer(front.X, ucb_k=0.0)["per_frame"]
        np.testing.assert_allclose(np.array(data["scores"]["solutions"]), per, rtol=1e-9,
                                   atol=1e-9)

    def test_verdict_banner(self, run):
        result, _, out = run
        text = (out / "interactive.html").read_text(encoding="utf-8")
        # Two frames: unreliable, with every reason listed in a visible banner.
        assert result.reliability.verdict == "unreliable"
        banner = re.search(r'<div id="verdict" class="verdict unreliable">(.*?)</div>', text,
                           re.S)
        assert banner and "UNRELIABLE" in banner.group(1)
        assert banner.group(1).count("<li>") == len(result.reliability.reasons)
        assert "only 2 frame(s)" in banner.group(1)
        assert "95 % intervals per axis" not in banner.group(1)     # none for an unreliable result

    def test_self_contained(self, run):
        _, _, out = run
        text = (out / "interactive.html").read_text(encoding="utf-8")
        parser = _Tags()
        parser.feed(text)
        tags = parser.tags
        assert not [a for t, a in tags if t == "script" and "src" in a], "a <script src=...>"
        assert not [a for t, a in tags if t == "link"], "a <link> tag"
        assert not [t for t, _ in tags if t in ("iframe", "img", "object", "embed")]
        for t, a in tags:
            for key in ("src", "href", "action", "data"):
                v = (a.get(key) or "").strip().lower()
                assert not v.startswith(("http:", "https:", "//")), (t, key, v)
        # No plotting library: the page's own script draws the front, and the page is small.
        assert "plotly" not in text.lower()
        assert len(text.encode()) < 1_500_000                    # two frames
        # The SVG namespace is the one address in the script, an identifier, never fetched.
        rest = text.replace("http://www.w3.org/2000/svg", "")
        assert "http://" not in rest and "https://" not in rest
        assert "data: KITTI (Geiger et al., IJRR 2013), CC BY-NC-SA 3.0" in rest
        table = re.search(r'<table id="run-table">(.*?)</table>', rest, re.S).group(1)
        for word in ("frames", "chosen n", "error vs reference", "wall time", "paretocal"):
            assert word in table

    def test_options(self, run, tmp_path):
        result, frames, _ = run
        # No reference: no reference extrinsic, errors or button.
        cols = {k: v for k, v in result.front.columns.items() if not k.startswith("ref_")}
        plain = dataclasses.replace(result, T_ref=None,
                                    front=dataclasses.replace(result.front, columns=cols))
        path = write_interactive(plain, frames, tmp_path / "a.html", max_points=500)
        text = path.read_text(encoding="utf-8")
        data = _page_data(text)
        assert data["T_ref"] is None and data["frames"][0]["points"]["count"] == 500
        assert data["scores"]["reference"] is None
        assert 'data-view="reference"' not in text and 'data-view="initial"' in text
        assert "ref_rotation_deg" not in data["solutions"][0]
        assert not list(tmp_path.glob(".*.tmp*")), "the atomic write left a temporary file"
        with pytest.raises(ValueError):
            write_interactive(result, [], tmp_path / "b.html")

    def test_without_objective(self, run, tmp_path):
        """A run that kept no objective (a resumed one): no scores, no feature points, and the
        page says so; the edges, computed afresh with the run's settings, are the objective's."""
        result, frames, _ = run
        bare = dataclasses.replace(result, objective=None)
        text = write_interactive(bare, frames, tmp_path / "c.html").read_text(encoding="utf-8")
        data = _page_data(text)
        assert data["scores"] is None
        assert all(e["features"] is None and e["scene_index"] is None for e in data["frames"])
        assert "did not keep its objective" in text
        for k, e in enumerate(data["frames"]):
            edges = _decode(e["edges"]["src"], cv2.IMREAD_GRAYSCALE) > 0
            np.testing.assert_array_equal(edges, result.objective.scene.frame_dt(k) == 0)


# --- the pure functions that build the page's data ---------------------------------------------

def test_frame_scores_are_the_objectives_per_frame_terms(run):
    result, frames, _ = run
    obj = result.objective
    X = result.front.X
    want = obj.chamfer(X, ucb_k=0.0)["per_frame"]
    got = frame_scores(obj, result.front.T, X[:, 6])
    assert got.shape == (len(X), len(frames))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    # Any extrinsic, as the correction of the objective's own T_init that gives it.
    n = result.n_points
    ref = obj.chamfer(np.array([[0, 0, 0, 0, 0, 0, n]], float), ucb_k=0.0)["per_frame"][0]
    np.testing.assert_allclose(frame_scores(obj, obj.T_init[None], [n])[0], ref, rtol=1e-12)
    # The page's data holds the same numbers: every solution, initial and reference.
    data = page_data(result, frames, budget_bytes=None, max_points=300)
    s = data["scores"]
    np.testing.assert_allclose(np.array(s["solutions"]), want, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(s["initial"], ref, rtol=1e-9)
    np.testing.assert_allclose(s["reference"], frame_scores(obj, result.T_ref[None], [n])[0],
                               rtol=1e-12)
    assert s["n"] == n


def test_depth_scale_is_the_frames_percentiles(run):
    result, frames, _ = run
    z_min = result.settings.features.z_min
    for f in frames:
        layer = lidar_layer(f.points[:, :3], f.points[:, 3], f.camera,
                            [result.T_init, result.T_cam_lidar], result.T_cam_lidar, z_min, 1000)
        _, z, vis = project(f.points, f.camera, result.T_cam_lidar, z_min)
        assert layer["depth_range"] == pytest.approx(tuple(np.percentile(z[vis],
                                                                         DEPTH_PERCENTILES)))
        assert layer["in_view"] == int(vis.sum()) and layer["total"] == len(f.points)
        lo, hi = layer["depth_range"]
        assert 2 < lo < 10 < hi < 60, (lo, hi)              # a street: not the fixed 0-30 m
        assert len(layer["xyz"]) == 1000 and layer["xyz"].dtype == np.dtype("<i2")
        lo_i, hi_i = layer["intensity_range"]
        assert 0 <= lo_i < hi_i <= 1.0                      # KITTI's reflectance
    # The quantisation: half a step at most, the same arithmetic as the script.
    xyz = np.random.default_rng(0).uniform(-80, 80, (1000, 3))
    q, scale = quantise_xyz(xyz)
    assert np.abs(dequantise_xyz(q, scale) - xyz).max() <= scale / 2 + 1e-12
    assert scale == pytest.approx(np.abs(xyz).max() / 32767)


# --- the page in a real browser --------------------------------------------------------------

def _require_browser():
    """playwright's ``sync_playwright`` and a chromium binary. Missing either, the test skips with
    a reason saying how to enable it; with PARETOCAL_REQUIRE_OPTIONAL=1 (set by .ci/run) it fails
    instead, so CI always runs it."""
    required = os.environ.get("PARETOCAL_REQUIRE_OPTIONAL") == "1"
    missing = pytest.fail if required else pytest.skip
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        missing("playwright is not installed: `.venv/bin/pip install -e '.[test]'` (or "
                "`pip install playwright`); the test drives Debian's chromium, so "
                "`playwright install` is not needed")
    if not os.access(CHROMIUM, os.X_OK):
        missing(f"chromium not found at {CHROMIUM}: install it with `apt-get install -y "
                "--no-install-recommends chromium` (as .ci/run does) or point "
                "PARETOCAL_CHROMIUM at a chromium binary")
    return sync_playwright


SNAP_JS = """name => {
  const c = document.getElementById('overlay');
  window.__snaps = window.__snaps || {};
  window.__snaps[name] = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
}"""
DIFF_JS = """([a, b]) => {
  const x = window.__snaps[a], y = window.__snaps[b];
  let n = 0;
  for (let i = 0; i < x.length; i += 4)
    if (x[i] !== y[i] || x[i + 1] !== y[i + 1] || x[i + 2] !== y[i + 2]) n++;
  return n;
}"""
STATE_JS = """() => [document.getElementById('overlay').getAttribute('data-solution'),
                     document.getElementById('caption').textContent]"""


def _in_view_of_caption(caption: str) -> int:
    m = re.search(r"(\d+) of (\d+) embedded points in view", caption)
    assert m, caption
    return int(m.group(1))


def test_page_in_browser(request, tmp_path):
    sync_playwright = _require_browser()       # before the calibration, so a skip is cheap
    result, frames, out = request.getfixturevalue("run")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            _check_page(browser, result, frames, out, tmp_path)
        finally:
            browser.close()


def _open(browser, path: Path, width: int = 1400):
    """A new page at ``path``, drawn; returns (page, errors, failed requests, request URLs)."""
    page = browser.new_page(viewport={"width": width, "height": 1100})
    errors, failed, urls = [], [], []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: failed.append(r.url))
    page.on("request", lambda r: urls.append(r.url))
    page.goto(path.as_uri())
    page.wait_for_selector("body[data-ready='1']", timeout=60_000)
    return page, errors, failed, urls


def _check_page(browser, result, frames, out: Path, tmp_path: Path) -> None:
    """Open the page; check rendering, hover, a click on the front and the view buttons."""
    data = _page_data((out / "interactive.html").read_text(encoding="utf-8"))
    xyz, f, z_min = _points(data["frames"][0]), frames[0], data["z_min"]
    k, chosen = len(result.front.X), result.chosen
    assert k >= 2, "the test needs a front of at least two solutions"

    page, errors, failed, urls = _open(browser, out / "interactive.html")

    # Rendered: the plot with one SVG point per solution, the overlay of the chosen solution
    # on the first frame, projected as paretocal.camera.project does.
    assert page.locator("#pareto svg").count() == 1
    points = page.locator("#pareto .sol")
    assert points.count() == k
    sol, caption = page.evaluate(STATE_JS)
    assert sol == str(chosen) and f"solution {chosen} of {k} (chosen)" in caption
    assert page.evaluate("document.getElementById('overlay').dataset.frame") == f.name
    assert _in_view_of_caption(caption) == _in_view(xyz, f, result.T_cam_lidar, z_min) > 1000
    page.evaluate(SNAP_JS, "chosen")
    shot = tmp_path / "overlay.png"
    page.locator("#overlay").screenshot(path=str(shot))
    crop = cv2.imread(str(shot), cv2.IMREAD_COLOR)[2:-2, 2:-2]
    assert crop.size and (np.abs(crop.astype(int) - 255).sum(axis=2) > 30).mean() > 0.8
    page.locator("#pareto").scroll_into_view_if_needed()
    page.locator("#pareto").screenshot(path=str(tmp_path / "plot.png"))
    plot = cv2.imread(str(tmp_path / "plot.png"), cv2.IMREAD_COLOR)
    assert (plot.astype(int).sum(axis=2) < 600).mean() > 0.005      # axes, labels, markers

    # The solution furthest (on screen) from the others, not the chosen one: hover, then click.
    boxes = [points.nth(i).bounding_box() for i in range(k)]
    centres = np.array([[b["x"] + b["width"] / 2, b["y"] + b["height"] / 2] for b in boxes])
    dist = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(k) * 1e9
    order = [i for i in np.argsort(-dist.min(axis=1)) if i != chosen]
    target = int(order[0])
    x, y = centres[target]
    page.mouse.move(x, y)
    hover = page.locator("#pareto-tip")
    hover.first.wait_for(timeout=10_000)
    text = hover.first.text_content()
    assert f"solution {target}" in text and "yaw, pitch, roll" in text and "n = " in text
    page.mouse.click(x, y)
    page.wait_for_function(f"document.getElementById('overlay').dataset.solution === '{target}'",
                           timeout=10_000)
    sol, caption = page.evaluate(STATE_JS)
    assert f"solution {target} of {k}" in caption and "(chosen)" not in caption
    assert _in_view_of_caption(caption) == _in_view(xyz, f, result.front.T[target], z_min)
    page.evaluate(SNAP_JS, "clicked")
    assert page.evaluate(DIFF_JS, ["chosen", "clicked"]) > 500
    # The frame list shows each frame's score at the solution shown.
    want = data["scores"]["solutions"][target]
    got = page.locator("#frames .score").all_text_contents()
    assert got == [f"{v:.3f}" for v in want]
    page.screenshot(path=str(tmp_path / "interactive_clicked.png"), full_page=True)

    # The before/after buttons.
    page.click("#view-initial")
    page.wait_for_function("document.getElementById('overlay').dataset.solution === 'initial'")
    sol, caption = page.evaluate(STATE_JS)
    assert caption.startswith("initial extrinsic: error vs reference")
    assert _in_view_of_caption(caption) == _in_view(xyz, f, result.T_init, z_min)
    page.evaluate(SNAP_JS, "initial")
    assert page.evaluate(DIFF_JS, ["clicked", "initial"]) > 500
    assert page.evaluate(DIFF_JS, ["chosen", "initial"]) > 500
    page.click("#view-reference")
    page.wait_for_function("document.getElementById('overlay').dataset.solution === 'reference'")
    page.click("#view-chosen")
    page.wait_for_function(f"document.getElementById('overlay').dataset.solution === '{chosen}'")
    page.evaluate(SNAP_JS, "again")
    assert page.evaluate(DIFF_JS, ["chosen", "again"]) == 0

    assert not errors, f"console errors: {errors}"
    assert not failed, f"failed requests: {failed}"
    assert all(u.startswith(("file:", "data:")) for u in urls), urls
    page.close()


def test_page_projects_through_the_lens_model_in_browser(request, tmp_path):
    """The page's JavaScript projects through a distorted pinhole, a fisheye and a Mei camera
    exactly as paretocal.camera does (same points in view for every extrinsic)."""
    sync_playwright = _require_browser()
    result, frames, _ = request.getfixturevalue("run")
    K = frames[0].camera.K
    cams = {"radtan": Camera(K, 1242, 375, "pinhole", [-0.28, 0.09, 0.0008, -0.0005, -0.015]),
            "fisheye": Camera(K, 1242, 375, "fisheye", [0.08, -0.03, 0.01, -0.002]),
            "mei": Camera(K, 1242, 375, "mei", [0.0336, -0.0842, 0.001, -0.002, 0.0], xi=1.02)}
    views = {"initial": result.T_init, "reference": result.T_ref, "chosen": result.T_cam_lidar}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            for name, cam in cams.items():
                f = dataclasses.replace(frames[0], camera=cam)
                path = write_interactive(result, [f], tmp_path / f"{name}.html")
                data = _page_data(path.read_text(encoding="utf-8"))
                assert data["cameras"][0]["model"] == cam.model
                xyz, z_min = _points(data["frames"][0]), data["z_min"]
                page = browser.new_page(viewport={"width": 1400, "height": 1100})
                errors = []
                page.on("pageerror", lambda e, errors=errors: errors.append(str(e)))
                page.goto(path.as_uri())
                page.wait_for_selector("body[data-ready='1']", timeout=60_000)
                for view, T in views.items():
                    key = str(result.chosen) if view == "chosen" else view
                    page.click(f"#view-{view}")
                    page.wait_for_function(
                        f"document.getElementById('overlay').dataset.solution === '{key}'")
                    count = _in_view_of_caption(page.evaluate(STATE_JS)[1])
                    assert count == _in_view(xyz, f, T, z_min) > 1000, (name, view)
                    if view == "chosen":   # not what an ideal pinhole would show
                        assert count != _in_view(xyz, frames[0], T, z_min), name
                assert not errors, errors
                page.close()
        finally:
            browser.close()


@pytest.fixture(scope="module")
def run20(raw_frames, tmp_path_factory):
    """A quick real calibration of all 20 KITTI frames and its page: (result, frames, page)."""
    assert len(raw_frames) == 20
    T_init = raw_frames[0].T_ref @ correction_matrix(np.array([0.05, -0.03, 0.02, 1, -1, 0.5]))
    settings = Settings().replace(search={"pop": 16, "gens": 3}, decision={"polish": False})
    result = calibrate(raw_frames, T_init, settings)
    path = write_interactive(result, result.sweeps,
                             tmp_path_factory.mktemp("interactive20") / "interactive.html")
    return result, result.sweeps, path


def test_page_of_twenty_frames_is_small(run20):
    """Every frame, each with its layers, in under 3 MB."""
    result, frames, path = run20
    size = path.stat().st_size
    assert 1_000_000 < size < 3_000_000, size
    data = _page_data(path.read_text(encoding="utf-8"))
    assert [e["name"] for e in data["frames"]] == result.frames
    assert all(e["features"] and e["edges"]["count"] > 1000 and e["points"]["count"] >= 2000
               and e["image"]["quality"] >= 60 for e in data["frames"])
    assert len(data["scores"]["solutions"][result.chosen]) == 20


COUNT_JS = """rgb => {
  const c = document.getElementById('overlay'), d = c.getContext('2d')
    .getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  for (let i = 0; i < d.length; i += 4)
    if (rgb === null ? (d[i] || d[i + 1] || d[i + 2])
                     : (d[i] === rgb[0] && d[i + 1] === rgb[1] && d[i + 2] === rgb[2])) n++;
  return n;
}"""


def _wait_attr(page, name: str, value: str) -> None:
    page.wait_for_function(
        f"document.getElementById('overlay').dataset.{name} === {json.dumps(value)}",
        timeout=20_000)


def test_page_frames_layers_and_zoom_in_browser(request, tmp_path):
    """The frame picker changes the frame drawn; each layer toggles; zoom and pan change the
    view and the reset button restores it; no console error."""
    sync_playwright = _require_browser()
    result, frames, path = request.getfixturevalue("run20")
    assert path.stat().st_size < 3_000_000
    data = _page_data(path.read_text(encoding="utf-8"))
    z_min, T = data["z_min"], result.T_cam_lidar
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            page, errors, failed, urls = _open(browser, path)
            _check_frames_layers_zoom(page, result, frames, data, z_min, T)
            assert not errors, f"console errors: {errors}"
            assert not failed and all(u.startswith(("file:", "data:")) for u in urls), urls
            page.close()
        finally:
            browser.close()


def _check_frames_layers_zoom(page, result, frames, data, z_min, T) -> None:
    # The picker: one entry per frame, each with its score at the chosen extrinsic.
    items = page.locator("#frames button")
    assert items.count() == len(frames) == 20
    scores = data["scores"]["solutions"][result.chosen]
    assert page.locator("#frames .score").all_text_contents() == [f"{v:.3f}" for v in scores]
    assert page.locator("#frames button.active").get_attribute("data-frame") == "0"
    _wait_attr(page, "frame", frames[0].name)
    page.evaluate(SNAP_JS, "f0")

    # Another frame: its name on the canvas, other pixels, its own points in view.
    items.nth(7).click()
    _wait_attr(page, "frame", frames[7].name)
    assert page.locator("#frames button.active").get_attribute("data-frame") == "7"
    page.evaluate(SNAP_JS, "f7")
    assert page.evaluate(DIFF_JS, ["f0", "f7"]) > 50_000
    _, caption = page.evaluate(STATE_JS)
    xyz7 = _points(data["frames"][7])
    assert f"frame {frames[7].name}, edge objective {scores[7]:.3f} px" in caption
    assert _in_view_of_caption(caption) == _in_view(xyz7, frames[7], T, z_min) > 1000
    page.keyboard.press("ArrowRight")
    _wait_attr(page, "frame", frames[8].name)
    items.nth(0).click()
    _wait_attr(page, "frame", frames[0].name)
    page.evaluate(SNAP_JS, "back")
    assert page.evaluate(DIFF_JS, ["f0", "back"]) == 0

    # The layers. No LiDAR colouring: the points go.
    e0 = data["frames"][0]
    page.check("#colour-none")
    _wait_attr(page, "colour", "none")
    page.evaluate(SNAP_JS, "none")
    assert page.evaluate(DIFF_JS, ["f0", "none"]) > 5000
    # No image either: black.
    page.uncheck("#layer-image")
    _wait_attr(page, "layers", "")
    assert page.evaluate(COUNT_JS, None) == 0
    # The edges alone: exactly the objective's edge pixels, in the edge colour.
    page.check("#layer-edges")
    _wait_attr(page, "layers", "edges")
    assert page.evaluate(COUNT_JS, data["edge_color"]) == e0["edges"]["count"] > 1000
    assert page.evaluate(COUNT_JS, None) == e0["edges"]["count"]
    assert "image edges" in page.locator("#legend").text_content()
    page.check("#layer-image")
    _wait_attr(page, "layers", "image+edges")
    page.evaluate(SNAP_JS, "edges")
    assert page.evaluate(DIFF_JS, ["none", "edges"]) == e0["edges"]["count"]
    page.uncheck("#layer-edges")
    _wait_attr(page, "layers", "image")
    # The arrows pick frames also while a layer's checkbox has the focus (issue 45).
    assert page.evaluate("document.activeElement.id") == "layer-edges"
    page.keyboard.press("ArrowRight")
    _wait_attr(page, "frame", frames[1].name)
    page.keyboard.press("ArrowLeft")
    _wait_attr(page, "frame", frames[0].name)
    # Intensity, then the feature groups: other colours; the groups of the first n points.
    page.check("#colour-intensity")
    _wait_attr(page, "colour", "intensity")
    page.evaluate(SNAP_JS, "intensity")
    assert page.evaluate(DIFF_JS, ["f0", "intensity"]) > 2000
    assert "intensity" in page.locator("#legend").text_content()
    page.check("#colour-groups")
    _wait_attr(page, "colour", "groups")
    page.evaluate(SNAP_JS, "groups")
    assert page.evaluate(DIFF_JS, ["f0", "groups"]) > 2000
    assert page.evaluate(DIFF_JS, ["intensity", "groups"]) > 2000
    _, caption = page.evaluate(STATE_JS)
    n, fx = result.n_points, _points(e0, "features")
    m = re.search(r"feature points in view: (\d+) of the first (\d+)", caption)
    assert m and int(m.group(2)) == min(n, len(fx)), caption
    assert int(m.group(1)) == _in_view(fx[:n], frames[0], T, z_min) > 0
    legend = page.locator("#legend").text_content()
    assert all(g in legend for g in ("depth edge", "intensity edge", "smooth"))
    page.check("#colour-depth")
    _wait_attr(page, "colour", "depth")
    page.evaluate(SNAP_JS, "depth")
    assert page.evaluate(DIFF_JS, ["f0", "depth"]) == 0
    lo, hi = e0["points"]["depth_range"]
    legend = page.locator("#legend").text_content()
    assert f"depth {lo:.1f} m" in legend and f"{hi:.1f} m" in legend and "percentile" in legend

    # Zoom about the pointer, pan by dragging, reset.
    box = page.locator("#overlay").bounding_box()
    cx, cy = box["x"] + box["width"] * 0.6, box["y"] + box["height"] * 0.5
    page.mouse.move(cx, cy)
    page.mouse.wheel(0, -600)
    page.wait_for_function("Number(document.getElementById('overlay').dataset.zoom) > 1.5")
    page.wait_for_timeout(200)
    page.evaluate(SNAP_JS, "zoomed")
    assert page.evaluate(DIFF_JS, ["f0", "zoomed"]) > 50_000
    zoom = float(page.evaluate("document.getElementById('overlay').dataset.zoom"))
    page.mouse.down()
    page.mouse.move(cx - 150, cy - 40, steps=5)
    page.mouse.up()
    page.wait_for_timeout(200)
    page.evaluate(SNAP_JS, "panned")
    assert page.evaluate(DIFF_JS, ["zoomed", "panned"]) > 50_000
    assert float(page.evaluate("document.getElementById('overlay').dataset.zoom")) == zoom
    page.click("#zoom-reset")
    _wait_attr(page, "zoom", "1.000")
    page.evaluate(SNAP_JS, "reset")
    assert page.evaluate(DIFF_JS, ["f0", "reset"]) == 0


def test_page_layout_at_narrow_widths_in_browser(request):
    """At 900 px and narrower the Pareto plot stays beside or above the run's table, never
    over it (issue 45: it covered the table at 900 px), and the page does not scroll
    sideways."""
    sync_playwright = _require_browser()
    _, _, path = request.getfixturevalue("run20")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            for width in (900, 800, 700):
                page, errors, _, _ = _open(browser, path, width)
                plot = page.locator("#pareto svg").bounding_box()
                table = page.locator("#run-info table").first.bounding_box()
                apart = (plot["x"] + plot["width"] <= table["x"] + 0.5
                         or table["y"] + table["height"] <= plot["y"] + 0.5
                         or plot["y"] + plot["height"] <= table["y"] + 0.5)
                assert apart, (width, plot, table)
                assert page.evaluate("document.documentElement.scrollWidth") <= width, width
                assert not errors, errors
                page.close()
        finally:
            browser.close()


def test_pareto_png_draws_both_fronts_on_one_point_set_and_says_so(raw_frames):
    """The polish re-chooses the feature points at the estimate and scores the final front on
    them; the search scored its front on those chosen at the start. pareto.png drew that
    front at a better f1 than the polished one without saying why (issue 45): it now draws it
    re-scored on the final points, says so in the legend and a caption, and there the
    polished front is the better one."""
    from paretocal.report.figures import pareto_plot, searched_front

    T_init = raw_frames[0].T_ref @ correction_matrix(np.array([0.05, -0.03, 0.02, 1, -1, 0.5]))
    r = calibrate(raw_frames[:2], T_init, Settings().replace(search={"pop": 16, "gens": 3}))
    assert r.settings.decision.polish and r.settings.features.reselect
    Fn, label, caption = searched_front(r)
    X = r.nsga_front[0].copy()
    X[:, 6] = np.clip(X[:, 6], *r.n_range)
    np.testing.assert_array_equal(Fn, r.objective.evaluate(X))
    assert "re-scored on the final points" in label and "features.reselect" in caption
    assert r.front.F[:, 0].min() <= Fn[:, 0].min()
    fig = pareto_plot(r)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert label in legend and any(caption[:40] in t.get_text() for t in fig.texts)
    # Without the re-selection both fronts share one objective: drawn as scored, no caption.
    same = dataclasses.replace(r, settings=r.settings.replace(features={"reselect": False}))
    Fs, label, caption = searched_front(same)
    assert Fs is r.nsga_front[1] and label == "NSGA-II front (before polish)" and caption == ""


def test_importing_the_figures_leaves_matplotlib_alone(tmp_path):
    """The report draws on Figure objects: importing it must not switch a user's backend (a
    notebook's inline one, an application's Qt one) nor need pyplot."""
    import subprocess
    import sys

    code = ("import matplotlib; matplotlib.use('svg'); import paretocal.report.figures as f; "
            "import paretocal.report.study_figures, paretocal.report.fleet; "
            "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend(); "
            "import sys; assert 'matplotlib.pyplot' not in sys.modules; "
            "fig, ax = f.subplots(1, 2, figsize=(4, 2)); ax[0].plot([0, 1]); "
            f"f.save_figure(fig, {str(tmp_path / 'x.png')!r})")
    subprocess.run([sys.executable, "-c", code], check=True)
    assert (tmp_path / "x.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_comparison_page_in_browser(tmp_path, raw_frames):
    """``compare A B SOURCE --page``: every frame with its score at A and at B, the A / B
    buttons change the projection, the layers work, no console error, no request."""
    sync_playwright = _require_browser()
    from paretocal.check import compare_extrinsics
    from paretocal.config import Settings
    from paretocal.geometry import apply_correction
    from paretocal.report.interactive import write_comparison

    frames = raw_frames[:4]
    T = frames[0].T_ref
    c = compare_extrinsics(T, apply_correction(T, [0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), frames)
    path = write_comparison(c, list(c.sweeps), Settings(), tmp_path / "compare.html")
    data = _page_data(path.read_text(encoding="utf-8"))
    assert data["plot"] is None and [s["caption"][0] for s in data["solutions"]] == ["A", "B"]
    np.testing.assert_allclose([[v for v in row] for row in data["scores"]["solutions"]],
                               c.frame_scores, rtol=1e-12)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            page, errors, failed, urls = _open(browser, path)
            assert page.locator("#frames button").count() == 4
            # B is shown first, with its scores; A moves the points and shows its own.
            b = [f"{v:.3f}" for v in c.frame_scores[1]]
            assert page.locator("#frames .score").all_text_contents() == b
            page.evaluate(SNAP_JS, "b")
            page.click("#view-a")
            page.wait_for_function("document.getElementById('view-a').className === 'active'")
            a = [f"{v:.3f}" for v in c.frame_scores[0]]
            assert page.locator("#frames .score").all_text_contents() == a
            page.evaluate(SNAP_JS, "a")
            assert page.evaluate(DIFF_JS, ["a", "b"]) > 1000
            page.click("#colour-intensity")
            page.click("#layer-edges")
            assert page.locator("#colour-groups").is_disabled()   # no calibration ran
            assert "the frames prefer A" in page.locator("#verdict").text_content()
            assert not errors, f"console errors: {errors}"
            assert not failed and all(u.startswith(("file:", "data:")) for u in urls), urls
            page.close()
        finally:
            browser.close()


def test_pandaset_page_in_browser(request, tmp_path, data):
    """A PandaSet run's page (1920 x 1080 images, a cloud in a vehicle frame): every frame,
    each layer and the front's solutions draw, no console error; within the page's budget
    (fewer frames take more of it each; measured: 2.84 MB for 20 front frames)."""
    sync_playwright = _require_browser()
    root = data / "pandaset" / "front"
    if not (root / "calib.yaml").is_file():
        pytest.skip("PandaSet sample not present")
    from paretocal.io import load_frames

    frames = load_frames(root, "0:3")
    T_init = frames[0].T_ref @ correction_matrix(np.array([0.05, -0.03, 0.02, 1, -1, 0.5]))
    settings = Settings().replace(search={"pop": 16, "gens": 3}, decision={"polish": False})
    result = calibrate(frames, T_init, settings)
    path = write_interactive(result, result.sweeps, tmp_path / "interactive.html")
    assert path.stat().st_size < 3_000_000
    page_data = _page_data(path.read_text(encoding="utf-8"))
    assert [e["name"] for e in page_data["frames"]] == result.frames
    assert all(e["image"]["width"] <= 1280 for e in page_data["frames"])
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS, headless=True)
        try:
            page, errors, failed, urls = _open(browser, path)
            assert page.locator("#frames button").count() == 3
            snaps = []
            for k in range(3):
                page.locator("#frames button").nth(k).click()
                _wait_attr(page, "frame", result.frames[k])
                page.evaluate(SNAP_JS, f"f{k}")
                snaps.append(f"f{k}")
            assert page.evaluate(DIFF_JS, ["f0", "f2"]) > 50_000
            for colour in ("intensity", "groups", "none", "depth"):
                page.check(f"#colour-{colour}")
                _wait_attr(page, "colour", colour)
            page.check("#layer-edges")
            _wait_attr(page, "layers", "image+edges")
            page.evaluate(SNAP_JS, "edges")
            assert page.evaluate(DIFF_JS, ["f2", "edges"]) > 1000
            page.click("#view-initial")
            page.wait_for_function("document.getElementById('view-initial').className === 'active'")
            assert not errors, f"console errors: {errors}"
            assert not failed and all(u.startswith(("file:", "data:")) for u in urls), urls
            page.close()
        finally:
            browser.close()
