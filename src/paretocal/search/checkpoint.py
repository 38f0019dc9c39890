"""Checkpoints of the NSGA-II search, so an interrupted run resumes exactly.

The array engine's state (population, objectives, ranks, crowding, the numpy Generator) is
saved every few generations, atomically and flushed to disk, with a fingerprint of everything
the search depends on (settings, initial extrinsic, frames, ``n`` range, seed poses). Resuming
from a checkpoint whose fingerprint matches continues the same random stream, so the result is
bitwise the one an uninterrupted run gives; a checkpoint of another run is refused.

The file is a numpy ``.npz`` archive of plain arrays plus one JSON text (format, fingerprint,
generation, evaluations, the Generator's state, the history), read by the safe ``.npz`` reader
(:mod:`paretocal.io.arrays`: no unpickling, no header trusted): loading a checkpoint cannot
run code or allocate what its headers claim, whoever wrote the file. Nor can
it steer the search: every field is checked against the run's settings (generation, counts,
shapes, the search box, the generator's state, the history) before the search continues, and
the file is never read through a symbolic link.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

from typing import TypeGuard

import numpy as np

from ..errors import InputError, Interrupted
from ..io.atomic import atomic_path
from ..io.arrays import load_npz
from ..io.paths import open_plain
from ..io.text import load_json

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
        run decides with the times the interrupted one measured; None when there is none or
        the file cannot be read (:meth:`load` then says why). The run's fingerprint is checked
        by :meth:`load`, not here; a cost model of the wrong form raises :class:`InputError`
        naming the file."""
        try:
            found = _read(Path(self.path))[0].get("cost_model")
        except (OSError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile,
                InputError):
            return None
        if found is not None:
            _check_cost_model(self.path, found)
        return found

    def save(self, state, history: list) -> None:
        meta = {"format": FORMAT, "key": self.key, "generation": int(state.generation),
                "evaluations": int(state.evaluations),
                "rng": state.rng.bit_generator.state, "history": history,
                "cost_model": self.cost_model}
        arrays = {k: np.asarray(getattr(state, k)) for k in ARRAYS}
        with atomic_path(Path(self.path)) as tmp:
            with open(tmp, "wb") as fh:
                # (numpy's stub reads **arrays as possibly naming allow_pickle: they never do)
                np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)  # type: ignore[arg-type]
                fh.flush()
                os.fsync(fh.fileno())

    def load(self, pop: int, gens: int, xl: np.ndarray, xu: np.ndarray):
        """``(state, history)`` from the file, or None when there is none.

        ``pop``, ``gens``, ``xl`` and ``xu`` (7,) are the run's population, generations and
        search box: every field of the state must be one this run's search can have reached.
        Raises :class:`InputError` when the file belongs to another run, is unreadable or
        holds a field out of range (naming it).
        """
        from .engine import EngineState

        path = Path(self.path)
        unreadable = (OSError, ValueError, KeyError, TypeError, AttributeError,
                      zipfile.BadZipFile)
        try:
            meta, arrays = _read(path)
        except FileNotFoundError:
            return None
        except unreadable as exc:
            raise InputError(f"{path}: unreadable checkpoint ({type(exc).__name__}: {exc})"
                             ) from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise InputError(f"{path}: not a paretocal checkpoint of this version")
        if meta.get("key") != self.key:
            raise InputError(f"{path}: the checkpoint belongs to another run (different data, "
                             "extrinsic or settings); remove it or use another --out")
        _check_state(path, meta, arrays, pop, gens, np.asarray(xl), np.asarray(xu))
        bit_gen = np.random.PCG64()
        bit_gen.state = meta["rng"]
        state = EngineState(rng=np.random.Generator(bit_gen), generation=meta["generation"],
                          evaluations=meta["evaluations"], **arrays)
        return state, meta["history"]


def _read(path: Path) -> tuple:
    """``(meta, arrays)`` of the checkpoint file ``path``: its metadata (JSON) and the arrays
    of :data:`ARRAYS`, read without following a link, by the safe ``.npz`` reader (a member's
    header is not trusted, nothing in it is unpickled)."""
    with open_plain(path, "a checkpoint file") as fh:
        members = load_npz(fh, f"{path}: unreadable checkpoint")
    meta = load_json(str(members["meta"]), path)
    return meta, {k: members[k] for k in ARRAYS}


class _Bad(Exception):
    """A checkpoint field out of range: ``(field, what is wrong)``."""


def _check_state(path: Path, meta: dict, arrays: dict, pop: int, gens: int,
                 xl: np.ndarray, xu: np.ndarray) -> None:
    """Raise :class:`InputError` naming ``path`` and the first field of the saved state that
    this run's search (``pop`` individuals, ``gens`` generations, box ``xl``..``xu``) cannot
    have produced: a tampered or damaged file must not skip or redirect the search."""
    try:
        gen, ev = meta.get("generation"), meta.get("evaluations")
        if not _is_int(gen) or not 1 <= gen <= gens:
            raise _Bad("generation", f"{gen!r} is not a generation of this run (1..{gens})")
        # Every generation evaluates one population: the first its initial one, then the
        # offspring.
        if not _is_int(ev) or ev != pop * gen:
            raise _Bad("evaluations", f"{ev!r} does not match generation {gen} of a "
                                      f"population of {pop} ({pop * gen})")
        X, F, rank, cd = (arrays[k] for k in ARRAYS)
        for name, a, shape in (("X", X, (pop, 7)), ("F", F, (pop, 2)), ("rank", rank, (pop,)),
                               ("crowding", cd, (pop,))):
            kind_ok = a.dtype.kind in "iu" if name == "rank" else a.dtype == np.float64
            if a.shape != shape or not kind_ok:
                want = "integers" if name == "rank" else "float64"
                raise _Bad(name, f"holds {a.dtype} of shape {a.shape}, not {want} of shape "
                                 f"{shape}")
        if not np.all(np.isfinite(X)) or np.any(X < xl) or np.any(X > xu):
            raise _Bad("X", "holds values that are not finite or outside the search box")
        # +inf is a possible objective (a candidate that sees nothing) and crowding (a
        # front's ends); NaN and -inf are not.
        if np.any(np.isnan(F) | (F == -np.inf)):
            raise _Bad("F", "holds NaN or -inf")
        if np.any(rank < 0) or np.any(np.isnan(cd) | (cd < 0)):
            raise _Bad("rank" if np.any(rank < 0) else "crowding", "holds negative values")
        _check_rng(meta.get("rng"))
        history = meta.get("history")
        if not isinstance(history, list) or len(history) != gen:
            raise _Bad("history", f"is not a list of {gen} generations")
        for k, h in enumerate(history, 1):
            if not (isinstance(h, dict) and set(h) == {"gen", "best_f1", "evaluations"}
                    and h["gen"] == k and _is_int(h["gen"]) and h["evaluations"] == pop * k
                    and _is_int(h["evaluations"]) and isinstance(h["best_f1"], (int, float))
                    and not isinstance(h["best_f1"], bool)):
                raise _Bad("history", f"entry {k} is not generation {k}'s record")
    except _Bad as bad:
        field, why = bad.args
        raise InputError(f"{path}: {field} {why}; the checkpoint is damaged (remove it to "
                         "start the search over)") from None


def _check_rng(rng) -> None:
    """The random generator's state must be a valid PCG64 state (``default_rng``'s)."""
    ok = (isinstance(rng, dict) and set(rng) == {"bit_generator", "state", "has_uint32",
                                                   "uinteger"}
          and rng["bit_generator"] == "PCG64" and isinstance(rng["state"], dict)
          and set(rng["state"]) == {"state", "inc"}
          and all(_is_int(v) and 0 <= v < 2 ** 128 for v in rng["state"].values())
          and rng["state"]["inc"] % 2 == 1                  # PCG's increment is odd
          and rng["has_uint32"] in (0, 1) and not isinstance(rng["has_uint32"], bool)
          and _is_int(rng["uinteger"]) and 0 <= rng["uinteger"] < 2 ** 32)
    if not ok:
        raise _Bad("rng", "is not the state of a PCG64 random generator")


def _check_cost_model(path: Path, model) -> None:
    """The saved cost model must be one a measurement gives (:meth:`CostModel.from_dict`)."""
    from ..objective.cost import CostModel

    try:
        CostModel.from_dict(model)
    except ValueError:
        raise InputError(f"{path}: cost_model is not a cost model paretocal saved; the "
                         "checkpoint is damaged (remove it to start the search over)") from None


def _is_int(v) -> TypeGuard[int]:
    return isinstance(v, int) and not isinstance(v, bool)
