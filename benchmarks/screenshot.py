"""A screenshot of a run's interactive page (``interactive.html``) in headless Chromium.

The images of the page in the documentation (``docs/images/interactive_*.png``) are made with
it (``interactive.html`` is written with the figures: not with ``--no-figures``)::

    make demo                                   # runs/demo: the 20 KITTI frames
    .venv/bin/python benchmarks/screenshot.py runs/demo --out docs/images/interactive_kitti.png

    .venv/bin/paretocal calibrate ../shared/data/pandaset/front --frames 0:20 --out runs/pandaset
    .venv/bin/python benchmarks/screenshot.py runs/pandaset --edges --zoom 2 --at 0.6 0.6 \\
        --out docs/images/interactive_pandaset.png

It opens the page (a run folder or the HTML file itself), waits until it has drawn, picks a
frame, an extrinsic and the layers, optionally zooms about a point of the image, and writes the
top of the page down to the end of the viewer as a PNG: a 256-colour palette image, scaled
down until it is at most ``--max-kb``. It needs the ``playwright`` package and a Chromium
(Debian's ``/usr/bin/chromium`` by default; ``playwright install`` is not needed). Prints the
page's size and what it shows.
"""

from __future__ import annotations

import argparse
import io
import math
import sys
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def shrink_png(png: bytes, max_bytes: int) -> tuple[bytes, tuple[int, int]]:
    """``png`` as a 256-colour palette PNG, scaled down by steps of 0.9 until it is at most
    ``max_bytes``; returns the bytes and the size (width, height) in px."""
    from PIL import Image

    img = Image.open(io.BytesIO(png)).convert("RGB")
    while True:
        q = img.quantize(colors=256, method=Image.Quantize.FASTOCTREE)
        buf = io.BytesIO()
        q.save(buf, "PNG", optimize=True)
        if buf.tell() <= max_bytes or img.width < 400:
            return buf.getvalue(), img.size
        img = img.resize((int(img.width * 0.9), int(img.height * 0.9)), Image.Resampling.LANCZOS)


def screenshot(page_path: Path, out: Path, frame: str | None = None, view: str = "chosen",
               colour: str = "depth", edges: bool = False, image: bool = True,
               zoom: float = 1.0, at: tuple[float, float] = (0.5, 0.5),
               viewport: tuple[int, int] = (1400, 1000), max_kb: int = 300,
               chromium: str = CHROMIUM) -> dict:
    """Write the screenshot; returns what it shows (frame, view, colour, zoom, sizes)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=BROWSER_ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(page_path.resolve().as_uri())
            page.wait_for_selector("body[data-ready='1']", timeout=120_000)
            names = page.evaluate("() => window.paretocal.data.frames.map(f => f.name)")
            if frame is not None:
                i = names.index(frame) if frame in names else int(frame)
                page.evaluate("i => window.paretocal.pick(i)", i)
                page.wait_for_function(
                    f"document.getElementById('overlay').dataset.frame === {names[i]!r}")
            if view != "chosen":
                page.click(f"#view-{view}")
            if not image:
                page.uncheck("#layer-image")
            if edges:
                page.check("#layer-edges")
            page.check(f"#colour-{colour}")
            if zoom != 1.0:
                box = page.locator("#overlay").bounding_box()
                x, y = box["x"] + at[0] * box["width"], box["y"] + at[1] * box["height"]
                page.mouse.move(x, y)
                while page.evaluate("() => window.paretocal.state.s") < zoom * 0.999:
                    s = page.evaluate("() => window.paretocal.state.s")
                    page.mouse.wheel(0, -min(300.0, 500.0 * math.log(zoom / s)))
                    page.wait_for_timeout(50)
            page.wait_for_timeout(300)
            bottom = page.evaluate(
                "() => { const r = document.querySelector('.viewer').getBoundingClientRect();"
                " return r.bottom + window.scrollY + 8; }")
            png = page.screenshot(full_page=True, clip={"x": 0, "y": 0, "width": viewport[0],
                                                        "height": bottom})
            state = page.evaluate(
                "() => { const c = document.getElementById('overlay'); return {frame: "
                "c.dataset.frame, view: c.dataset.solution, colour: c.dataset.colour, "
                "zoom: c.dataset.zoom, caption: document.getElementById('caption')"
                ".textContent}; }")
            if errors:
                raise RuntimeError(f"the page reported errors: {errors}")
        finally:
            browser.close()
    data, size = shrink_png(png, max_kb * 1000)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(data)
    return {**state, "png_bytes": len(data), "png_size": size,
            "page_bytes": page_path.stat().st_size, "frames": len(names)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("page", type=Path, help="a run folder or its interactive.html")
    ap.add_argument("--out", type=Path, required=True, help="the PNG to write")
    ap.add_argument("--frame", help="frame name or index (default: the page's first)")
    ap.add_argument("--view", default="chosen", choices=["chosen", "initial", "reference"])
    ap.add_argument("--colour", default="depth",
                    choices=["depth", "intensity", "groups", "none"])
    ap.add_argument("--edges", action="store_true", help="show the image edges")
    ap.add_argument("--no-image", action="store_true", help="hide the camera image")
    ap.add_argument("--zoom", type=float, default=1.0, help="zoom factor (wheel)")
    ap.add_argument("--at", type=float, nargs=2, default=(0.5, 0.5), metavar=("U", "V"),
                    help="where to zoom, as fractions of the canvas (default: the centre)")
    ap.add_argument("--viewport", type=int, nargs=2, default=(1400, 1000), metavar=("W", "H"))
    ap.add_argument("--max-kb", type=int, default=300, help="largest PNG (kB)")
    ap.add_argument("--chromium", default=CHROMIUM)
    a = ap.parse_args(argv)
    page = a.page / "interactive.html" if a.page.is_dir() else a.page
    info = screenshot(page, a.out, a.frame, a.view, a.colour, a.edges, not a.no_image, a.zoom,
                      tuple(a.at), tuple(a.viewport), a.max_kb, a.chromium)
    print(f"{a.out}: {info['png_size'][0]}x{info['png_size'][1]} px, "
          f"{info['png_bytes'] / 1000:.0f} kB; page {page} {info['page_bytes'] / 1e6:.2f} MB "
          f"({info['frames']} frames); frame {info['frame']}, view {info['view']}, "
          f"colour {info['colour']}, zoom {info['zoom']}")
    print(info["caption"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
