"""Property tests (hypothesis) of the loaders and the geometry.

* Loaders: random bytes, and random but structured (valid, nearly valid, invalid) ``.bin``,
  ``.npy``, ``.pcd``, ``.ply``, ``calib.yaml``, ``--init`` and ``--config`` contents either load
  into something sound or raise a :class:`~paretocal.errors.ParetocalError`: never another
  exception (and never a Python warning: the test configuration turns warnings into errors).
* Geometry: the correction, its parameters and the inverse round-trip; projection agrees with
  the pinhole model for random rigid transforms; the objective does not depend on the order of
  the points within a frame.

Example counts are kept small so the whole file runs in well under 20 s.
"""

from __future__ import annotations

import json
import os
import string

import lzf
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from paretocal.camera import Camera, project
from paretocal.config import Settings, load_settings
from paretocal.errors import InputError, ParetocalError, SettingsError
from paretocal.geometry import (apply_correction, correction_matrix, correction_params, invert,
                                pose_error, rotation_angle_deg, transform_points)
from paretocal.io import detect_source, read_extrinsic
from paretocal.io.clouds import read_points

#: More examples for a deeper search: PARETOCAL_FUZZ_EXAMPLES=2000 pytest tests/test_fuzz.py
N = int(os.environ.get("PARETOCAL_FUZZ_EXAMPLES", "40"))
# filter_too_much: a random settings document is often invalid across fields (rejected with
# assume): those are the bad-input tests' business; the ones that load are what is checked.
FUZZ = settings(max_examples=N, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])
FEW = settings(max_examples=max(N // 3, 10), deadline=None,
               suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """One folder for every example (hypothesis runs examples inside a single test call)."""
    return tmp_path_factory.mktemp("fuzz")


def check_points(path):
    """``read_points`` either returns a sound cloud or raises InputError."""
    try:
        pts = read_points(path)
    except InputError as exc:
        assert str(path) in str(exc)            # the message names the file
        event("rejected")
        return None
    event("loaded")
    assert pts.dtype == np.float32 and pts.ndim == 2 and pts.shape[1] == 4
    assert len(pts) > 0 and np.isfinite(pts).all()
    return pts


# --- numbers that stress parsers ------------------------------------------------------------------

wild_floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
mild_floats = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
some_floats = st.one_of(mild_floats, wild_floats, st.sampled_from([0.0, 1e39, -1e39, 1e300]))


# --- raw bytes ------------------------------------------------------------------------------------

@FUZZ
@given(suffix=st.sampled_from([".bin", ".npy", ".pcd", ".ply"]),
       prefix=st.sampled_from([b"", b"ply\n", b"ply\nformat ascii 1.0\n", b"VERSION 0.7\n",
                               b"FIELDS x y z\n", b"\x93NUMPY\x01\x00"]),
       body=st.binary(max_size=600))
def test_random_bytes_never_crash_the_point_readers(work, suffix, prefix, body):
    p = work / f"random{suffix}"
    p.write_bytes(prefix + body)
    check_points(p)


# --- .bin and .npy --------------------------------------------------------------------------------

@FUZZ
@given(rows=st.lists(st.tuples(some_floats, some_floats, some_floats, some_floats), max_size=16),
       extra=st.sampled_from([0, 0, 0, 1, 4, 15, 16]))
def test_bin_of_any_floats(work, rows, extra):
    p = work / "a.bin"
    values = [v for row in rows for v in row]
    with np.errstate(over="ignore"):
        raw = np.array(values, dtype=np.float64).astype(np.float32).tobytes() + b"\x00" * extra
    p.write_bytes(raw)
    pts = check_points(p)
    if len(raw) % 16 or not raw:
        assert pts is None                          # truncated or empty
        return
    rows = np.frombuffer(raw, np.float32).reshape(-1, 4)
    finite = np.isfinite(rows[:, :3]).all(axis=1)
    if finite.any():                                # NaN and infinite rows are dropped, no more
        assert pts is not None and len(pts) == finite.sum()
        np.testing.assert_array_equal(pts[:, :3], rows[finite, :3])
    else:
        assert pts is None


@FUZZ
@given(shape=st.one_of(st.tuples(st.integers(0, 6), st.sampled_from([3, 4, 2, 5])),
                      st.lists(st.integers(0, 5), min_size=0, max_size=3)),
       dtype=st.sampled_from(["f4", "f8", "i4", "u1", "c16", "?", "U3"]),
       fill=some_floats)
def test_npy_of_any_shape_and_dtype(work, shape, dtype, fill):
    p = work / "a.npy"
    with np.errstate(all="ignore"):
        try:
            arr = np.full(shape, fill).astype(dtype)
        except (ValueError, OverflowError):
            arr = np.zeros(shape, dtype)
    np.save(p, arr)
    pts = check_points(p)
    if pts is not None:
        assert arr.ndim == 2 and arr.shape[1] in (3, 4) and arr.dtype.kind in "iuf"


# --- .pcd -----------------------------------------------------------------------------------------

VALID_PCD_TYPES = [("F", 4), ("F", 8), ("U", 1), ("U", 2), ("I", 4)]
BAD_PCD_TYPES = [("F", 3), ("X", 4), ("U", 3)]
PCD_DAMAGE = [None, None, None, None, "type", "count", "width", "drop_line", "cut", "junk",
              "points", "data", "no_z", "random_body"]


def _column(draw, kind: str, size: int, n: int) -> np.ndarray:
    vals = draw(st.lists(some_floats if kind == "f" else st.integers(0, 200), min_size=n,
                         max_size=n))
    with np.errstate(all="ignore"):
        return np.array(vals, dtype=np.float64).astype(f"<{kind}{size}")


@st.composite
def pcd_files(draw):
    """A PCD file with x, y, z and maybe more fields, valid or with one kind of damage."""
    damage = draw(st.sampled_from(PCD_DAMAGE))
    names = draw(st.permutations(["x", "y", "z"] + draw(st.sampled_from(
        [[], ["intensity"], ["i", "ring"], ["_", "reflectance"]]))))
    if damage == "no_z":
        names = [n for n in names if n != "z"] or ["x"]
    types = [draw(st.sampled_from(VALID_PCD_TYPES)) for _ in names]
    counts = [1] * len(names)
    if damage == "type":
        types[0] = draw(st.sampled_from(BAD_PCD_TYPES))
    if damage == "count":
        counts[0] = draw(st.sampled_from([0, 2]))
    n = draw(st.integers(1 if damage is None else 0, 12))
    data = draw(st.sampled_from(["ascii", "binary", "binary_compressed"]))
    lines = ["# .PCD v0.7", "VERSION 0.7", "FIELDS " + " ".join(names),
             "SIZE " + " ".join(str(sz) for _, sz in types),
             "TYPE " + " ".join(t for t, _ in types), "COUNT " + " ".join(map(str, counts)),
             f"WIDTH {n + 1 if damage == 'width' else n}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0",
             f"POINTS {n + 3 if damage == 'points' else n}",
             f"DATA {'binary_lzma' if damage == 'data' else data}"]
    if damage == "drop_line":
        del lines[draw(st.sampled_from([2, 3, 4, 9, 10]))]
    head = ("\n".join(lines) + "\n").encode()
    cols = [_column(draw, {"F": "f", "U": "u", "I": "i"}[t], sz, n)
            for (t, sz), c in zip(types, counts) if (t, sz) in VALID_PCD_TYPES for _ in range(c)]
    if damage == "random_body" or not cols:
        body = draw(st.binary(max_size=200))
    elif data == "ascii":
        body = "".join(" ".join(repr(float(c[k])) for c in cols) + "\n" for k in range(n)).encode()
    elif data == "binary":
        rec = np.zeros(n, dtype=[(f"c{j}", c.dtype) for j, c in enumerate(cols)])
        for j, c in enumerate(cols):
            rec[f"c{j}"] = c
        body = rec.tobytes()
    else:
        raw = b"".join(c.tobytes() for c in cols)
        packed = (lzf.compress(raw) if raw else b"") or b""
        body = np.array([len(packed), len(raw)], "<u4").tobytes() + packed
    if damage == "cut":
        body = body[: max(len(body) - draw(st.integers(1, 40)), 0)]
    if damage == "junk":
        body += draw(st.sampled_from([b"1 2\n", b"\xff", b"nan nan nan nan nan\n"]))
    return head + body


@FUZZ
@given(pcd_files())
def test_pcd_valid_or_damaged(work, content):
    p = work / "a.pcd"
    p.write_bytes(content)
    check_points(p)


# --- .ply -----------------------------------------------------------------------------------------

PLY_NP = {"float": "f4", "float32": "f4", "double": "f8", "uchar": "u1", "int": "i4",
          "ushort": "u2"}
PLY_DAMAGE = [None, None, None, None, "format", "type", "list", "count", "no_end", "cut",
              "no_y", "random_body"]


@st.composite
def ply_files(draw):
    """A PLY file with a vertex element (x, y, z, ...), valid or with one kind of damage."""
    damage = draw(st.sampled_from(PLY_DAMAGE))
    fmt = draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian"]))
    names = draw(st.permutations(["x", "y", "z"] + draw(st.sampled_from(
        [[], ["intensity"], ["nx", "reflectance"]]))))
    if damage == "no_y":
        names = [n for n in names if n != "y"]
    types = [draw(st.sampled_from(list(PLY_NP))) for _ in names]
    n = draw(st.integers(1 if damage is None else 0, 10))
    before, after = draw(st.booleans()), draw(st.booleans())
    head = ["ply", f"format {'binary_middle_endian' if damage == 'format' else fmt} 1.0",
            "comment fuzz"]
    if before:
        head += ["element camera 1", "property float f"]
    head.append(f"element vertex {'ten' if damage == 'count' else n}")
    head += [f"property {t} {name}" for name, t in zip(names, types)]
    if damage == "type":
        head.append("property half w")
    if damage == "list":
        head.append("property list uchar int w")
    if after:
        head += ["element face 1", "property list uchar int vertex_indices"]
    if damage != "no_end":
        head.append("end_header")
    text = ("\n".join(head) + "\n").encode()
    cols = [_column(draw, PLY_NP[t][0], int(PLY_NP[t][1]), n) for t in types]
    if damage == "random_body":
        body = draw(st.binary(max_size=120))
    elif fmt == "ascii":
        rows = (["1.5"] if before else []) + [" ".join(repr(c[k].item()) for c in cols)
                                              for k in range(n)]
        body = ("\n".join(rows) + "\n" + ("3 0 1 2\n" if after else "")).encode()
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        rec = np.zeros(n, dtype=[(f"c{j}", e + c.dtype.str[1:]) for j, c in enumerate(cols)])
        for j, c in enumerate(cols):
            rec[f"c{j}"] = c
        body = (np.array([1.5], e + "f4").tobytes() if before else b"") + rec.tobytes()
    if damage == "cut":
        body = body[: max(len(body) - draw(st.integers(1, 20)), 0)]
    return text + body


@FUZZ
@given(ply_files())
def test_ply_valid_or_damaged(work, content):
    p = work / "a.ply"
    p.write_bytes(content)
    check_points(p)


# --- YAML: calib.yaml, --init, --config -----------------------------------------------------------

yaml_scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), some_floats,
                         st.text(string.ascii_letters + " :[]{}-#", max_size=8))


def matrices(rows=(3, 4), cols=(3, 4)):
    row = st.lists(st.one_of(mild_floats, yaml_scalars), min_size=min(cols), max_size=max(cols))
    return st.one_of(st.lists(row, min_size=min(rows), max_size=max(rows)), yaml_scalars)


def rigid(params):
    """A valid T_cam_lidar from six numbers, as nested lists."""
    return correction_matrix(np.asarray(params)).tolist()


params6 = st.lists(st.floats(-50, 50, allow_nan=False), min_size=6, max_size=6)
extrinsics = st.one_of(params6.map(rigid), matrices((3, 5), (3, 5)))


@st.composite
def calib_docs(draw):
    """A valid calib.yaml document with zero to three random changes."""
    cam = {"K": [[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]], "width": 1242, "height": 375}
    doc = {"camera": cam, "T_cam_lidar": draw(params6.map(rigid))}
    changes = {
        "K": lambda: cam.update(K=draw(matrices((2, 4)))),
        "width": lambda: cam.update(width=draw(yaml_scalars)),
        "height": lambda: cam.update(height=draw(st.one_of(yaml_scalars, st.floats(1, 1e4)))),
        "D": lambda: cam.update(D=draw(st.one_of(
            st.lists(st.one_of(mild_floats, yaml_scalars), max_size=6),
            st.lists(st.floats(-0.5, 0.5), min_size=4, max_size=5), yaml_scalars))),
        "model": lambda: cam.update(model=draw(st.one_of(
            st.sampled_from(["pinhole", "fisheye", "radtan", "omnidir"]), yaml_scalars))),
        "drop": lambda: cam.pop(draw(st.sampled_from(["K", "width", "height"]))),
        "ros": lambda: cam.update(image_width=draw(yaml_scalars), camera_matrix=draw(
            st.one_of(yaml_scalars, st.fixed_dictionaries({"rows": yaml_scalars,
                                                           "cols": yaml_scalars,
                                                           "data": st.lists(mild_floats,
                                                                            max_size=10)})))),
        "camera": lambda: doc.update(camera=draw(yaml_scalars)),
        "T": lambda: doc.update(T_cam_lidar=draw(extrinsics)),
        "no_T": lambda: doc.pop("T_cam_lidar"),
        "camera_info": lambda: doc.update(camera_info=draw(yaml_scalars)),
    }
    for name in draw(st.lists(st.sampled_from(sorted(changes)), max_size=3, unique=True)):
        if name in ("drop", "ros") and not isinstance(doc.get("camera"), dict):
            continue
        if name == "no_T" and "T_cam_lidar" not in doc:
            continue
        changes[name]()
    return doc


def dump(doc) -> str:
    return yaml.safe_dump(doc, default_flow_style=None, allow_unicode=True)


yaml_texts = st.one_of(st.text(max_size=120),
                       st.text(string.printable, max_size=120),
                       st.sampled_from(["{", "[1, 2", "a: b: c", "- - -", "!!python/object:os.system {}",
                                        "key: &a [*a]", "\t- x", "T_cam_lidar: [[1, 0]", "", "~"]))


@pytest.fixture(scope="module")
def rig(work):
    """A generic folder whose calib.yaml the examples rewrite (images and points not read)."""
    root = work / "rig"
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    (root / "images" / "000000.png").write_bytes(b"")
    (root / "points" / "000000.bin").write_bytes(b"")
    return root


def check_calib(root):
    try:
        src = detect_source(root)
    except ParetocalError:
        event("rejected")
        return
    event("loaded")
    f = src.frames[0]
    assert f.camera.K.shape == (3, 3) and np.isfinite(f.camera.K).all()
    assert f.camera.width > 0 and f.camera.height > 0
    if f.T_ref is not None:
        assert np.allclose(f.T_ref[:3, :3].T @ f.T_ref[:3, :3], np.eye(3), atol=1e-9)


@FUZZ
@given(calib_docs())
def test_calib_yaml_structures(rig, doc):
    (rig / "calib.yaml").write_text(dump(doc))
    check_calib(rig)


@FUZZ
@given(yaml_texts)
def test_calib_yaml_random_text(rig, text):
    (rig / "calib.yaml").write_text(text, encoding="utf-8", errors="surrogatepass")
    check_calib(rig)


def check_init(path):
    try:
        T = read_extrinsic(path)
    except InputError as exc:
        assert str(path) in str(exc)
        event("rejected")
        return None
    event("loaded")
    assert T.shape == (4, 4) and np.isfinite(T).all()
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-9)
    assert np.linalg.det(T[:3, :3]) > 0 and np.array_equal(T[3], [0, 0, 0, 1])
    return T


@FUZZ
@given(st.one_of(extrinsics.map(lambda m: {"T_cam_lidar": m}),
                 st.dictionaries(st.sampled_from(["T_cam_lidar", "T", "extra"]), extrinsics)),
       st.sampled_from([".yaml", ".json"]))
def test_init_structures(work, doc, suffix):
    p = work / f"init{suffix}"
    p.write_text(json.dumps(doc) if suffix == ".json" else dump(doc))
    T = check_init(p)
    if isinstance(doc.get("T_cam_lidar"), list) and T is not None:
        np.testing.assert_allclose(T[:3], np.array(doc["T_cam_lidar"], float)[:3], atol=1e-4)


@FUZZ
@given(yaml_texts, st.sampled_from([".yaml", ".json"]))
def test_init_random_text(work, text, suffix):
    p = work / f"init_text{suffix}"
    p.write_bytes(text.encode("utf-8", "surrogatepass"))
    check_init(p)


SECTION_KEYS = {"search": ["pop", "gens", "seed", "bound_t_m", "n_min", "n_max", "engine",
                           "seed_grid_deg", "popsize"],
                "features": ["grid", "blur_sigma", "z_min", "reselect", "ring_method"],
                "objective": ["w_edge", "ucb_k", "chamfer", "holdout"],
                "decision": ["rule", "budget_ms", "polish"], "extra": ["x"]}
config_values = st.one_of(yaml_scalars, st.lists(st.integers(-2, 10), max_size=3),
                          st.integers(0, 500), st.floats(0, 2))


@st.composite
def config_docs(draw):
    doc = {}
    for section in draw(st.lists(st.sampled_from(list(SECTION_KEYS) + ["camera", "frames"]),
                                 max_size=3, unique=True)):
        if section in ("camera", "frames"):
            doc[section] = draw(config_values)
        elif draw(st.integers(0, 9)) == 0:
            doc[section] = draw(yaml_scalars)
        else:
            keys = draw(st.lists(st.sampled_from(SECTION_KEYS[section]), max_size=3, unique=True))
            doc[section] = {k: draw(config_values) for k in keys}
    return doc


@FUZZ
@given(st.one_of(config_docs().map(dump), yaml_texts))
def test_config_files(work, text):
    p = work / "config.yaml"
    p.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        s = load_settings(p)
    except ParetocalError as exc:
        assert "\n" not in str(exc).strip()          # one line for the CLI
        event("rejected")
        return
    event("loaded")
    assert isinstance(s, Settings)
    s.validate()                                     # what loads is valid


@st.composite
def settings_docs(draw):
    """Settings laid out by section with values near the defaults, None where a field allows
    it (most of them valid; the invalid ones are rejected by the test)."""
    import dataclasses as dc

    from paretocal.config import CHOICES, _field_types

    base = Settings()
    doc = {}
    for f in dc.fields(Settings):
        current = getattr(base, f.name)
        if not dc.is_dataclass(current):
            continue
        section = {}
        for name, annotation in _field_types(type(current)).items():
            if not draw(st.booleans()):
                continue
            value = getattr(current, name)
            kinds = [k.strip() for k in annotation.split("|")]
            if "None" in kinds and draw(st.integers(0, 3)) == 0:
                section[name] = None
                continue
            kind = kinds[0]
            if kind == "bool":
                section[name] = draw(st.booleans())
            elif kind == "int":
                section[name] = max(1, int(value or 1) + draw(st.integers(-2, 5)))
            elif kind == "float":
                ref = value if value not in (None, 0.0) else 1.0
                section[name] = float(ref) * draw(st.floats(0.25, 2.0))
            elif kind == "str":
                section[name] = draw(st.sampled_from(CHOICES.get((f.name, name), (value,))))
            elif kind.startswith("tuple"):
                section[name] = [draw(st.integers(1, 16)), draw(st.integers(1, 16))]
        doc[f.name] = section
    if draw(st.booleans()):
        doc["frames"] = draw(st.sampled_from([None, "0:5", "0,3,7"]))
    return doc


@FUZZ
@given(settings_docs())
def test_settings_round_trip_exactly(doc):
    """Any valid settings -> dict -> YAML -> settings is equal (None included: a saved run
    reloads as the same run, a batch worker gets the settings it was sent)."""
    from hypothesis import assume

    from paretocal.config import settings_from_mapping

    try:
        s = settings_from_mapping(doc)
    except ParetocalError:
        assume(False)
    for section, values in doc.items():                 # what the file says is what loads
        if isinstance(values, dict):
            for key, value in values.items():
                got = getattr(getattr(s, section), key)
                assert (got is None) if value is None else got == pytest.approx(
                    tuple(value) if isinstance(value, list) else value), (section, key)
        else:
            assert getattr(s, section) == values
    text = yaml.safe_dump(s.to_dict(), sort_keys=False)
    again = settings_from_mapping(yaml.safe_load(text))
    assert again == s
    assert again.to_dict() == s.to_dict()


def test_null_turns_the_seed_grid_off(work):
    p = work / "nogrid.yaml"
    p.write_text("search:\n  seed_grid_deg: null\n  bound_t_m: null\n")
    s = load_settings(p)
    assert s.search.seed_grid_deg is None and s.search.bound_t_m is None
    # The command line's "not given" stays "keep the current value".
    assert s.replace(search={"seed_grid_deg": None}).search.seed_grid_deg is None
    assert Settings().replace(search={"seed_grid_deg": None}).search.seed_grid_deg == 2.5


def test_retired_settings_load_only_with_their_one_meaning(work):
    """Files written before ``search.eliminate_duplicates`` was retired still load when it says
    what the code does (false); ``true`` is refused naming the key, as is the retired engine."""
    p = work / "old.yaml"
    p.write_text("search:\n  engine: lean\n  eliminate_duplicates: false\n  pop: 40\n")
    assert load_settings(p).search.pop == 40
    p.write_text("search:\n  eliminate_duplicates: true\n")
    with pytest.raises(SettingsError, match="eliminate_duplicates"):
        load_settings(p)
    p.write_text("search:\n  engine: pymoo\n")
    with pytest.raises(SettingsError, match="engine"):
        load_settings(p)


def test_renamed_settings_load_under_their_new_names(work):
    """``decision.refine`` / ``refine_iters`` (files and saved runs written before the polish had
    one name) load as ``decision.polish`` / ``polish_iters``; the new name wins when both are
    given; the settings written name only the new keys."""
    p = work / "old.yaml"
    p.write_text("decision:\n  refine: false\n  refine_iters: 3\n")
    s = load_settings(p)
    assert (s.decision.polish, s.decision.polish_iters) == (False, 3)
    assert Settings().replace(decision={"refine": False}).decision.polish is False
    p.write_text("decision:\n  refine: false\n  polish: true\n")
    assert load_settings(p).decision.polish is True
    assert "refine" not in s.to_dict()["decision"] and "polish" in s.to_dict()["decision"]


# --- geometry -------------------------------------------------------------------------------------

corrections = st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5),
                        st.floats(-179, 179), st.floats(-89, 89), st.floats(-179, 179)
                        ).map(np.array)


@FUZZ
@given(corrections, corrections)
def test_correction_round_trips(p, q):
    D = correction_matrix(p)
    np.testing.assert_allclose(correction_params(D), p, atol=1e-7)
    np.testing.assert_allclose(D @ invert(D), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(invert(invert(D)), D, atol=1e-12)
    # Batched forms agree with one at a time.
    both = correction_matrix(np.stack([p, q]))
    np.testing.assert_allclose(both[1], correction_matrix(q), atol=0)
    np.testing.assert_allclose(invert(both)[0], invert(D), atol=0)
    # A correction followed by the correction back returns to the start.
    T0 = correction_matrix(q)
    back = correction_params(invert(D))
    np.testing.assert_allclose(apply_correction(apply_correction(T0, p), back), T0, atol=1e-9)
    np.testing.assert_allclose(apply_correction(T0, np.stack([p, q])),
                               T0 @ correction_matrix(np.stack([p, q])), atol=1e-12)
    e = pose_error(apply_correction(T0, p), T0)
    angle = float(rotation_angle_deg(D[:3, :3]))
    assert 0.0 <= angle <= 180.0 + 1e-9
    assert float(e["rotation_deg"]) == pytest.approx(angle, abs=1e-6)


@FUZZ
@given(corrections, st.lists(st.tuples(st.floats(-30, 30), st.floats(-30, 30),
                                       st.one_of(st.floats(-5, -1e-3), st.floats(1e-3, 60))),
                             min_size=1, max_size=30),
       st.floats(100, 2000), st.integers(16, 2000), st.integers(16, 1000))
def test_projection_matches_the_pinhole_model(p, cam_pts, f, width, height):
    K = np.array([[f, 0, (width - 1) / 2], [0, 1.1 * f, (height - 1) / 2], [0, 0, 1]])
    cam = Camera(K=K, width=width, height=height)
    T = correction_matrix(p)                       # any rigid transform
    pc = np.array(cam_pts, dtype=np.float64)       # points in the camera frame
    pl = transform_points(invert(T), pc)           # the same points in the LiDAR frame
    uv, z, visible = project(pl, cam, T, z_min=0.1)
    np.testing.assert_allclose(z, pc[:, 2], atol=1e-9)
    front = pc[:, 2] > 0.1 + 1e-9
    expect = (pc[front] @ K.T)[:, :2] / pc[front, 2:3]
    np.testing.assert_allclose(uv[front], expect, rtol=1e-9, atol=1e-6)
    inside = ((expect[:, 0] >= 0) & (expect[:, 0] <= width - 1)
              & (expect[:, 1] >= 0) & (expect[:, 1] <= height - 1))
    strict = np.abs(pc[front, 2] - 0.1) > 1e-6        # away from the z_min boundary
    edge = np.minimum.reduce([expect[:, 0], width - 1 - expect[:, 0], expect[:, 1],
                              height - 1 - expect[:, 1]])
    clear = strict & (np.abs(edge) > 1e-6)
    np.testing.assert_array_equal(visible[front][clear], inside[clear])
    assert not visible[pc[:, 2] < 0.1 - 1e-9].any()
    # Moving the points by D and the extrinsic by D^-1 changes nothing.
    D = correction_matrix(p[::-1] * [1, 1, 1, 0.01, 0.01, 0.01])
    uv2, z2, vis2 = project(transform_points(D, pl), cam, T @ invert(D), z_min=0.1)
    np.testing.assert_allclose(z2, z, atol=1e-9)
    np.testing.assert_allclose(uv2[front], uv[front], rtol=1e-9, atol=1e-6)


# --- the objective ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_frame(raw_frames):
    """The features of one real frame at KITTI's extrinsic, cut to 400 points."""
    from paretocal.pipeline import prepare_features

    f = raw_frames[0]
    (feat,) = prepare_features([f], f.T_ref, Settings())
    m = min(400, len(feat.xyz))
    head, _ = feat.split(1.0 - m / len(feat.xyz))
    return head, f.T_ref


def _objective(feats, T):
    from paretocal.objective import CalibrationObjective, build_scene
    from paretocal.objective.cost import CostModel

    scene = build_scene(feats)
    dummy = CostModel(0.0, 1.0, 0.0, 1.0, 0, 1, {})
    return CalibrationObjective(scene, T, Settings().objective, dummy, ucb_k=2.0)


@FEW
@given(seed=st.integers(0, 2**32 - 1), X=st.lists(corrections, min_size=1, max_size=6))
def test_objective_ignores_the_order_of_points_within_a_frame(small_frame, seed, X):
    from paretocal.features.prepare import FrameFeatures

    feat, T = small_frame
    perm = np.random.default_rng(seed).permutation(len(feat.xyz))
    shuffled = FrameFeatures(feat.name, feat.camera, feat.image, feat.xyz[perm],
                             feat.group[perm], feat.weight[perm], feat.n_rings)
    C = np.zeros((len(X), 7))
    C[:, :6] = np.array(X) * [0.02, 0.02, 0.02, 0.01, 0.01, 0.01]   # near the reference
    C[:, 6] = len(feat.xyz)                        # every point: the same set either way
    a = _objective([feat], T).chamfer(C)
    b = _objective([shuffled], T).chamfer(C)
    for key in ("f1", "se", "in_view"):
        np.testing.assert_allclose(a[key], b[key], rtol=1e-6, atol=1e-9)


@FEW
@given(st.binary(min_size=0, max_size=64))
def test_yaml_reader_on_bytes(work, raw):
    """Non-UTF-8 or binary files given as YAML fail with one clear line."""
    p = work / "bytes.yaml"
    p.write_bytes(raw)
    try:
        read_extrinsic(p)
    except InputError as exc:
        assert "\n" not in str(exc)
