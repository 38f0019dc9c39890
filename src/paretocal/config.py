"""Every setting of a calibration, as frozen dataclasses loadable from a YAML/JSON file.

A config file mirrors the sections below, e.g.::

    search: {pop: 400, gens: 150, seed: 3}
    objective: {w_edge: 0.8}

Unknown sections or keys are errors (a typo must not silently fall back to a default).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SettingsError, key_list, quote


@dataclass(frozen=True)
class FeatureSettings:
    """Image and LiDAR feature extraction (see :mod:`paretocal.features`)."""

    blur_sigma: float = 1.0          #: Gaussian sigma (px) before Canny
    canny_low: float = 50.0          #: Canny hysteresis thresholds
    canny_high: float = 150.0
    canny_relative: bool = False     #: thresholds for a full-range image, scaled by exposure
    equalize: bool = False           #: local contrast equalised (CLAHE) before Canny
    #: Canny's high threshold as this many noise deviations of the image's gradient (the low
    #: one keeps its ratio); None: the thresholds above.
    canny_noise: float | None = None
    min_edge_px: int = 0             #: drop edge fragments smaller than this (px)
    depth_jump_m: float = 1.0        #: along-ring range jump for a depth edge (m)
    cross_ring: bool = True          #: also detect edges against the rings above and below
    cross_jump_m: float = 0.3        #: across rings: jump > max(cross_jump_m, cross_jump_rel * r)
    cross_jump_rel: float | None = None  #: None: from the ring spacing (features.lidar)
    ground_tol_m: float | None = None  #: ignore cross-ring pairs with both returns on the ground
    along_fraction: float = 0.5      #: edge placement between near and far ray, along a ring
    cross_fraction: float = 0.25     #: the same across rings (see README, Method)
    edge_support: bool = False       #: keep depth edges only where the near side is a surface
    edge_contour: bool = False       #: keep depth edges only where their contour continues
    sky_edges: bool = False          #: also edges at the top of objects against the sky
    intensity_jump: float = 0.5      #: intensity jump for an intensity edge (x the 99th pct)
    min_range_m: float = 1.5
    max_range_m: float = 70.0
    smooth_ratio: float = 1.0        #: smooth points kept per depth edge (for the contrast term)
    ring_method: str = "auto"        #: "auto", "field", "scan", "lines" or "elevation"
    view_margin_px: float = 60.0     #: keep feature points projecting this far outside the image
    z_min: float = 0.1               #: minimum depth (m) of a projectable point
    reselect: bool = True            #: after the search, choose the points in view again
    grid: tuple[int, int] = (8, 4)   #: image cells (columns, rows) stratifying the point order
    edge_weight: str = "none"        #: "none" or "sqrt_jump" (weight depth edges by strength)


@dataclass(frozen=True)
class ObjectiveSettings:
    """The two objectives (see :mod:`paretocal.objective`)."""

    chamfer: str = "edge-dt"         #: "edge-dt" (default, sound) or "paper" (as written)
    truncation_px: float = 10.0      #: robust cap of the per-point distance (px)
    outside: str = "mean"            #: charge for points out of view: "mean" DT or "truncation"
    w_edge: float = 0.8              #: w1, weight of the depth-edge term; w2 = 1 - w1 (intensity)
    contrast: float = 1.0            #: weight of the smooth-point term subtracted (0 disables)
    ucb_k: float | None = None       #: multiplier of the sampling error; None: sqrt(2 ln evals)
    cost: str = "model"              #: "model" (deterministic) or "psutil" (paper, measured)
    holdout: float = 0.0             #: share of each frame's points kept out of the search
    evaluator: str = "auto"          #: "auto", "numba" or "numpy"


#: The search box is this many times the stated initial error per axis: a start at the edge
#: of its stated error still has room around the truth for the search to settle.
BOX_MARGIN = 1.5
#: Smallest box (m, deg): the objective's own optimum can lie a few cm / tenths of a degree
#: from the truth, and the polish needs room around it.
MIN_BOUND_T_M = 0.05
MIN_BOUND_R_DEG = 1.0


@dataclass(frozen=True)
class SearchSettings:
    """NSGA-II over ``[x, y, z, yaw, pitch, roll, n]`` (see :mod:`paretocal.search`)."""

    pop: int = 300
    gens: int = 120
    seed: int = 0
    #: How far off the initial extrinsic may be, per axis (deg, m): sets the search box.
    init_error_deg: float = 10.0
    init_error_m: float = 0.3
    bound_t_m: float | None = None   #: +- bound of x, y, z (m); None: from init_error_m
    bound_r_deg: float | None = None  #: +- bound of yaw, pitch, roll (deg); None: from init_error
    n_min: int | None = None         #: feature points per frame; None -> automatic
    n_max: int | None = None
    sbx_prob: float = 0.9
    sbx_eta: float = 15.0
    pm_eta: float = 20.0
    include_init: bool = True        #: seed the population with the zero correction
    seed_grid_deg: float | None = 2.5  #: rotation grid step for seeding (None: no grid)
    seed_truncation_px: float = 30.0  #: coarse objective's DT truncation for the grid
    seed_points: int = 200           #: points per frame for the grid
    seed_count: int = 8              #: grid poses placed in the initial population
    seed_grid_t_m: float | None = None  #: joint rotation x translation grid step (m); off
    #: The wide start (paretocal.wide): "auto" when the stated error is wide, "on", "off".
    wide: str = "auto"

    @property
    def bound_t(self) -> float:
        """The translation bound in effect (m): ``bound_t_m`` or ``BOX_MARGIN`` times the
        stated initial error (at least ``MIN_BOUND_T_M``)."""
        if self.bound_t_m is not None:
            return float(self.bound_t_m)
        return max(BOX_MARGIN * self.init_error_m, MIN_BOUND_T_M)

    @property
    def bound_r(self) -> float:
        """The rotation bound in effect (deg), like :attr:`bound_t`."""
        if self.bound_r_deg is not None:
            return float(self.bound_r_deg)
        return min(max(BOX_MARGIN * self.init_error_deg, MIN_BOUND_R_DEG), 90.0)


@dataclass(frozen=True)
class DecisionSettings:
    """How one solution is chosen from the front (see :mod:`paretocal.decide`)."""

    rule: str = "knee"               #: "knee", "knee-chamfer", "budget" or "min-chamfer"
    budget_ms: float | None = None   #: with rule "budget": modelled evaluation time limit (ms)
    max_deviation_px: float = 1.0    #: knee: only solutions this close to the best-supported one
    polish: bool = True              #: polish the front locally at each solution's n
    polish_iters: int = 12           #: Newton iterations of the polish
    restarts: int = 1                #: independent restarts checking the result (0: none)
    restart_share: float = 0.25      #: each restart's share of the search's evaluations
    motion_check: bool = True        #: check the rotation against the recording's motion


@dataclass(frozen=True)
class MotionSettings:
    """De-skewing clouds recorded while moving (see :mod:`paretocal.lidar.trajectory`)."""

    deskew: str = "auto"             #: "auto": when every cloud has per-point time; "off"
    time_offset_s: float = 0.0       #: image time minus the sweep's centre time (s)
    per_frame: bool = True           #: each frame its own twist (the speed may change)
    points: int = 15000              #: points per cloud for the ego-motion registration


@dataclass(frozen=True)
class Settings:
    """All settings of one calibration run.

    Every section is a frozen dataclass; a ``--config`` file gives them by section name
    (``search: {pop: 1000, gens: 200}``).

    Attributes
    ----------
    features : FeatureSettings
        Image and LiDAR feature extraction.
    objective : ObjectiveSettings
        The two objectives.
    search : SearchSettings
        NSGA-II, its box (the stated initial error, m and deg) and the seeding.
    decision : DecisionSettings
        How one solution is chosen from the front; the polish and the verdict's restarts.
    motion : MotionSettings
        De-skewing clouds recorded while moving.
    camera : int
        KITTI camera index 0-3 (2, the left colour camera).
    frames : str or None
        The frames' selection (``"0:20"``, ``"0,3,7"`` or stems); None: every frame.
    """

    features: FeatureSettings = field(default_factory=FeatureSettings)
    objective: ObjectiveSettings = field(default_factory=ObjectiveSettings)
    search: SearchSettings = field(default_factory=SearchSettings)
    decision: DecisionSettings = field(default_factory=DecisionSettings)
    motion: MotionSettings = field(default_factory=MotionSettings)
    camera: int = 2
    frames: str | None = None

    def replace(self, keep_none: bool = False, **sections: dict[str, Any]) -> "Settings":
        """A copy with some fields of some sections replaced.

        ``None`` values are ignored (an option not given on the command line), unless
        ``keep_none``: then ``None`` is a value like any other, for the fields that allow it
        (``seed_grid_deg: null`` turns the seed grid off). Configuration files, saved runs and
        batch workers read settings with ``keep_none`` (see :func:`settings_from_mapping`).

        Parameters
        ----------
        keep_none : bool
            ``None`` is a value like any other.
        **sections : dict
            By section name (``features``, ``objective``, ``search``, ``decision``,
            ``motion``), the fields to replace, e.g. ``search={"pop": 300, "seed": 0}``.

        Returns
        -------
        Settings

        Raises
        ------
        SettingsError
            An unknown section or field, or a value of the wrong type.
        """
        out = self
        for name, values in sections.items():
            if not keep_none:
                values = {k: v for k, v in values.items() if v is not None}
            if not values:
                continue
            current = getattr(out, name, None)
            if dataclasses.is_dataclass(current) and not isinstance(current, type):
                values = _renamed(name, values)
                _check_keys(type(current), values, name)
                values = {k: _coerce(f"{name}.{k}", v, _field_types(type(current))[k])
                          for k, v in values.items()}
                section: dict[str, Any] = {name: dataclasses.replace(current, **values)}
                out = dataclasses.replace(out, **section)
            else:
                raise SettingsError(f"unknown settings section {quote(name)}")
        return out

    @property
    def ucb_k(self) -> float:
        """The sampling-error multiplier in effect: the setting, or ``sqrt(2 ln M)`` for the
        ``M = pop * gens`` evaluations of the search (see :mod:`paretocal.objective.chamfer`)."""
        if self.objective.ucb_k is not None:
            return float(self.objective.ucb_k)
        import math

        return math.sqrt(2.0 * math.log(max(self.search.pop * self.search.gens, 2)))

    def to_dict(self) -> dict[str, Any]:
        """Every setting by section, as ``result.json``'s ``config`` holds it."""
        return dataclasses.asdict(self)

    def validate(self) -> "Settings":
        """Raise :class:`SettingsError` naming the option when a value is out of range."""
        for section in (self.search, self.objective, self.features, self.decision, self.motion):
            for fl in fields(section):
                v = getattr(section, fl.name)
                if isinstance(v, float) and not math.isfinite(v):
                    raise SettingsError(f"{_option(fl.name)} {v}: must be a finite number")
        for (section_name, name), allowed in CHOICES.items():
            value = getattr(getattr(self, section_name), name)
            if value not in allowed:
                raise SettingsError(f"{_option(name)} {quote(value)}: choose "
                                    f"{', '.join(allowed[:-1])} or {allowed[-1]}")
        _check_search(self.search)
        _check_objective(self.objective)
        _check_decision(self.decision)
        _check_motion(self.motion)
        _check_features(self.features)
        if not 0 <= self.camera <= 3:          # the words of the layouts that have cameras
            raise SettingsError(f"--camera {self.camera}: must be 0, 1, 2 or 3")
        _check_ranges(self)
        _check_seed_grids(self.search)
        return self


#: Memory the search holds per individual at the peak of a generation, in bytes: the parents
#: and their offspring (7 variables, 2 objectives, rank, crowding), the candidates' extrinsics
#: and, per frame, the objective's sums over the three feature groups with their temporaries.
#: It follows from array shapes alone, not from the data: measured with tracemalloc (one
#: generation at populations of 20 000 and 80 000 on 1, 3 and 6 frames: 457 + 262 bytes per
#: frame, the same at both sizes) and rounded up; tests/test_bad_input.py measures it again.
#: The frames' own data (images, clouds, distance transforms) come on top.
SEARCH_BYTES_PER_INDIVIDUAL = 512
SEARCH_BYTES_PER_INDIVIDUAL_FRAME = 288


def check_population_memory(pop: int, n_frames: int = 1,
                            available: int | None = None) -> None:
    """Refuse a population whose search cannot fit in memory, before any of it is allocated.

    Raises :class:`SettingsError` naming ``--pop`` with the figure when ``pop`` individuals on
    ``n_frames`` frames need more than ``available`` bytes (default: the memory available now,
    as the operating system reports it). The need counted is a lower bound (the frames' data
    come on top), so a population that would fit is never refused.
    """
    per = SEARCH_BYTES_PER_INDIVIDUAL + SEARCH_BYTES_PER_INDIVIDUAL_FRAME * int(n_frames)
    need = int(pop) * per
    if available is None:
        import psutil

        available = int(psutil.virtual_memory().available)
    if need > available:
        frames = f"{n_frames} frame{'s' if n_frames != 1 else ''}"
        raise SettingsError(f"--pop {pop}: the search needs at least {need / 1e9:.1f} GB "
                            f"({per} bytes per individual on {frames}: the population, its "
                            f"offspring and their evaluation), more than the "
                            f"{available / 1e9:.1f} GB of memory available")


def _check_search(s: SearchSettings) -> None:
    if s.pop < 4:
        raise SettingsError(f"--pop {s.pop}: the population needs at least 4 individuals")
    check_population_memory(s.pop)          # at least one frame; the pipeline counts them all
    if s.gens < 1:
        raise SettingsError(f"--gens {s.gens}: needs at least 1 generation")
    if s.seed < 0:
        raise SettingsError(f"--seed {s.seed}: must be 0 or more")
    if s.bound_t_m is not None and not s.bound_t_m > 0:
        raise SettingsError(f"--bound-t {s.bound_t_m:g}: the translation bound must be "
                            "positive (metres, +- around the initial extrinsic)")
    if s.bound_r_deg is not None and not s.bound_r_deg > 0:
        raise SettingsError(f"--bound-r {s.bound_r_deg:g}: the rotation bound must be "
                            "positive (degrees, +- around the initial extrinsic)")
    if s.bound_r_deg is not None and s.bound_r_deg > 90:
        raise SettingsError(f"--bound-r {s.bound_r_deg:g}: at most 90 degrees")
    if not (s.init_error_deg > 0 and s.init_error_m > 0):
        raise SettingsError(f"--init-error {s.init_error_deg:g},{s.init_error_m:g}: both the "
                            "rotation (deg) and the translation (m) must be positive")
    if s.init_error_deg > 60:
        raise SettingsError(f"--init-error {s.init_error_deg:g},{s.init_error_m:g}: at most "
                            "60 degrees (a start further off is not an initial guess)")
    if s.n_min is not None and s.n_max is not None and s.n_min > s.n_max:
        raise SettingsError(f"--n-min {s.n_min} is larger than --n-max {s.n_max}")
    if s.n_min is not None and s.n_min < 1:
        raise SettingsError(f"--n-min {s.n_min}: must be at least 1")
    if s.n_max is not None and s.n_max < 1:
        raise SettingsError(f"--n-max {s.n_max}: must be at least 1")
    if not 0.0 <= s.sbx_prob <= 1.0:
        raise SettingsError(f"sbx_prob {s.sbx_prob}: must lie in [0, 1]")
    if s.seed_grid_deg is not None and not s.seed_grid_deg > 0:
        raise SettingsError(f"seed_grid_deg {s.seed_grid_deg}: must be positive (or null)")
    if s.seed_grid_t_m is not None and not s.seed_grid_t_m > 0:
        raise SettingsError(f"seed_grid_t_m {s.seed_grid_t_m}: must be positive (or null)")
    if s.seed_points < 1 or s.seed_count < 0:
        raise SettingsError("seed_points must be at least 1 and seed_count not negative")


def _check_objective(o: ObjectiveSettings) -> None:
    if not 0.0 <= o.w_edge <= 1.0:
        raise SettingsError(f"--w-edge {o.w_edge}: must lie in [0, 1] (w2 = 1 - w1)")
    if not 0.0 <= o.holdout < 0.9:
        raise SettingsError(f"holdout {o.holdout}: must lie in [0, 0.9)")
    if not o.truncation_px > 0:
        raise SettingsError(f"--truncation {o.truncation_px}: must be positive")
    if (o.ucb_k is not None and o.ucb_k < 0) or o.contrast < 0:
        raise SettingsError("ucb_k and contrast must not be negative")


def _check_decision(d: DecisionSettings) -> None:
    if not d.max_deviation_px > 0:
        raise SettingsError(f"--max-deviation {d.max_deviation_px}: must be positive (px)")
    if d.rule == "budget" and (d.budget_ms is None or not d.budget_ms > 0):
        raise SettingsError("--budget-ms must be a positive number of milliseconds")
    if d.restarts < 0 or d.restarts > 10:
        raise SettingsError(f"decision.restarts {d.restarts}: between 0 and 10")
    if not 0.0 < d.restart_share <= 1.0:
        raise SettingsError(f"decision.restart_share {d.restart_share}: must lie in (0, 1]")
    if d.polish_iters < 0:
        raise SettingsError(f"polish_iters {d.polish_iters}: must not be negative")


def _check_motion(m: MotionSettings) -> None:
    if not abs(m.time_offset_s) <= 1.0:
        raise SettingsError(f"--time-offset {m.time_offset_s}: at most 1 s either way")
    if m.points < 1000:
        raise SettingsError(f"motion.points {m.points}: at least 1000")


def _check_features(f: FeatureSettings) -> None:
    if f.canny_low < 0 or f.canny_low > f.canny_high:
        raise SettingsError("canny_low must not be negative nor exceed canny_high")
    if len(f.grid) != 2 or min(f.grid) < 1:
        raise SettingsError(f"grid {list(f.grid)}: two whole numbers of cells, at least 1")
    if not 0 <= f.min_range_m < f.max_range_m:
        raise SettingsError(f"min_range_m {f.min_range_m} and max_range_m {f.max_range_m}: "
                            "need 0 <= min_range_m < max_range_m")
    if not f.z_min > 0:
        raise SettingsError(f"z_min {f.z_min}: must be positive (metres in front of the camera)")
    if f.canny_noise is not None and not f.canny_noise > 0:
        raise SettingsError(f"canny_noise {f.canny_noise}: must be positive (noise deviations "
                            "of the image's gradient)")
    negative = [k for k in ("blur_sigma", "min_edge_px", "depth_jump_m", "cross_jump_m",
                            "cross_jump_rel", "intensity_jump", "smooth_ratio",
                            "view_margin_px") if (getattr(f, k) or 0) < 0]
    if negative:
        raise SettingsError(f"features: {', '.join(negative)} must not be negative")


@dataclass(frozen=True)
class Range:
    """The values a numeric setting may take: ``low`` to ``high`` (None: bounded elsewhere),
    each end included unless ``open_low`` / ``open_high``; ``why`` says what bounds it."""

    low: float
    high: float | None
    why: str
    open_low: bool = False
    open_high: bool = False

    def holds(self, value: float) -> bool:
        """Whether ``value`` lies in the range."""
        above = value > self.low if self.open_low else value >= self.low
        below = (self.high is None
                 or (value < self.high if self.open_high else value <= self.high))
        return above and below

    def words(self) -> str:
        """The range as an interval: ``[0, 50]``, ``(0, 16384]``, ``[4, ...)``."""
        high = "..." if self.high is None else f"{self.high:g}"
        return (f"{'(' if self.open_low else '['}{self.low:g}, {high}"
                f"{')' if self.open_high or self.high is None else ']'}")


#: Metres: beyond the range of the longest-range LiDARs (a few hundred metres).
MAX_RANGE_M = 1000.0
#: The largest gradient Canny can threshold on an 8-bit image: 3x3 Sobel, L2 norm,
#: 4 x 255 x sqrt(2) = 1442.5 (paretocal.features.image.edge_map).
MAX_GRADIENT = 1443.0
#: Rotations (or joint rotation x translation poses) a seed grid may score: the paper's grid
#: (+-25 deg in steps of 2.5 deg) holds 9,261, about a second on 20 frames; a million is
#: under two minutes.
MAX_SEED_GRID = 1_000_000
#: Step of the rotations of the joint rotation x translation seed grid (deg,
#: paretocal.search.seeding).
SEED_JOINT_STEP_DEG = 5.0
#: Generations of a search: its checkpoint keeps a record of every generation (at most about
#: 80 bytes of JSON) in its metadata, which is read back as a text of at most 8 MiB
#: (``paretocal.io.text.MAX_TEXT_BYTES``).
MAX_GENS = 100_000
_M = f"metres: within the longest LiDAR range ({MAX_RANGE_M:g} m)"
_WEIGHT = "a weight against the edge terms' 1: at 100 they count for 1 %"
_FRACTION = "a place between the near ray (0) and the far one (1)"
_ETA = ("a distribution index: children lie about 1/eta of the box from their parents; "
        "beyond 1000 they copy them")
_SENSORS = "metres: one vehicle's sensors lie within a few metres of each other"


@functools.cache
def ranges() -> dict[tuple[str, str], Range]:
    """The range of every numeric setting, by (section, name) (section "" for the top level),
    checked by :meth:`Settings.validate` after the settings' own checks, which word the most
    common mistakes; docs/calibrating.md lists them. Pixels are bounded by the side of the
    largest square image the readers accept, points by the largest cloud (the readers'
    limits, :mod:`paretocal.io`, imported here on first use: the command line reads this
    module's choices at start-up)."""
    from .io.clouds import MAX_CLOUD_POINTS
    from .io.images import MAX_IMAGE_PIXELS

    max_px = math.isqrt(MAX_IMAGE_PIXELS)
    px = f"pixels: no distance within an image is longer than the largest image's side ({max_px})"
    points = f"points: no cloud holds more ({MAX_CLOUD_POINTS:,})"
    return {
        ("features", "blur_sigma"): Range(0, 50, "pixels: a blur of sigma leaves Canny the edges "
                                          "of structure wider than about 2 sigma; beyond 50 px "
                                          "those the LiDAR sees are gone, and the blur alone "
                                          "takes seconds a frame"),
        ("features", "canny_low"): Range(0, MAX_GRADIENT, "a gradient: no gradient of an 8-bit "
                                         "image exceeds 1443"),
        ("features", "canny_high"): Range(0, MAX_GRADIENT, "a gradient: no gradient of an 8-bit "
                                          "image exceeds 1443"),
        ("features", "canny_noise"): Range(0, MAX_GRADIENT, "noise deviations: beyond 1443 no "
                                           "gradient of an image noisy by a grey level reaches "
                                           "them", open_low=True),
        ("features", "min_edge_px"): Range(0, MAX_IMAGE_PIXELS, "pixels of a fragment: at most "
                                           "the largest image's"),
        ("features", "depth_jump_m"): Range(0, MAX_RANGE_M, _M),
        ("features", "cross_jump_m"): Range(0, MAX_RANGE_M, _M),
        ("features", "cross_jump_rel"): Range(0, MAX_RANGE_M, "times the near return's range: "
                                              "returns 1 m away and within the longest range "
                                              "never jump more"),
        ("features", "ground_tol_m"): Range(0, MAX_RANGE_M, _M),
        ("features", "along_fraction"): Range(0, 1, _FRACTION),
        ("features", "cross_fraction"): Range(0, 1, _FRACTION),
        ("features", "intensity_jump"): Range(0, 100, "times the 99th percentile of the "
                                              "intensities: beyond 100 only outliers jump so"),
        ("features", "min_range_m"): Range(0, MAX_RANGE_M, _M, open_high=True),
        ("features", "max_range_m"): Range(0, MAX_RANGE_M, _M, open_low=True),
        ("features", "smooth_ratio"): Range(0, MAX_CLOUD_POINTS, "smooth points per depth edge: "
                                            "no cloud holds more points"),
        ("features", "view_margin_px"): Range(0, max_px, px),
        ("features", "z_min"): Range(0, MAX_RANGE_M, _M, open_low=True),
        ("features", "grid"): Range(1, 1024, "image cells per side: cells at least 16 px wide on "
                                    "the largest image, a million at most, more than the feature "
                                    "points a frame holds"),
        ("objective", "truncation_px"): Range(0, max_px, px, open_low=True),
        ("objective", "w_edge"): Range(0, 1, "w1, with w2 = 1 - w1"),
        ("objective", "contrast"): Range(0, 100, _WEIGHT),
        ("objective", "ucb_k"): Range(0, 100, "standard errors of the sampling"),
        ("objective", "holdout"): Range(0, 0.9, "a share of each frame's points", open_high=True),
        ("search", "pop"): Range(4, None, "individuals: at most what fits in memory "
                                 "(check_population_memory)"),
        ("search", "gens"): Range(1, MAX_GENS, "generations: the checkpoint's record of them "
                                  "must stay a text of at most 8 MiB"),
        ("search", "seed"): Range(0, 2 ** 63 - 1, "a 64-bit whole number"),
        ("search", "init_error_deg"): Range(0, 60, "degrees: a start further off is not an "
                                            "initial guess", open_low=True),
        ("search", "init_error_m"): Range(0, 10, _SENSORS, open_low=True),
        ("search", "bound_t_m"): Range(0, 10, _SENSORS, open_low=True),
        ("search", "bound_r_deg"): Range(0, 90, "degrees", open_low=True),
        ("search", "n_min"): Range(1, MAX_CLOUD_POINTS, points),
        ("search", "n_max"): Range(1, MAX_CLOUD_POINTS, points),
        ("search", "sbx_prob"): Range(0, 1, "a probability"),
        ("search", "sbx_eta"): Range(0, 1000, _ETA),
        ("search", "pm_eta"): Range(0, 1000, _ETA),
        ("search", "seed_grid_deg"): Range(0, 90, "degrees, at most the largest rotation bound",
                                           open_low=True),
        ("search", "seed_truncation_px"): Range(0, max_px, px, open_low=True),
        ("search", "seed_points"): Range(1, MAX_CLOUD_POINTS, points),
        ("search", "seed_count"): Range(0, MAX_SEED_GRID, "poses of the seed grid: no grid holds "
                                        "more"),
        ("search", "seed_grid_t_m"): Range(0, 10, "metres, at most the largest translation bound",
                                           open_low=True),
        ("decision", "budget_ms"): Range(0, 3.6e6, "milliseconds of one evaluation: an hour is "
                                         "beyond any", open_low=True),
        ("decision", "max_deviation_px"): Range(0, max_px, px, open_low=True),
        ("decision", "polish_iters"): Range(0, 1000, "Newton iterations: the polish converges in "
                                            "about a dozen"),
        ("decision", "restarts"): Range(0, 10, "restarts of the search"),
        ("decision", "restart_share"): Range(0, 1, "a share of the search's evaluations",
                                             open_low=True),
        ("motion", "time_offset_s"): Range(-1, 1, "seconds: a sweep lasts a tenth of one"),
        ("motion", "points"): Range(1000, MAX_CLOUD_POINTS, points),
        ("", "camera"): Range(0, 3, "KITTI's cameras (other layouts ignore it)"),
    }


def _check_ranges(settings: Settings) -> None:
    """Raise :class:`SettingsError` naming the first setting outside its :func:`ranges`."""
    for (section, name), r in ranges().items():
        value = getattr(settings if not section else getattr(settings, section), name)
        values = value if isinstance(value, tuple) else (value,)
        if all(v is None or r.holds(v) for v in values):
            continue
        key = f"{section}.{name}" if section else name
        shown = list(value) if isinstance(value, tuple) else f"{value:g}"
        raise SettingsError(f"{key} {shown}: must lie in {r.words()} ({r.why})")


def grid_half_steps(bound: float, step: float) -> int:
    """Steps on each side of zero of a seed grid over +-``bound`` in steps of ``step``
    (``paretocal.search.seeding``: ``2 k + 1`` values per axis)."""
    return math.floor(bound / step + 1e-9)


def _least_step(bound: float, poses: int) -> float:
    """The smallest step (two significant digits) whose 3-D grid over +-``bound`` holds at
    most ``poses`` points (at least one)."""
    per_axis = max(round(poses ** (1 / 3)), 1)
    while per_axis ** 3 > poses and per_axis > 1:
        per_axis -= 1
    k = (per_axis - 1) // 2                  # steps on each side of zero
    exact = bound / (k + 1)                  # a step above this leaves k on each side
    unit = 10.0 ** (math.floor(math.log10(exact)) - 1)
    return (math.floor(exact / unit) + 1) * unit


def _check_seed_grids(s: SearchSettings) -> None:
    """The seed grids (``paretocal.search.seeding``) must hold at most
    :data:`MAX_SEED_GRID` poses: their step follows from the box they span."""
    if s.seed_grid_deg:
        rotations = (2 * grid_half_steps(s.bound_r, s.seed_grid_deg) + 1) ** 3
        if rotations > MAX_SEED_GRID:
            least = _least_step(s.bound_r, MAX_SEED_GRID)
            raise SettingsError(
                f"search.seed_grid_deg {s.seed_grid_deg:g}: a grid over +-{s.bound_r:g} deg "
                f"in steps of {s.seed_grid_deg:g} deg holds {rotations:,} rotations, more than "
                f"the {MAX_SEED_GRID:,} the seeding scores (about a second per 10,000 on 20 "
                f"frames); use a step of at least {least:g} deg, or null for no grid")
    if s.seed_grid_deg and s.seed_grid_t_m and s.bound_t > s.seed_grid_t_m:
        rotations = (2 * grid_half_steps(s.bound_r, SEED_JOINT_STEP_DEG) + 1) ** 3
        poses = rotations * (2 * grid_half_steps(s.bound_t, s.seed_grid_t_m) + 1) ** 3
        if poses > MAX_SEED_GRID:
            least = _least_step(s.bound_t, MAX_SEED_GRID // rotations)
            raise SettingsError(
                f"search.seed_grid_t_m {s.seed_grid_t_m:g}: a joint grid of {rotations:,} "
                f"rotations (+-{s.bound_r:g} deg in steps of {SEED_JOINT_STEP_DEG:g} deg) and "
                f"translations over +-{s.bound_t:g} m in steps of {s.seed_grid_t_m:g} m holds "
                f"{poses:,} poses, more than the {MAX_SEED_GRID:,} the seeding scores; use a "
                f"step of at least {least:g} m, or null for no joint grid")


#: The allowed values of every setting that takes a word, by (section, name): the one list the
#: validation, the command line's choices and the documentation read.
CHOICES: dict[tuple[str, str], tuple[str, ...]] = {
    ("objective", "chamfer"): ("edge-dt", "paper"),
    ("objective", "outside"): ("mean", "truncation"),
    ("objective", "cost"): ("model", "psutil"),
    ("objective", "evaluator"): ("auto", "numba", "numpy"),
    ("decision", "rule"): ("knee", "knee-chamfer", "budget", "min-chamfer"),
    ("motion", "deskew"): ("auto", "off"),
    ("search", "wide"): ("auto", "on", "off"),
    ("features", "ring_method"): ("auto", "field", "scan", "lines", "elevation"),
    ("features", "edge_weight"): ("none", "sqrt_jump", "depth_balanced"),
}

_OPTIONS = {"pop": "--pop", "gens": "--gens", "seed": "--seed", "n_min": "--n-min",
            "n_max": "--n-max", "bound_t_m": "--bound-t", "bound_r_deg": "--bound-r",
            "w_edge": "--w-edge", "budget_ms": "--budget-ms",
            "max_deviation_px": "--max-deviation", "truncation_px": "--truncation",
            "rule": "--rule", "chamfer": "--chamfer", "cost": "--cost",
            "evaluator": "--evaluator", "deskew": "motion.deskew",
            "init_error_deg": "--init-error", "init_error_m": "--init-error",
            "time_offset_s": "--time-offset"}


def _option(name: str) -> str:
    """The command-line spelling of a setting when it has one, else the setting's name."""
    return _OPTIONS.get(name, name)


def _check_keys(cls, values: dict, section: str) -> None:
    names = {f.name for f in fields(cls)}
    unknown = sorted(map(str, set(values) - names))
    if unknown:
        raise SettingsError(f"unknown setting(s) {key_list(unknown)} in section {section!r} "
                            f"(known: {', '.join(sorted(names))})")


def _field_types(cls) -> dict[str, str]:
    """Each field's annotation as written (a string: the module uses postponed annotations)."""
    return {f.name: str(f.type) for f in fields(cls)}


def _coerce(name: str, value: Any, annotation: str) -> Any:
    """``value`` checked against a field annotation (``int``, ``float | None``,
    ``tuple[int, int]``, ...): ints widen to floats, whole floats narrow to ints, anything else
    of the wrong type is a :class:`SettingsError` naming the setting."""
    kinds = [k.strip() for k in annotation.split("|")]
    if value is None:
        if "None" in kinds:
            return None
        raise SettingsError(f"{name}: a value is required (got null)")
    kind = kinds[0]
    ok = False
    number = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if kind == "bool":
        ok = isinstance(value, (bool, np.bool_))
        value = bool(value) if ok else value
    elif kind == "int":
        ok = number and (isinstance(value, numbers.Integral) or float(value).is_integer())
        value = int(value) if ok else value
    elif kind == "float":
        ok = number
        value = float(value) if ok else value
    elif kind == "str":
        if isinstance(value, (bool, np.bool_)):
            # YAML 1.1 reads an unquoted off/no (on/yes) as false (true): `deskew: off`.
            value = "on" if value else "off"
        ok = isinstance(value, str) or (number and isinstance(value, numbers.Integral))
        value = str(value) if ok else value
    elif kind.startswith("tuple["):
        inner = [k.strip() for k in kind[len("tuple["):-1].split(",")]
        if isinstance(value, (list, tuple)) and len(value) == len(inner):
            return tuple(_coerce(name, v, k) for v, k in zip(value, inner))
    else:                                   # an annotation this checker does not know
        return value
    if not ok:
        words = {"bool": "true or false", "int": "a whole number", "float": "a number",
                 "str": "a string"}
        want = words.get(kind) or f"a list of {len(inner)} whole numbers"
        raise SettingsError(f"{name}: expected {want}{' or null' if 'None' in kinds else ''}, "
                            f"got {quote(value)}")
    return value


def dataset_settings(settings: Settings | None, options: dict,
                     adopt: bool = True) -> Settings:
    """The settings a dataset is calibrated with: ``settings`` with what the dataset states
    about itself where the settings leave the default.

    A dataset states its ``init_error`` (calib.yaml; ``options`` as
    :func:`paretocal.io.source_options` returns them): how far off its initial extrinsics
    may be, which sets the search box. It is taken when ``adopt`` and the settings'
    ``init_error_deg`` and ``init_error_m`` are both the defaults: settings that changed
    either keep theirs (the user's word wins over the dataset's).

    Parameters
    ----------
    settings : Settings, optional
        None: the defaults.
    options : dict
        ``init_error`` as ``(deg, m)`` when the dataset states it.
    adopt : bool
        False: the settings are final. For settings that state ``init_error`` even at its
        default values (``--init-error``, a config file that names it), and for settings
        recorded after adoption (a resumed run).

    Returns
    -------
    Settings
    """
    settings = settings or Settings()
    s, default = settings.search, SearchSettings()
    if (adopt and options.get("init_error") is not None
            and (s.init_error_deg, s.init_error_m) == (default.init_error_deg,
                                                       default.init_error_m)):
        deg, m = options["init_error"]
        settings = settings.replace(search={"init_error_deg": deg, "init_error_m": m})
    return settings


def parse_init_error(text, where: str) -> tuple[float | None, float | None]:
    """The stated initial error ``"DEG,M"`` (or a two-item list) as (deg, m), both positive;
    (None, None) for None. ``where`` names the option or key in the error."""
    from .io.layouts import positive_pair

    if text is None:
        return None, None
    items = text if isinstance(text, (list, tuple)) else str(text).replace(" ", "").split(",")
    pair = positive_pair(items)
    if pair is None:
        raise SettingsError(f"{where} {text!r}: expected DEG,M, two positive numbers (the "
                            "rotation in degrees and the translation in metres per axis, "
                            "e.g. 5,0.2)")
    return pair


def states_init_error(path: str | Path | None) -> bool:
    """Whether the config file ``path`` names ``search.init_error_deg`` or ``init_error_m``
    (then the user set it, even to the default values: a dataset's own does not replace it,
    see :func:`dataset_settings`)."""
    from .io.text import read_mapping

    if path is None:
        return False
    search = read_mapping(Path(path)).get("search")
    return isinstance(search, dict) and bool({"init_error_deg", "init_error_m"} & set(search))


def load_settings(path: str | Path | None, base: Settings | None = None) -> Settings:
    """Settings from a YAML/JSON config file laid out by section, over ``base``.

    Parameters
    ----------
    path : str or Path or None
        The file (``search: {pop: 1000, gens: 200}``); None: ``base`` itself.
    base : Settings, optional
        The settings the file's values replace (the defaults when omitted).

    Returns
    -------
    Settings
    """
    from .io.text import read_mapping

    if path is None:
        return base or Settings()
    return settings_from_mapping(read_mapping(Path(path)), str(path), base)


#: Settings that no longer exist: the one value that still means what the code does, and why
#: the others went. Files written before their removal load; any other value is refused, naming
#: the key.
_ONE_ENGINE = "the package runs one NSGA-II engine, on arrays; pymoo's own algorithm object is gone"
RETIRED = {("search", "engine"): ("lean", _ONE_ENGINE),
           ("search", "eliminate_duplicates"): (False, _ONE_ENGINE + ", and only it eliminated "
                                                       "duplicates")}


#: Settings that were renamed: files and saved runs written before load under the new name.
RENAMED = {("decision", "refine"): "polish", ("decision", "refine_iters"): "polish_iters"}


def _renamed(section: str, values: dict) -> dict:
    """``values`` of ``section`` with renamed keys under their current names (the current
    name wins when both are given)."""
    out = dict(values)
    for (sec, old), new in RENAMED.items():
        if sec == section and old in out:
            value = out.pop(old)
            out.setdefault(new, value)
    return out


def _drop_retired(data: dict, name: str) -> dict:
    out = dict(data)
    for (section, key), (value, why) in RETIRED.items():
        sec = out.get(section)
        if isinstance(sec, dict) and key in sec:
            if sec[key] != value:
                raise SettingsError(f"{name}: {section}.{key}: {quote(sec[key])} is no longer "
                                    f"available ({why}); remove the key")
            out[section] = {k: v for k, v in sec.items() if k != key}
    return out


def settings_from_mapping(data: dict, name: str = "settings",
                          base: Settings | None = None) -> Settings:
    """Settings from a mapping laid out by section (as :meth:`Settings.to_dict` writes it),
    over ``base``; errors name ``name`` (the file it came from)."""
    settings = base or Settings()
    data = _drop_retired(data, name)
    top = {f.name for f in fields(Settings)}
    unknown = sorted(map(str, set(data) - top))
    if unknown:
        raise SettingsError(f"{name}: unknown section(s) {key_list(unknown)} "
                            f"(known: {', '.join(sorted(top))})")
    types = _field_types(Settings)
    sections: dict[str, dict] = {}
    scalars: dict[str, Any] = {}
    for k, v in data.items():
        is_section = dataclasses.is_dataclass(getattr(settings, k))
        if is_section and not isinstance(v, dict):
            raise SettingsError(f"{name}: section {k!r} must be a mapping of settings "
                                f"(key: value), got {quote(v)}")
        if not is_section and isinstance(v, dict):
            raise SettingsError(f"{name}: {k!r} is a single value, not a section")
        (sections if is_section else scalars)[k] = v
    try:
        settings = settings.replace(keep_none=True, **sections)
        scalars = {k: _coerce(k, v, types[k]) for k, v in scalars.items()}
        if scalars:
            settings = dataclasses.replace(settings, **scalars)
        settings.validate()
    except SettingsError as exc:
        raise SettingsError(f"{name}: {exc}") from None
    return settings
