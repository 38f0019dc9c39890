"""Nothing read from a run folder reaches outside it: a checkpoint whose fields this run cannot
have written is refused before the search, naming the field, and nothing is touched."""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from .helpers import bad_cli
from paretocal import Settings
from paretocal.search.checkpoint import SearchInterrupted

SETTINGS = Settings(frames="0:2").replace(search={"pop": 16, "gens": 6, "seed": 2},
                                           decision={"refine": False})


def _stop_at(generation):
    def progress(stage, done, total):
        if stage == "search" and done == generation:
            raise KeyboardInterrupt
    return progress


@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory, raw_date):
    """A run folder interrupted after generation 4 of 6 (checkpoint, arguments, partial
    front)."""
    from paretocal import calibrate_run

    run = tmp_path_factory.mktemp("stopped") / "run"
    with pytest.raises(SearchInterrupted):
        calibrate_run(raw_date, run, None, SETTINGS, figures=False, checkpoint_every=2,
                      progress=_stop_at(4))
    return run


def _copy(run: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "run"
    shutil.copytree(run, dst, symlinks=True)
    return dst


def _snapshot(folder: Path) -> dict:
    """Every entry below ``folder``: its kind and its bytes (files) or target (links)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        mode = p.lstat().st_mode
        out[rel] = (("link", os.readlink(p)) if stat.S_ISLNK(mode)
                    else ("file", p.read_bytes()) if stat.S_ISREG(mode)
                    else ("other", stat.S_IFMT(mode)))
    return out


# --- a checkpoint must be one this run can have written ------------------------------------------

def _gen(v):
    return lambda meta, arrays: meta.update(generation=v)


def _cut(key):
    return lambda meta, arrays: arrays.update({key: arrays[key][:-3]})


def _rng(**kw):
    def edit(meta, arrays):
        if "inc" in kw:
            meta["rng"]["state"]["inc"] = kw["inc"]
        else:
            meta["rng"].update(kw)
    return edit


TAMPERED = {
    "generation far ahead": (_gen(10 ** 9), "generation 1000000000 is not a generation"),
    "generation negative": (_gen(-3), "generation -3 is not a generation of this run"),
    "generation text": (_gen("4"), "generation '4' is not"),
    "evaluations": (lambda m, a: m.update(evaluations=5), "evaluations 5 does not match"),
    "X cut": (_cut("X"), "X holds float64 of shape (13, 7), not float64 of shape (16, 7)"),
    "F cut": (_cut("F"), "F holds float64 of shape (13, 2)"),
    "rank cut": (_cut("rank"), "rank holds"),
    "X outside the box": (lambda m, a: a["X"].__setitem__((0, 0), 1e6),
                          "X holds values that are not finite or outside the search box"),
    "X NaN": (lambda m, a: a["X"].__setitem__((0, 3), np.nan), "X holds values that are not"),
    "F NaN": (lambda m, a: a["F"].__setitem__((0, 0), np.nan), "F holds NaN or -inf"),
    "crowding negative": (lambda m, a: a["crowding"].__setitem__(0, -1.0),
                          "crowding holds negative values"),
    "X as text": (lambda m, a: a.update(X=a["X"].astype(str)), "X holds <U"),
    "rng of another generator": (_rng(bit_generator="MT19937"), "rng is not the state of a"),
    "rng even increment": (_rng(inc=2), "rng is not the state of a PCG64"),
    "rng state text": (_rng(state="x"), "rng is not the state"),
    "history not a list": (lambda m, a: m.update(history={"gen": 1}), "history is not a list"),
    "history entry": (lambda m, a: m["history"][1].update(gen=7), "history entry 2 is not"),
    "cost model": (lambda m, a: m["cost_model"].update(ms_per_point=-1.0),
                   "cost_model is not a cost model"),
}


@pytest.mark.parametrize("case", list(TAMPERED))
def test_a_tampered_checkpoint_is_refused_naming_the_field(capfd, tmp_path, stopped_run,
                                                           case):
    edit, expect = TAMPERED[case]
    run = _copy(stopped_run, tmp_path)
    with np.load(run / "checkpoint.npz", allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        arrays = {k: np.array(z[k]) for k in z.files if k != "meta"}
    assert meta["generation"] == 4                      # the case edits a real checkpoint
    edit(meta, arrays)
    np.savez(run / "checkpoint.npz", meta=np.array(json.dumps(meta)), **arrays)
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run,
            expect=(f"{run / 'checkpoint.npz'}: ", expect))
    assert _snapshot(tmp_path) == before
