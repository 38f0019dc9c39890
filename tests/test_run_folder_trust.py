"""Nothing read from a run folder reaches outside it: ``.outputs``, the run's own files, the
checkpoint and the recorded arguments are checked before anything is touched; a folder of
other files is not taken for a run folder; ``result.json`` always comes with its own run's
``run_args.json``; stale temporaries do not outlive a finished run."""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from .helpers import bad_cli, run_cli
from paretocal import Settings
from paretocal.errors import InputError
from paretocal.search.checkpoint import SearchInterrupted

SETTINGS = Settings(frames="0:2").replace(search={"pop": 16, "gens": 6, "seed": 2},
                                           decision={"polish": False})
#: The command line of the runs above (the same run as SETTINGS, minus the seed).
CLI = ["--frames", "0:2", "--pop", "16", "--gens", "6", "--no-polish", "--no-figures",
       "--quiet", "--checkpoint-every", "2"]
#: The unfinished run's arguments (``run_args.json`` in folders of the previous release).
ARGS = "checkpoint_args.json"


def _stop_at(generation):
    def progress(stage, done, total):
        if stage == "search" and done == generation:
            raise KeyboardInterrupt
    return progress


@pytest.fixture(scope="module")
def done_run(tmp_path_factory, raw_date):
    """A finished run folder (copied by each test that changes it)."""
    from paretocal import calibrate_run

    run = tmp_path_factory.mktemp("done") / "run"
    calibrate_run(raw_date, run, None, SETTINGS, figures=False)
    return run


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


@pytest.fixture(scope="module")
def result(raw_frames):
    """A small calibration result, to publish."""
    from paretocal import calibrate

    return calibrate(raw_frames[:1], None, Settings().replace(
        search={"pop": 12, "gens": 2}, decision={"polish": False}))


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


# --- .outputs names only plain files of the folder -----------------------------------------------

@pytest.mark.parametrize("line, why", [
    ("../victim.txt", "is not a plain file name"),
    ("ABS", "is not a plain file name"),
    ("..", "is not a plain file name"),
    ("sub/x.txt", "is not a plain file name"),
    ("bell\x07.txt", "is not a plain file name"),
    (".lock", "the run folder's own bookkeeping"),
    ("subdir", "is a directory, not a file"),
], ids=["parent", "absolute", "dotdot", "separator", "control", "own file", "directory"])
def test_outputs_naming_anything_but_a_file_of_the_folder_is_refused(
        capfd, tmp_path, raw_date, done_run, line, why):
    run = _copy(done_run, tmp_path)
    victim, absolute = tmp_path / "victim.txt", tmp_path / "elsewhere" / "victim.txt"
    absolute.parent.mkdir()
    for v in (victim, absolute):
        v.write_text("keep me\n")
    (run / "sub").mkdir()
    (run / "sub" / "x.txt").write_text("keep me too\n")
    (run / "subdir").mkdir()
    (run / "subdir" / "notes.txt").write_text("mine\n")
    line = str(absolute) if line == "ABS" else line
    with open(run / ".outputs", "a") as fh:
        fh.write(line + "\n")
    before = _snapshot(tmp_path)
    err = bad_cli(capfd, "calibrate", raw_date, "--out", run, "--seed", "2", *CLI,
                  expect=(f"{run / '.outputs'}: line ", repr(line), why))
    assert _snapshot(tmp_path) == before, err          # the victims and the whole run too


def test_resume_and_publish_check_the_outputs_list_too(capfd, tmp_path, raw_frames,
                                                       stopped_run, result):
    """--resume refuses the folder before the search; publishing (as batch does) refuses it
    before removing anything, and leaves no staging folder."""
    from paretocal.rundir import publish_run

    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    run = _copy(stopped_run, tmp_path)
    (run / ".outputs").write_text("result.json\n../victim.txt\n")
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run, expect=(".outputs: line 2", "'../victim.txt'"))
    with pytest.raises(InputError, match=r"\.outputs: line 2: '\.\./victim\.txt' is not a"):
        publish_run(result, run, raw_frames[:1], figures=False)
    assert _snapshot(tmp_path) == before


def test_a_batch_entry_with_a_tampered_folder_fails_and_touches_nothing(tmp_path, raw_date):
    from paretocal.apps.batch import Entry, run_entry

    out = tmp_path / "batch"
    run = out / "runs" / "a"
    run.mkdir(parents=True)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    (run / ".outputs").write_text(f"{victim}\n")
    (run / "result.json").write_text("{}\n")
    before = _snapshot(tmp_path)
    record = run_entry(Entry("a", str(raw_date), frames="0:1"), SETTINGS.to_dict(), str(out))
    assert record["status"] == "failed" and ".outputs: line 1" in record["reason"]
    assert _snapshot(tmp_path) == before


def test_a_batch_entry_whose_folder_is_a_link_fails_and_touches_nothing(tmp_path, raw_date):
    from paretocal.apps.batch import Entry, run_entry

    victim = tmp_path / "mine"
    victim.mkdir()
    (victim / "result.json").write_text("mine\n")
    (tmp_path / "batch" / "runs").mkdir(parents=True)
    (tmp_path / "batch" / "runs" / "a").symlink_to(victim)
    before = _snapshot(tmp_path)
    record = run_entry(Entry("a", str(raw_date), frames="0:1"), SETTINGS.to_dict(),
                       str(tmp_path / "batch"))
    assert record["status"] == "failed"
    assert "runs/a: is a symbolic link, not an entry's run folder" in record["reason"]
    assert _snapshot(tmp_path) == before


def test_a_folder_in_place_of_a_new_output_is_refused_before_anything_is_removed(
        tmp_path, raw_frames, done_run, result):
    from paretocal.rundir import publish_run

    run = _copy(done_run, tmp_path)
    (run / "result.json").unlink()
    (run / "result.json").mkdir()
    before = _snapshot(tmp_path)
    with pytest.raises(InputError, match=r"result\.json: is a directory, not a file of a"):
        publish_run(result, run, raw_frames[:1], figures=False)
    assert _snapshot(tmp_path) == before


# --- the run's own files are never followed ------------------------------------------------------

@pytest.mark.parametrize("kind", ["link to a file", "directory", "fifo"])
def test_a_lock_that_is_not_a_plain_file_is_refused(capfd, tmp_path, raw_date, done_run, kind):
    run = _copy(done_run, tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    (run / ".lock").unlink(missing_ok=True)
    if kind == "directory":
        (run / ".lock").mkdir()
    elif kind == "fifo":
        os.mkfifo(run / ".lock")
    else:
        (run / ".lock").symlink_to(victim)
    what = {"link to a file": "a symbolic link", "directory": "a directory",
            "fifo": "a special file"}[kind]
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", raw_date, "--out", run, "--seed", "2", *CLI,
            expect=f"{run / '.lock'}: is {what}, not ")
    assert _snapshot(tmp_path) == before and victim.read_text() == "keep me\n"


def test_a_staging_link_is_refused(capfd, tmp_path, raw_date, done_run):
    run = _copy(done_run, tmp_path)
    victim = tmp_path / "mine"
    victim.mkdir()
    for name in ("result.json", "pareto.csv"):
        (victim / name).write_text("mine\n")
    (run / ".staging").symlink_to(victim)
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", raw_date, "--out", run, "--seed", "2", *CLI,
            expect=f"{run / '.staging'}: is a symbolic link, not the staging folder")
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("name", ["checkpoint.npz", "ARGS", "partial_front.csv",
                                  "result.json"])
def test_links_in_place_of_the_runs_files_are_refused(capfd, tmp_path, stopped_run, name):
    """The run's files linked to files elsewhere (the checkpoint to a copy of itself, so a
    run that follows it would resume): refused, the link and its target untouched."""
    run = _copy(stopped_run, tmp_path)
    if name == "ARGS":
        name = ARGS if (run / ARGS).exists() else "run_args.json"
    target = tmp_path / "elsewhere" / name
    target.parent.mkdir()
    if (run / name).exists():
        shutil.move(run / name, target)
    else:
        target.write_text("mine\n")
    (run / name).symlink_to(target)
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run,
            expect=f"{run / name}: is a symbolic link, not ")
    assert _snapshot(tmp_path) == before


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


def _member(path, name: str, content: bytes) -> None:
    """Replace the member ``name`` (``X.npy``) of the .npz ``path`` by ``content``."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    members[name] = content
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)


def _npy_bytes(header: dict | str, data: bytes = b"\0" * 64) -> bytes:
    import io

    if isinstance(header, str):
        body = header.encode() + b" " * (-(len(header) + 11) % 64) + b"\n"
        return b"\x93NUMPY\x01\x00" + len(body).to_bytes(2, "little") + body + data
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    return buf.getvalue() + data


@pytest.mark.parametrize("content, expect", [
    (_npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (10 ** 12, 7)}),
     "member X.npy: the .npy header says shape (1000000000000, 7) of float64 "
     "(56,000,000,000,000 bytes), but 64 bytes of data follow"),
    (_npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (" + "-" * 5000 + "5, 7), }"),
     "member X.npy: unreadable .npy header (its shape is nested too deeply to be read)"),
], ids=["claims 10^12 x 7", "nested shape"])
def test_a_checkpoint_member_is_read_by_the_safe_npy_reader(capfd, tmp_path, stopped_run,
                                                            content, expect):
    """A checkpoint's member claiming shape (10^12, 7) made numpy reserve 50.9 TiB, one with a
    shape nested 5,000 deep raised RecursionError (exit 1 both); they are read as a cloud's
    .npy is, and refused naming the member."""
    run = _copy(stopped_run, tmp_path)
    _member(run / "checkpoint.npz", "X.npy", content)
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run,
            expect=(f"{run / 'checkpoint.npz'}: unreadable checkpoint, {expect}",))
    assert _snapshot(tmp_path) == before


# --- the recorded arguments are checked field by field -------------------------------------------

@pytest.mark.parametrize("field, value, expect", [
    ("T_init", [[1, 2], [3, 4]], "T_init must be 4x4 (or 3x4), got shape (2, 2)"),
    ("T_init", [["a"] * 4] * 4, "T_init is not a numeric matrix"),
    ("T_init", np.diag([2.0, 2, 2, 1]).tolist(), "the rotation block of T_init is not a "
                                                 "rotation"),
    ("source", ["x"], "malformed: source must be the dataset folder's path (text) (got"),
    ("settings", [1], "malformed: settings must be a mapping of settings by section"),
    ("figures", "yes", "malformed: figures must be true or false (got 'yes')"),
    ("rig_camera", 5, "malformed: rig_camera must be a camera's name"),
    ("source", None, "malformed: source must be"),
], ids=["T_init shape", "T_init text", "T_init not rigid", "source list", "settings list",
        "figures text", "rig_camera number", "source missing"])
def test_malformed_run_arguments_are_refused_naming_the_field(capfd, tmp_path, raw_date,
                                                              field, value, expect):
    run = tmp_path / "run"
    run.mkdir()
    args = {"source": str(raw_date), "T_init": None, "settings": SETTINGS.to_dict(),
            "figures": False, field: value}
    if value is None:
        del args[field]
    (run / "run_args.json").write_text(json.dumps(args))
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run,
            expect=(f"{run / 'run_args.json'}: ", expect))
    assert _snapshot(tmp_path) == before


#: JSON (and YAML) nested 100,000 deep: Python's readers raise RecursionError on it.
DEEP = "[" * 100_000 + "]" * 100_000


@pytest.mark.parametrize("where", ["ARGS", "run_args.json", "checkpoint meta",
                                   "a rig camera's run_args.json"])
def test_run_files_nested_too_deeply_are_refused_in_one_line(capfd, tmp_path, stopped_run,
                                                             done_run, where):
    """A run's arguments or its checkpoint's metadata nested 100,000 deep ended the resume with
    exit 1 (RecursionError); now one line naming the file, nothing touched."""
    if where == "checkpoint meta":
        run = _copy(stopped_run, tmp_path)
        with np.load(run / "checkpoint.npz", allow_pickle=False) as z:
            arrays = {k: np.array(z[k]) for k in z.files if k != "meta"}
        np.savez(run / "checkpoint.npz", meta=np.array(DEEP), **arrays)
        bad, expect = run / "checkpoint.npz", "its values are nested too deeply to be read"
    elif where == "a rig camera's run_args.json":
        run = tmp_path / "rig_out"
        _copy(done_run, run)
        (run / "run" / "run_args.json").write_text(DEEP)
        bad, expect = run, "no run_args.json here; not a run directory"
    else:
        run = _copy(stopped_run if where == "ARGS" else done_run, tmp_path)
        name = ARGS if where == "ARGS" else "run_args.json"
        assert (run / name).exists()
        (run / name).write_text(DEEP)
        bad, expect = run / name, "its values are nested too deeply to be read"
    before = _snapshot(tmp_path)
    bad_cli(capfd, "calibrate", "--resume", run, expect=(f"{bad}: {expect}",))
    assert _snapshot(tmp_path) == before


# --- a folder of other files is not a run folder -------------------------------------------------

def test_a_folder_of_other_files_is_refused_unless_forced(capfd, tmp_path, raw_date):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "pareto.csv").write_text("my own table\n")
    (mine / "notes.txt").write_text("mine\n")
    before = _snapshot(tmp_path)
    for command in (["calibrate", raw_date, "--seed", "2", *CLI], ["study", raw_date],
                    ["batch", tmp_path / "none.yaml"]):
        what = {"calibrate": "run", "study": "study", "batch": "batch"}[command[0]]
        bad_cli(capfd, *command, "--out", mine,
                expect=(f"--out {mine}: the folder is not empty and is not a paretocal {what} "
                        "folder", "add --force"))
    assert _snapshot(tmp_path) == before
    code, _, err = run_cli(capfd, "calibrate", raw_date, "--out", mine, "--seed", "2", *CLI,
                           "--force")
    assert code == 0, err
    assert (mine / "notes.txt").read_text() == "mine\n" and (mine / "result.json").is_file()
    assert (mine / "pareto.csv").read_text() != "my own table\n"


def test_what_marks_a_run_folder(tmp_path):
    """Any of the run's own names marks a run folder, a .lock alone (a killed run) too."""
    from paretocal.io.atomic import check_own_folder
    from paretocal.rundir import MARKS

    for name in MARKS:
        folder = tmp_path / name.strip(".")
        folder.mkdir()
        (folder / name).write_text("")
        (folder / "pareto.csv").write_text("")
        check_own_folder(folder, MARKS, "run")
    check_own_folder(tmp_path / "new", MARKS, "run")
    (tmp_path / "empty").mkdir()
    check_own_folder(tmp_path / "empty", MARKS, "run")


def test_rig_runs_into_their_own_folder_and_refuse_others(capfd, tmp_path, monkeypatch):
    """A rig's run folder (rig.json, a run folder per camera) is rerun into; a folder of other
    files, as the rig's or as a camera's, is refused."""
    import paretocal.apps.rig
    from .test_rig import make_rig

    rig = make_rig(tmp_path)
    calls = []
    monkeypatch.setattr(paretocal.apps.rig, "calibrate_rig",
                        lambda *a, **k: calls.append(a) or {"pairs": []})
    out = tmp_path / "out"
    for name in ("front", "left"):
        (out / name).mkdir(parents=True)
        (out / name / ".outputs").write_text("result.json\n")
        (out / name / "result.json").write_text("{}\n")
    (out / "rig.json").write_text("{}\n")
    code, _, err = run_cli(capfd, "calibrate", rig, "--out", out, "--no-figures")
    assert code == 0 and len(calls) == 1, err
    (out / "left" / ".outputs").unlink()
    (out / "left" / "result.json").unlink()
    (out / "left" / "photo.jpg").write_text("mine\n")
    bad_cli(capfd, "calibrate", rig, "--out", out, "--no-figures",
            expect=f"--out {out / 'left'}: the folder is not empty and is not a paretocal run")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "photo.jpg").write_text("mine\n")
    bad_cli(capfd, "calibrate", rig, "--out", mine, "--no-figures",
            expect=f"--out {mine}: the folder is not empty and is not a paretocal rig run")
    assert len(calls) == 1


@pytest.mark.parametrize("target", ["a run folder", "an empty folder", "nothing"])
@pytest.mark.parametrize("joint", [False, True], ids=["per camera", "joint"])
def test_a_rig_camera_folder_that_is_a_link_is_refused(capfd, tmp_path, monkeypatch, target,
                                                       joint):
    """A rig's per-camera run folder (OUT/<name>) or its joint one (OUT/joint) that is a
    symbolic link is refused before anything is read or written, as a batch entry's runs/<id>
    is: the run's files would go wherever the link leads (a run folder there replaced)."""
    import paretocal.apps.rig
    from paretocal.apps.rig import calibrate_rig
    from .test_rig import make_rig

    rig = make_rig(tmp_path)
    monkeypatch.setattr(paretocal.apps.rig, "calibrate_run",
                        lambda *a, **k: pytest.fail("a run started through the link"))
    elsewhere = tmp_path / "elsewhere" / "run"
    if target == "a run folder":
        elsewhere.mkdir(parents=True)
        (elsewhere / ".outputs").write_text("result.json\n")
        (elsewhere / "result.json").write_text("mine\n")
    elif target == "an empty folder":
        elsewhere.mkdir(parents=True)
    out = tmp_path / "out"
    out.mkdir()
    name = "joint" if joint else "left"
    (out / name).symlink_to(elsewhere)
    before = _snapshot(tmp_path)
    expect = f"{out / name}: is a symbolic link, not a rig camera's run folder"
    bad_cli(capfd, "calibrate", rig, "--out", out, "--no-figures",
            *(["--joint"] if joint else []), expect=expect)
    with pytest.raises(InputError, match="is a symbolic link, not a rig camera's run folder"):
        calibrate_rig(rig, out, Settings(frames="0:2"), joint=joint)
    assert _snapshot(tmp_path) == before


# --- result.json comes with its own run's run_args.json ------------------------------------------

def test_a_failed_rerun_keeps_the_run_args_of_the_published_run(capfd, tmp_path, raw_date,
                                                                 done_run, monkeypatch):
    """A rerun (seed 3) whose publication fails (a full disk) leaves the published run (seed
    2) whole, with its own run_args.json; --resume then finishes the rerun and publishes it
    with its arguments."""
    import errno

    import paretocal.rundir
    from paretocal.io.atomic import write_error

    run = _copy(done_run, tmp_path)

    def full(*args, **kwargs):
        raise write_error(run / "result.json", OSError(errno.ENOSPC, "No space left on device"))

    with monkeypatch.context() as m:
        m.setattr(paretocal.rundir, "write_outputs", full)
        bad_cli(capfd, "calibrate", raw_date, "--out", run, "--seed", "3", *CLI,
                expect="No space left on device")

    def seeds():
        return (json.loads((run / "result.json").read_text())["seed"],
                json.loads((run / "run_args.json").read_text())["settings"]["search"]["seed"])
    assert seeds() == (2, 2)
    code, _, err = run_cli(capfd, "calibrate", "--resume", run, "--quiet")
    assert code == 0, err
    assert seeds() == (3, 3) and not (run / ARGS).exists()
    assert not (run / "checkpoint.npz").exists()


def test_a_folder_of_the_previous_release_resumes(capfd, tmp_path, stopped_run):
    """run_args.json beside the checkpoint, as the previous release wrote them."""
    run = _copy(stopped_run, tmp_path)
    if (run / ARGS).exists():
        (run / ARGS).rename(run / "run_args.json")
    code, _, err = run_cli(capfd, "calibrate", "--resume", run, "--quiet")
    assert code == 0, err
    names = {p.name for p in run.iterdir()}
    assert {"result.json", "run_args.json"} <= names
    assert not {ARGS, "checkpoint.npz", "partial_front.csv", ".staging", ".lock"} & names


# --- stale temporaries do not outlive a finished run ---------------------------------------------

def test_a_finished_resume_removes_stale_temporaries_of_its_files_only(capfd, tmp_path,
                                                                      stopped_run):
    run = _copy(stopped_run, tmp_path)
    stale = [".checkpoint.npz.k3j_x9qa.tmp.npz", ".result.json.abcdefgh.tmp.json",
             f".{ARGS}.0123abcd.tmp.json"]
    kept = [".checkpoint.npz.short.tmp.npz", ".notes.txt.abcdefgh.tmp.txt",
            "checkpoint.npz.abcdefgh.tmp.npz"]
    for name in stale + kept:
        (run / name).write_bytes(b"partial")
    target = tmp_path / "target.npz"
    target.write_bytes(b"mine")
    (run / ".checkpoint.npz.linkedxx.tmp.npz").symlink_to(target)      # links: not removed
    code, _, err = run_cli(capfd, "calibrate", "--resume", run, "--quiet")
    assert code == 0, err
    names = {p.name for p in run.iterdir()}
    assert not set(stale) & names
    assert set(kept) | {".checkpoint.npz.linkedxx.tmp.npz"} <= names
    assert target.read_bytes() == b"mine"


def test_atomic_paths_temporaries_match_the_pattern(tmp_path):
    from paretocal.io.atomic import atomic_path, temporary_pattern

    for name in ("checkpoint.npz", "result.json", ".outputs", "calib_velo_to_cam.txt"):
        with atomic_path(tmp_path / name) as tmp:
            tmp.write_text("x")
            assert temporary_pattern(tmp_path / name).fullmatch(tmp.name), tmp.name
