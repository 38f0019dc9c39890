"""Reading text inputs: KITTI calibration files, YAML (calib.yaml, camera_info, settings,
--init files, batch manifests) and JSON (inputs, and the files paretocal reads back), with
their size, aliases, nesting and duplicate keys bounded.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError, excerpt, first_line, is_name, quote
from .paths import mib, require_file, require_size

# What a file may hold, or its header claim, is checked before anything is allocated for it (a
# stat and a header read: the normal path costs nothing measurable). Each limit is far beyond any
# real sensor or file, so that only a corrupt or hostile file meets it; docs/bad_input.md lists
# them with their messages.

#: Bytes of a text input: calib.yaml, camera_info, --config, --init, a batch manifest, KITTI
#: calibration text. These hold a few kilobytes; a manifest about 100 bytes per entry, so 8 MiB
#: is some 80,000 entries. PyYAML parses 0.3-1 MB per second on a busy machine: the largest
#: file accepted takes up to half a minute, where a 200 MB file would take over ten minutes.
MAX_TEXT_BYTES = 8 << 20
_TEXT = "YAML, JSON, CSV or calibration text file"
#: Most values (scalars, lists and mappings) a YAML file may hold once its aliases are expanded.
#: A value costs at most about 100 bytes as a Python object (8 as a number in numpy), so one
#: file can make the readers build at most about 100 MB; the files paretocal reads (calib.yaml,
#: camera_info, --config, --init) hold a few hundred values. Aliases themselves are allowed:
#: only their expansion is bounded ("billion laughs": nine nested anchors of nine aliases each
#: are 340 bytes of text and 387 million values, which numpy turns into 2.9 GB).
MAX_YAML_VALUES = 1_000_000


def read_kitti_calib(path: Path) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``key: numbers`` per line) into float64 arrays.

    Lines whose values are not numbers (such as ``calib_time``) are skipped.
    """
    path = Path(path)
    require_file(path, "calibration file")
    out: dict[str, np.ndarray] = {}
    try:
        require_size(path, MAX_TEXT_BYTES, _TEXT)
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8); expected a KITTI calibration "
                         "file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read calibration file ({exc.strerror or exc})") from None
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            out[key.strip()] = np.array([float(v) for v in rest.split()], dtype=np.float64)
        except ValueError:
            continue
    return out


def calib_matrix(calib: dict[str, np.ndarray], key: str, shape: tuple[int, int],
                 path: Path) -> np.ndarray:
    """Fetch ``key`` from a parsed KITTI calibration and reshape it, or fail naming the file."""
    if key not in calib:
        raise InputError(f"{path}: missing key {key!r}")
    v = calib[key]
    if v.size != shape[0] * shape[1]:
        raise InputError(f"{path}: {key!r} has {v.size} values, expected "
                         f"{shape[0] * shape[1]} ({shape[0]}x{shape[1]})")
    m = v.reshape(shape)
    if not np.all(np.isfinite(m)):
        raise InputError(f"{path}: {key!r} contains NaN or infinite values")
    return m


class _AliasBomb(Exception):
    """A YAML document whose aliases expand beyond :data:`MAX_YAML_VALUES`, or refer to
    themselves."""


def _expanded_size(node, sizes: dict, open_: set) -> int:
    """Values in ``node`` with every alias expanded (memoised per node, so linear in the
    document's own nodes however often they are referred to)."""
    key = id(node)
    if key in sizes:
        return sizes[key]
    if key in open_:
        raise _AliasBomb("a YAML alias refers to a structure that contains it (a recursive "
                         "document); write the values out instead")
    open_.add(key)
    n = 1
    if isinstance(node, yaml.SequenceNode):
        n += sum(_expanded_size(v, sizes, open_) for v in node.value)
    elif isinstance(node, yaml.MappingNode):
        n += sum(_expanded_size(k, sizes, open_) + _expanded_size(v, sizes, open_)
                 for k, v in node.value)
    open_.discard(key)
    sizes[key] = n
    if n > MAX_YAML_VALUES:
        raise _AliasBomb(f"its YAML aliases expand it to more than {MAX_YAML_VALUES:,} values "
                         "(an alias bomb?); write the values out instead of repeating anchors")
    return n


class _DuplicateKey(Exception):
    """A mapping that holds a key twice: ``key``, and the lines (1-based) of both, or None."""

    def __init__(self, key, lines=None):
        super().__init__(key)
        self.key, self.lines = key, lines

    def error(self, path) -> InputError:
        shown = quote(self.key) if is_name(self.key) else "a key that is not a plain name"
        a, b = self.lines or (None, None)
        where = "" if a is None else f" (line {a})" if a == b else f" (lines {a} and {b})"
        return InputError(f"{path}: {shown} is given twice in one mapping{where}; a key may "
                          "appear once (the second would silently replace the first)")


class _UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a mapping holding a key twice, at any depth (PyYAML
    keeps the last one silently). Keys brought in by a merge (``<<: *anchor``) may be
    overridden: that is what a merge is for."""

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                if key in seen:
                    raise _DuplicateKey(key, (seen[key], line))
                seen[key] = line
            except TypeError:
                continue                                # unhashable: the constructor says so
        return super().construct_mapping(node, deep)


def _unique_pairs(pairs: list) -> dict:
    """``object_pairs_hook`` of :func:`json.loads` that refuses a key given twice."""
    seen = set()
    for key, _ in pairs:
        if key in seen:
            raise _DuplicateKey(key)
        seen.add(key)
    return dict(pairs)


#: Why a file nested too deeply is refused. Python's JSON and YAML readers recurse once (or a
#: few times) per level and raise RecursionError some hundreds of levels down; the files
#: paretocal reads nest a few levels.
_TOO_DEEP = ("its values are nested too deeply to be read (lists or mappings hundreds of "
             "levels deep; the files paretocal reads nest a few)")


def _check_length(text: str, path: Path | str) -> None:
    if len(text) > MAX_TEXT_BYTES:
        raise InputError(f"{path}: {len(text):,} characters, more than the "
                         f"{mib(MAX_TEXT_BYTES)} a {_TEXT} may hold")


def load_yaml(text: str, path: Path | str):
    """``yaml.safe_load`` of ``text`` that refuses what would be read wrongly or slowly,
    naming ``path``.

    :class:`InputError` is raised, before anything is built, for text longer than
    :data:`MAX_TEXT_BYTES` or anchors and aliases that expand beyond :data:`MAX_YAML_VALUES`
    values (or refer to themselves); and for a mapping that holds a key twice (at any depth)
    or values nested too deeply to read (hundreds of levels).
    YAML syntax errors propagate as :class:`yaml.YAMLError` (:func:`yaml_error` words them).
    """
    _check_length(text, path)
    loader = _UniqueKeyLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node, {}, set())
        return loader.construct_document(node)
    except _AliasBomb as exc:
        raise InputError(f"{path}: {exc}") from None
    except _DuplicateKey as exc:
        raise exc.error(path) from None
    except RecursionError:
        raise InputError(f"{path}: {_TOO_DEEP}") from None
    finally:
        loader.dispose()


def load_json(text: str, path: Path | str):
    """``json.loads`` of ``text`` that refuses what would be read wrongly or not at all,
    naming ``path``: :class:`InputError` for text longer than :data:`MAX_TEXT_BYTES`, a
    mapping that holds a key twice (at any depth), values nested too deeply to read
    (hundreds of levels) and text that is not JSON. The one reader of every JSON file
    paretocal reads back (a run's arguments, a checkpoint's metadata, a batch entry's
    record, the cost-model cache) and of JSON inputs."""
    _check_length(text, path)
    try:
        return json.loads(text, object_pairs_hook=_unique_pairs)
    except _DuplicateKey as exc:
        raise exc.error(path) from None
    except RecursionError:
        raise InputError(f"{path}: {_TOO_DEEP}") from None
    except ValueError as exc:
        raise InputError(f"{path}: not valid JSON ({first_line(exc)})") from None


def yaml_error(path: Path | str, exc: yaml.YAMLError) -> InputError:
    """The one-line error for a YAML syntax error in ``path``: the line and column and the
    parser's words, never the lines of the file it quotes."""
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        return InputError(f"{path}: not valid YAML "
                          f"({where}{excerpt(exc.problem or exc.context or 'syntax error')})")
    return InputError(f"{path}: not valid YAML ({first_line(exc)})")


def read_mapping(path: Path) -> dict:
    """Read a YAML or JSON file whose top level is a mapping."""
    path = Path(path)
    require_file(path, "file")
    try:
        require_size(path, MAX_TEXT_BYTES, _TEXT)
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8); expected YAML or JSON") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if path.suffix.lower() == ".json":
        data = load_json(text, path)
    else:
        try:
            data = load_yaml(text, path)
        except yaml.YAMLError as exc:
            raise yaml_error(path, exc) from None
        except ValueError as exc:              # a value PyYAML cannot construct
            raise InputError(f"{path}: not valid YAML ({first_line(exc)})") from None
    if not isinstance(data, dict):
        got = "an empty file" if data is None else f"a {type(data).__name__}"
        raise InputError(f"{path}: expected a mapping (key: value) at the top level, got {got}")
    return data
