"""The calibration target: a checkerboard described in calib.yaml's ``board:`` section (or a
``board.yaml`` beside it), validated like the rest of calib.yaml.

The section's form (docs/board.md)::

    board:
      kind: checkerboard
      squares: [9, 7]            # along the board's width and along its height
      square_m: 0.07             # the side of one square (m)
      size_m: [0.767, 0.626]     # the whole board, white margin included (m)
      margin_mm: [137, 136]      # optional: size minus the squares, per direction (mm)

The squares are centred on the board (the margin is the same on opposite sides): a
checkerboard with an odd number of squares both ways looks the same turned half a turn, so
its corners cannot tell which side a wider margin would be on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, quote

#: The kinds of board the tool detects.
BOARD_KINDS = ("checkerboard",)
#: The keys of a ``board:`` section.
BOARD_KEYS = ("kind", "squares", "square_m", "size_m", "margin_mm")
#: A checkerboard needs at least this many squares each way: two inner corners per row and
#: column are the fewest a corner detector can order.
MIN_SQUARES = 3
#: How far a stated ``margin_mm`` may differ from ``size_m`` minus the squares (mm): the
#: rounding of a figure given to the millimetre.
MARGIN_TOL_MM = 1.0


@dataclass(frozen=True)
class Board:
    """A checkerboard target.

    Attributes
    ----------
    squares : tuple of int, shape (2,)
        Squares along the board's width and along its height.
    square_m : float
        The side of one square (m).
    size_m : tuple of float, shape (2,)
        The whole board's width and height, white margin included (m).
    kind : str
        ``"checkerboard"``.
    """

    squares: tuple[int, int]
    square_m: float
    size_m: tuple[float, float]
    kind: str = "checkerboard"

    @property
    def inner(self) -> tuple[int, int]:
        """Inner corners along the width and the height (OpenCV's pattern size)."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def margin_m(self) -> tuple[float, float]:
        """The white margin on each side, along the width and the height (m)."""
        (w, h), (nx, ny) = self.size_m, self.squares
        return (w - nx * self.square_m) / 2.0, (h - ny * self.square_m) / 2.0

    def corners_m(self) -> np.ndarray:
        """The inner corners in the board's frame, shape (nx * ny, 3) (m): origin at the board's
        centre, x along its width, y along its height, z = 0; row by row (x fastest), the order
        of OpenCV's detectors."""
        nx, ny = self.inner
        x = (np.arange(nx) - (nx - 1) / 2.0) * self.square_m
        y = (np.arange(ny) - (ny - 1) / 2.0) * self.square_m
        gx, gy = np.meshgrid(x, y)
        return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])

    def square_centres_m(self) -> tuple[np.ndarray, np.ndarray]:
        """The centres of the squares in the board's frame, shape (sx * sy, 3) (m), and their
        colour parity (0 or 1), shape (sx * sy,): squares of one parity share a colour."""
        sx, sy = self.squares
        x = (np.arange(sx) - (sx - 1) / 2.0) * self.square_m
        y = (np.arange(sy) - (sy - 1) / 2.0) * self.square_m
        gx, gy = np.meshgrid(x, y)
        i, j = np.meshgrid(np.arange(sx), np.arange(sy))
        return (np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]),
                ((i + j) % 2).ravel())

    def outline_m(self) -> np.ndarray:
        """The board's four outer corners in its frame, shape (4, 3) (m), in order around it."""
        w, h = self.size_m[0] / 2.0, self.size_m[1] / 2.0
        return np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])

    def to_dict(self) -> dict:
        """As calib.yaml's ``board:`` section (and result.json's ``board.board``)."""
        return {"kind": self.kind, "squares": list(self.squares), "square_m": self.square_m,
                "size_m": list(self.size_m)}


def _number(value) -> float | None:
    """``value`` as a finite float, or None (booleans and text are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        return None
    v = float(value)
    return v if math.isfinite(v) else None


def _pair(value) -> list | None:
    return list(value) if isinstance(value, (list, tuple)) and len(value) == 2 else None


def read_board(section, path: str | Path, where: str = "board") -> Board:
    """The board of a calib.yaml ``board:`` section (or a board.yaml's), validated.

    Parameters
    ----------
    section : object
        The section as read from YAML.
    path : str or path
        The file, for messages.
    where : str
        The section's name in the file, for messages (``board``, ``cameras.left.board``).

    Raises
    ------
    InputError
        One line naming the file, the key and what is wrong: an unknown key or kind, a square
        count that is not two whole numbers of at least :data:`MIN_SQUARES`, sizes that are not
        positive, a board smaller than its squares, a margin that disagrees with the sizes.
    """
    from .layouts import check_keys

    if not isinstance(section, dict):
        raise InputError(f"{path}: {where} must be a mapping with kind, squares, square_m and "
                         f"size_m, got {quote(section)}")
    check_keys(path, section, BOARD_KEYS, where)
    for key in ("kind", "squares", "square_m", "size_m"):
        if section.get(key) is None:
            raise InputError(f"{path}: {where}.{key} is missing (a board needs kind, squares, "
                             "square_m and size_m)")
    kind = section["kind"]
    if not isinstance(kind, str) or kind.strip().lower() not in BOARD_KINDS:
        raise InputError(f"{path}: {where}.kind {quote(kind)} is not one of "
                         f"{', '.join(BOARD_KINDS)}")
    squares = _pair(section["squares"])
    if squares is None or not all(
            _number(v) is not None and float(v) == int(v) and int(v) >= MIN_SQUARES
            for v in squares):
        raise InputError(f"{path}: {where}.squares must be two whole numbers of at least "
                         f"{MIN_SQUARES} (the squares along the board's width and height), got "
                         f"{quote(section['squares'])}")
    nx, ny = (int(v) for v in squares)
    square = _number(section["square_m"])
    if square is None or square <= 0:
        raise InputError(f"{path}: {where}.square_m must be a positive number of metres, got "
                         f"{quote(section['square_m'])}")
    size = _pair(section["size_m"])
    sizes = [] if size is None else [_number(v) for v in size]
    if size is None or any(v is None or v <= 0 for v in sizes):
        raise InputError(f"{path}: {where}.size_m must be two positive numbers of metres (the "
                         f"whole board's width and height), got {quote(section['size_m'])}")
    w, h = (float(v) for v in size or ())
    for name, s, n in (("width", w, nx), ("height", h, ny)):
        if s < n * square - 1e-9:
            raise InputError(f"{path}: {where}.size_m: the board's {name} {s:g} m is smaller "
                             f"than its {n} squares of {square:g} m ({n * square:g} m)")
    if section.get("margin_mm") is not None:
        margin = _pair(section["margin_mm"])
        got = [] if margin is None else [_number(v) for v in margin]
        if margin is None or any(v is None for v in got):
            raise InputError(f"{path}: {where}.margin_mm must be two numbers of millimetres, "
                             f"got {quote(section['margin_mm'])}")
        want = [1000.0 * (w - nx * square), 1000.0 * (h - ny * square)]
        if any(abs(float(g) - m) > MARGIN_TOL_MM for g, m in zip(margin or (), want)):
            raise InputError(f"{path}: {where}.margin_mm {quote(section['margin_mm'])} "
                             f"disagrees with size_m minus the squares ({want[0]:.0f}, "
                             f"{want[1]:.0f} mm)")
    return Board(squares=(nx, ny), square_m=square, size_m=(w, h))
