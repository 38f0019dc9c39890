"""Checkpoints of the NSGA-II search, so an interrupted run resumes exactly.

The array engine's state (population, objectives, ranks, crowding, the numpy Generator) is
saved every few generations, atomically and flushed to disk, with a fingerprint of everything
the search depends on (settings, initial extrinsic, frames, ``n`` range, seed poses). Resuming
from a checkpoint whose fingerprint matches continues the same random stream, so the result is
bitwise the one an uninterrupted run gives; a checkpoint of another run is refused.

The file is a numpy ``.npz`` archive of plain arrays plus one JSON text (format, fingerprint,
generation, evaluations, the Generator's state, the history), read with
``allow_pickle=False``: loading a checkpoint cannot run code, whoever wrote the file.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, Interrupted
from ..io.atomic import atomic_path

FORMAT = 2
ARRAYS = ("X", "F", "rank", "crowding")


def fingerprint(*parts) -> str:
    """SHA-256 over JSON-able values and arrays (their bytes, dtype and shape)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(json.dumps(p, sort_keys=True, default=str).encode())
    return h.hexdigest()


class SearchInterrupted(Interrupted):
    """The search stopped on SIGINT/SIGTERM after saving its checkpoint.

    Attributes (of :class:`~paretocal.errors.Interrupted`): ``X`` (k, 7) and ``F`` (k, 2), the
    non-dominated set of the last completed generation; ``generation``; ``checkpoint`` (its
    path, or None).
    """

    def __init__(self, X: np.ndarray, F: np.ndarray, generation: int, checkpoint: Path | None):
        super().__init__("the search", generation, X, F, checkpoint)


@dataclass
class Checkpoint:
    """Where and how often the search state is saved.

    Attributes
    ----------
    path : Path
        The checkpoint file.
    every : int
        Save after every ``every`` generations (and when interrupted).
    key : str
        Fingerprint of the run; set by the pipeline before the search starts.
    cost_model : dict, optional
        The run's cost model, saved with the state (set by the pipeline).
    """

    path: Path
    every: int = 5
    key: str = ""
    cost_model: dict | None = None

    def stored_cost_model(self) -> dict | None:
        """The cost model saved with the state (``CostModel.to_dict()``), so that a resumed
        run decides with the times the interrupted one measured; None when there is none. The
        run's fingerprint is checked by :meth:`load`, not here."""
        try:
            with np.load(Path(self.path), allow_pickle=False) as z:
                found = json.loads(str(z["meta"])).get("cost_model")
        except (OSError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile):
            return None
        return found if isinstance(found, dict) else None

    def save(self, state, history: list) -> None:
        meta = {"format": FORMAT, "key": self.key, "generation": int(state.generation),
                "evaluations": int(state.evaluations),
                "rng": state.rng.bit_generator.state, "history": history,
                "cost_model": self.cost_model}
        arrays = {k: np.asarray(getattr(state, k)) for k in ARRAYS}
        with atomic_path(Path(self.path)) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
                fh.flush()
                os.fsync(fh.fileno())

    def load(self):
        """``(state, history)`` from the file, or None when there is none.

        Raises :class:`InputError` when the file belongs to another run or is unreadable.
        """
        from .lean import LeanState

        path = Path(self.path)
        if not path.exists():
            return None
        unreadable = (OSError, ValueError, KeyError, TypeError, AttributeError,
                      zipfile.BadZipFile)
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: np.array(z[k]) for k in ARRAYS}
        except unreadable as exc:
            raise InputError(f"{path}: unreadable checkpoint ({type(exc).__name__}: {exc})"
                             ) from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise InputError(f"{path}: not a paretocal checkpoint of this version")
        if meta.get("key") != self.key:
            raise InputError(f"{path}: the checkpoint belongs to another run (different data, "
                             "extrinsic or settings); remove it or use another --out")
        try:
            bit_gen = getattr(np.random, meta["rng"]["bit_generator"])()
            bit_gen.state = meta["rng"]
            state = LeanState(rng=np.random.Generator(bit_gen),
                              generation=int(meta["generation"]),
                              evaluations=int(meta["evaluations"]), **arrays)
        except unreadable as exc:
            raise InputError(f"{path}: unreadable checkpoint ({type(exc).__name__}: {exc})"
                             ) from None
        return state, meta["history"]
