"""The README's picture: a run's overlays before and after the calibration, and its Pareto front.

Made from the figures ``make demo`` writes into ``runs/demo``::

    make demo
    .venv/bin/python benchmarks/demo_figure.py runs/demo --out docs/images/demo_kitti.png

The overlays (``overlay_before.png``, ``overlay_after.png``: every LiDAR return of the first frame
coloured by depth, at the initial and at the chosen extrinsic) are stacked above the front
(``pareto.png``), each scaled to one width, and the whole is written as a 256-colour palette PNG
of at most ``--max-kb`` (scaled down further when needed). The figures keep their own titles and
the data's credit line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def compose(run: Path, out: Path, width: int = 1200, max_kb: int = 600) -> tuple[int, int]:
    """Write the picture of run folder ``run`` to ``out``; returns its size (width, height) in px."""
    import io

    from PIL import Image

    parts = []
    for name in ("overlay_before.png", "overlay_after.png", "pareto.png"):
        path = run / name
        if not path.is_file():
            raise SystemExit(f"{path} not found: the run was made with --no-figures, or is not a run")
        img = Image.open(path).convert("RGB")
        parts.append(img.resize((width, round(img.height * width / img.width)),
                                Image.Resampling.LANCZOS))
    canvas = Image.new("RGB", (width, sum(p.height for p in parts)), "white")
    y = 0
    for p in parts:
        canvas.paste(p, (0, y))
        y += p.height
    while True:
        buf = io.BytesIO()
        canvas.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(buf, "PNG", optimize=True)
        if buf.tell() <= max_kb * 1000 or canvas.width < 600:
            break
        canvas = canvas.resize((int(canvas.width * 0.9), int(canvas.height * 0.9)),
                               Image.Resampling.LANCZOS)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(buf.getvalue())
    return canvas.size


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a run folder written with its figures")
    ap.add_argument("--out", type=Path, required=True, help="the PNG to write")
    ap.add_argument("--width", type=int, default=1200, help="width in px (default 1200)")
    ap.add_argument("--max-kb", type=int, default=600, help="largest file size in kB (default 600)")
    args = ap.parse_args(argv)
    w, h = compose(args.run, args.out, args.width, args.max_kb)
    print(f"wrote {args.out} ({w} x {h} px, {args.out.stat().st_size / 1000:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
