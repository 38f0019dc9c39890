"""The second objective: what evaluating a calibration with ``n`` points costs.

Default (``model``): a cost model measured on this machine. The evaluator is timed on a probe
population at several ``n``, in CPU time on one core (:func:`time_per_candidate`; the fastest
of repeats, as noise only ever adds time) and a line is fitted, ``time = a + b * P`` ms per
candidate, where ``P`` is the number of points evaluated over all frames; the bytes an
evaluation reads are counted from the arrays it touches, ``bytes = DT bytes + 17 * P`` (three
float32 coordinates, a float32 weight and a group byte per point). Both are min-max normalised
over the search's ``n`` range and summed, ``f2 = t_norm + m_norm`` in [0, 2].

Because both parts are affine in ``P``, the normalised cost is the same function of ``n`` on
every machine, so the search stays deterministic for a seed; the measured line supplies the
absolute milliseconds and bytes reported beside it and used by ``--budget-ms``. Where the line
comes from (measured, a cache of an earlier measurement, a checkpoint) is the stage's concern
(:func:`paretocal.stage.cost_model`).

Option ``psutil`` is the paper's approach: every candidate is timed (3 repetitions) and its
resident-memory growth read with psutil. It is reproduced faithfully but is noisy (tens of
microseconds of jitter on an evaluation of similar length), so the front it gives changes
from run to run.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields

import numpy as np

from .kernel import one_thread
from .scene import Scene

BYTES_PER_POINT = 17  # x, y, z, weight float32 + group int8


@dataclass(frozen=True)
class CostModel:
    """Affine time and memory model of one evaluation, in the points ``P`` it evaluates.

    Attributes
    ----------
    ms_fixed, ms_per_point : float
        Time per candidate evaluation in milliseconds: ``ms_fixed + ms_per_point * P``.
    bytes_fixed, bytes_per_point : float
        Bytes read per evaluation: ``bytes_fixed + bytes_per_point * P``.
    points_min, points_max : int
        ``P`` at the search's smallest and largest ``n`` (the normalisation range).
    probe : dict
        The measurements the line was fitted to (``points``, ``ms``).
    """

    ms_fixed: float
    ms_per_point: float
    bytes_fixed: float
    bytes_per_point: float
    points_min: int
    points_max: int
    probe: dict

    def time_ms(self, points) -> np.ndarray:
        """Modelled time of one evaluation (CPU ms on one core).

        Parameters
        ----------
        points : array_like, shape (...)
            ``P``, the points evaluated over all frames.

        Returns
        -------
        ndarray, shape (...)
        """
        return self.ms_fixed + self.ms_per_point * np.asarray(points, dtype=np.float64)

    def nbytes(self, points) -> np.ndarray:
        """Modelled bytes read by one evaluation.

        Parameters
        ----------
        points : array_like, shape (...)
            ``P``, the points evaluated over all frames.

        Returns
        -------
        ndarray, shape (...)
        """
        return self.bytes_fixed + self.bytes_per_point * np.asarray(points, dtype=np.float64)

    def normalised(self, points) -> tuple[np.ndarray, np.ndarray]:
        """``(t_norm, m_norm)``, each min-max normalised over the search's range.

        For affine models with positive slopes both equal ``(P - P_min) / (P_max - P_min)``
        exactly; computing them that way keeps them bitwise independent of the timing.

        Parameters
        ----------
        points : array_like, shape (...)
            ``P``, the points evaluated over all frames.

        Returns
        -------
        t_norm, m_norm : ndarray, shape (...)
        """
        p = np.asarray(points, dtype=np.float64)
        u = (p - self.points_min) / max(self.points_max - self.points_min, 1)
        return u, u.copy()

    def to_dict(self) -> dict:
        """The model's fields, as ``result.json``'s ``cost_model`` holds them."""
        return asdict(self)

    @classmethod
    def from_dict(cls, model) -> "CostModel":
        """The model :meth:`to_dict` wrote, checked to be one a measurement gives.

        Parameters
        ----------
        model : dict
            Exactly the fields: finite non-negative times (ms) and sizes (bytes), a point range
            ``0 <= points_min <= points_max`` and a ``probe`` mapping.

        Returns
        -------
        CostModel

        Raises
        ------
        ValueError
            For anything else (a cache file or a checkpoint's copy edited or damaged: a model
            with ``ms_fixed`` -1000 would model evaluations of -999 ms).
        """
        names = {f.name for f in fields(cls)}
        numbers = ("ms_fixed", "ms_per_point", "bytes_fixed", "bytes_per_point")
        ok = (isinstance(model, dict) and set(model) == names
              and isinstance(model["probe"], dict)
              and all(_is_number(model[k]) and math.isfinite(model[k]) and model[k] >= 0
                      for k in numbers)
              and _is_int(model["points_min"]) and _is_int(model["points_max"])
              and 0 <= model["points_min"] <= model["points_max"])
        if not ok:
            raise ValueError("not a cost model a measurement gives (its fields, finite "
                             "non-negative times and sizes, a point range, a probe)")
        return cls(**model)

    def for_scene(self, scene: Scene, n_min: int, n_max: int, source: str | None = None
                  ) -> "CostModel":
        """This model's time line applied to another scene of the same frames (the feature
        points chosen again at another pose): the time per point and per candidate belong to
        the machine and the evaluator, the bytes and the normalisation range to the scene.
        ``source`` (where the line comes from) is recorded in ``probe["source"]``.

        Parameters
        ----------
        scene : Scene
            The other scene.
        n_min, n_max : int
            The search's range of points per frame in that scene.
        source : str, optional
            Where the time line comes from (``"cache FILE"``, ``"checkpoint FILE"``).

        Returns
        -------
        CostModel
        """
        probe = dict(self.probe, **({"source": source} if source else {}))
        return CostModel(ms_fixed=self.ms_fixed, ms_per_point=self.ms_per_point,
                         bytes_fixed=_bytes_fixed(scene), bytes_per_point=float(BYTES_PER_POINT),
                         points_min=int(scene.points_used(n_min)),
                         points_max=int(scene.points_used(n_max)), probe=probe)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _bytes_fixed(scene: Scene) -> float:
    """Bytes every evaluation reads whatever ``n``: the distance transforms and one 3x4
    extrinsic per frame (float64)."""
    return float(scene.nbytes_static + scene.n_frames * 12 * 8)


def measure_cost_model(scene: Scene, evaluator, T_probe: np.ndarray, n_min: int, n_max: int,
                       candidates: int = 64, repeats: int = 5) -> CostModel:
    """Time ``evaluator`` on this machine and fit the affine cost model.

    Parameters
    ----------
    scene : Scene
        The frames' feature points and distance transforms.
    evaluator : callable
        ``evaluator(scene, T, n) -> (S1, S2, n_in)`` as in :mod:`paretocal.objective.kernel`.
    T_probe : ndarray, shape (4, 4)
        Extrinsic used for the probe population (the initial guess: realistic visibility).
    n_min, n_max : int
        The search's range of points per frame.
    candidates : int
        The probe population's size.
    repeats : int
        Batches timed at each ``n``; the fastest counts.

    Returns
    -------
    CostModel
        The line fitted to the times at five ``n`` (CPU ms of one evaluation on one core).
    """
    ns = np.unique(np.linspace(n_min, n_max, 5).round().astype(np.int64))
    time_per_candidate(scene, evaluator, T_probe, ns[-1], candidates, 1)  # warm-up (JIT)
    pts = [int(scene.points_used(n)) for n in ns]
    ms = [time_per_candidate(scene, evaluator, T_probe, n, candidates, repeats) for n in ns]
    pts_a, ms_a = np.array(pts, dtype=np.float64), np.array(ms)
    if len(pts_a) > 1 and np.ptp(pts_a) > 0:
        slope, icpt = np.polyfit(pts_a, ms_a, 1)
    else:
        slope, icpt = ms_a[0] / max(pts_a[0], 1.0), 0.0
    # Timing noise must not produce a cost that falls with n.
    slope = max(float(slope), 1e-9)
    icpt = max(float(icpt), 0.0)
    return CostModel(ms_fixed=icpt, ms_per_point=slope,
                     bytes_fixed=_bytes_fixed(scene),
                     bytes_per_point=float(BYTES_PER_POINT),
                     points_min=int(scene.points_used(n_min)),
                     points_max=int(scene.points_used(n_max)),
                     probe={"points": pts, "ms": [round(v, 6) for v in ms], "source": "measured"})


def time_per_candidate(scene: Scene, evaluator, T: np.ndarray, n: int, candidates: int = 64,
                       repeats: int = 5) -> float:
    """CPU milliseconds ``evaluator`` takes per candidate on one core, for ``candidates``
    copies of the extrinsic ``T`` (4, 4) at ``n`` points per frame: the fastest of
    ``repeats`` batches.

    One core and the thread's CPU clock make the figure a property of the machine and the
    scene, not of the load: on two busy cores a parallel batch's wall time was 5-30 times its
    work (threads waiting for each other's time slices), flat in ``n``."""
    Tb = np.repeat(np.asarray(T, dtype=np.float64)[None], candidates, 0)
    nn = np.full(candidates, int(n))
    samples = []
    with one_thread():
        for _ in range(repeats):
            t0 = time.thread_time()
            evaluator(scene, Tb, nn)
            samples.append(time.thread_time() - t0)
    return 1e3 * float(np.min(samples)) / candidates


def measure_per_candidate(evaluate_one, count: int, repeats: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The paper's measured cost: wall time (ms) and RSS growth (bytes) of each evaluation.

    ``evaluate_one(i)`` evaluates candidate ``i``; it is run ``repeats`` times and the mean
    time is reported.
    """
    import psutil

    proc = psutil.Process()
    ms = np.zeros(count)
    nbytes = np.zeros(count)
    for i in range(count):
        rss0 = proc.memory_info().rss
        t0 = time.perf_counter()
        for _ in range(repeats):
            evaluate_one(i)
        ms[i] = 1e3 * (time.perf_counter() - t0) / repeats
        nbytes[i] = max(0, proc.memory_info().rss - rss0)
    return ms, nbytes
