"""The documentation site (``docs/``, ``mkdocs.yml``) and the README stay true to the code.

* The site builds with ``mkdocs build --strict``: a broken link or anchor, a page left out of
  the navigation or a docstring the API reference cannot parse fails the build.
* Every code block of README.md and the pages runs in the tests or says why not: a fenced
  ``bash`` or ``python`` block begins ``# runs on the sample data`` or ``# not run by the
  tests: REASON``; a ``yaml`` block parses; a ``text`` block (output, layouts, synopses) holds
  no command but a synopsis (with a placeholder such as ``SOURCE`` or an optional ``[--x]``);
  no block is left without its language or indented instead of fenced.
* The blocks marked to run are run, block after block in one folder per page, as a user would
  run them from a clone: the folder holds ``.venv/bin/paretocal`` and ``.venv/bin/python``
  (the package under test) and ``../shared/data`` (the sample data). Each block must exit 0
  and leave every file or folder its commands name with ``--out``. A first line going on with
  ``; the docs test adds OPTIONS to paretocal COMMAND`` has those options added to that
  command (a shortcut the page states where it shows it); in a ``python`` block, ``; the docs
  test adds OPTIONS to calibrate()`` (and ``calibrate_run()``) calls those functions with the
  settings the same options give (``--frames``, ``--pop``, ``--gens``, ``--no-polish``).
* README's Python snippet gives the result of the command line before it on the same folder.
* "Getting started" shows what ``make demo`` runs; README.md has at most 200 lines; every
  relative link of the README and of the pages resolves (file and heading).
* The API reference documents every public name, and every function and class it shows
  documents each of its parameters (numpydoc).

The build and the parameter check need the ``docs`` extra (MkDocs, mkdocstrings, griffe): they
are skipped, with the reason, without it, and fail instead under
``PARETOCAL_REQUIRE_OPTIONAL=1`` (CI).
"""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"

MARK = "# runs on the sample data"
ADDS = re.compile(r"; the docs test adds (?P<opts>.+?) to paretocal (?P<cmd>[\w-]+)\s*$")
#: A code block that is not run says why.
NOT_RUN = re.compile(r"^# not run by the tests: \S")
#: ... in a Python block: the functions whose settings the options change.
PY_ADDS = re.compile(r"; the docs test adds (?P<opts>.+?) to (?P<calls>\w+\(\)(?: and \w+\(\))*)\s*$")
#: Blocks of code, which run or say why not.
CODE = ("bash", "python")
#: A line of a text block that is a command (after any ``NAME=value`` prefixes) ...
COMMAND = re.compile(r"^(?:[A-Z_]+=\S+\s+)*(?:\.venv/bin/|paretocal |make |pip |python|cd |"
                     r"mkdir |cp |cat )")
#: ... unless it is a synopsis: a placeholder (SOURCE, RUN_DIR) or an optional option.
SYNOPSIS = re.compile(r"\b[A-Z][A-Z_]*[A-Z]\b(?!=)|\[--")
#: Pages whose commands must run on the sample data (the issue's "done when").
REQUIRED_PAGES = ("getting-started.md", "preparing-data.md")
#: Pages whose commands take longer (a check of 20 frames, a Dask cluster): marked slow.
SLOW_PAGES = ("trusting.md", "fleets.md", "board.md")
#: The modules the API reference documents besides the public names (``paretocal.__all__``).
CORE_MODULES = ("geometry", "camera", "objective", "search", "quality", "lidar", "features",
                "check", "verdict", "result")


def _require(module: str) -> None:
    """Skip (fail under PARETOCAL_REQUIRE_OPTIONAL=1) when ``module`` is missing."""
    if importlib.util.find_spec(module) is None:
        missing = pytest.fail if os.environ.get("PARETOCAL_REQUIRE_OPTIONAL") == "1" else pytest.skip
        missing(f"{module} is not installed: the documentation's tools come with the docs extra "
                "(pip install -e '.[docs]', included in .[test])")


# --- reading the pages ------------------------------------------------------------------------

def fenced_blocks(text: str) -> list[tuple[str, list[str]]]:
    """The fenced code blocks of a Markdown text: ``(info string, lines)`` in order."""
    blocks, info, lines = [], None, []
    for line in text.splitlines():
        stripped = line.strip()
        if info is None:
            if stripped.startswith("```"):
                info, lines = stripped[3:].strip(), []
        elif stripped.startswith("```"):
            blocks.append((info, lines))
            info = None
        else:
            lines.append(line)
    return blocks


def sample_data_blocks(page: Path) -> list[list[str]]:
    """The page's ``bash`` blocks marked to run on the sample data."""
    return [lines for info, lines in fenced_blocks(page.read_text())
            if info == "bash" and lines and lines[0].startswith(MARK)]


def runnable_blocks(page: Path) -> list[tuple[str, list[str]]]:
    """The page's ``bash`` and ``python`` blocks marked to run, in order: ``(info, lines)``."""
    return [(info, lines) for info, lines in fenced_blocks(page.read_text())
            if info in CODE and lines and lines[0].startswith(MARK)]


def indented_code(text: str) -> list[str]:
    """Lines that open an indented code block (four spaces after a blank line, outside a
    fence and not a list's nested item)."""
    found, fence, prev = [], False, ""
    for line in text.splitlines():
        if line.strip().startswith("```"):
            fence = not fence
        elif (not fence and not prev.strip() and line.startswith("    ") and line.strip()
              and not re.match(r"\s*([-*+]|\d+\.)\s", line)):
            found.append(line)
        prev = line
    return found


def block_problems(path: Path) -> list[str]:
    """What keeps the code blocks of a Markdown file from running in the tests or saying why
    not (the module docstring's rules)."""
    import yaml

    bad = [f"an indented code block (fence it): {line.strip()[:60]}"
           for line in indented_code(path.read_text())]
    for k, (info, lines) in enumerate(fenced_blocks(path.read_text()), 1):
        first = lines[0] if lines else ""
        where = f"block {k} ({info or 'no language'})"
        if not info:
            bad.append(f"{where}: name its language (text for output and diagrams)")
        elif info in CODE:
            if not (first.startswith(MARK) or NOT_RUN.match(first)):
                bad.append(f"{where}: begin it with {MARK!r} or '# not run by the tests: "
                           "REASON'")
            elif info == "python" and first.startswith(MARK) and "docs test adds" in first \
                    and not PY_ADDS.search(first):
                bad.append(f"{where}: a Python block's shortcut names calibrate() (and "
                           "calibrate_run())")
        elif info == "yaml":
            try:
                yaml.safe_load("\n".join(lines))
            except yaml.YAMLError as exc:
                bad.append(f"{where}: not YAML ({' '.join(str(exc).split())[:80]})")
        elif info == "text":
            bad += [f"{where}: a command in a text block (make it a bash block that runs or "
                    f"says why not): {line.strip()[:60]}"
                    for line in shell_lines(lines)
                    if COMMAND.match(line.strip())
                    and not SYNOPSIS.search(line.split(" #")[0])]
    return bad


@pytest.mark.parametrize("path", [README] + sorted(DOCS.rglob("*.md")),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_every_code_block_runs_or_says_why_not(path):
    bad = block_problems(path)
    assert not bad, f"{path.relative_to(ROOT)}:\n" + "\n".join(bad)


def test_the_rules_for_code_blocks(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("Text.\n\n    make demo\n\n```\nx\n```\n\n```bash\nls\n```\n\n"
                    "```python\n# not run by the tests: a reason\nimport x\n```\n\n"
                    "```yaml\na: [1\n```\n\n```text\n.venv/bin/paretocal check SOURCE\n"
                    "pip install 'paretocal[bags]'   # no ROS needed\nparetocal: output\n```\n\n"
                    "- a list\n\n"
                    "    - nested\n")
    bad = block_problems(page)
    assert [b.split(":")[0] for b in bad] == [
        "an indented code block (fence it)", "block 1 (no language)", "block 2 (bash)",
        "block 4 (yaml)", "block 5 (text)"], bad
    assert "pip install" in bad[-1]


def shell_lines(lines: list[str]) -> list[str]:
    """The block's lines with backslash continuations joined."""
    out, cur = [], ""
    for line in lines:
        if line.endswith("\\"):
            cur += line[:-1] + " "
        else:
            out.append(cur + line)
            cur = ""
    return out + ([cur] if cur else [])


def with_shortcut(lines: list[str]) -> list[str]:
    """The block as the test runs it: the options its first line names added to that command."""
    m = ADDS.search(lines[0])
    lines = shell_lines(lines)
    if m is None:
        return lines
    command = re.compile(rf"(^|\s)\S*paretocal\s+{re.escape(m['cmd'])}(\s|$)")
    out = [f"{line} {m['opts']}" if command.search(line) and not line.lstrip().startswith("#")
           else line for line in lines]
    assert out != lines, f"the shortcut names paretocal {m['cmd']}, which the block does not run"
    return out


def outputs(lines: list[str]) -> list[str]:
    """What the block's commands write with ``--out``."""
    found = []
    for line in lines:
        if "paretocal" not in line:
            continue
        words = shlex.split(line, comments=True)
        found += [words[i + 1] for i, w in enumerate(words[:-1]) if w == "--out"]
    return found


def pages_with_commands() -> list:
    pages = sorted(p.name for p in DOCS.glob("*.md") if runnable_blocks(p))
    return [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_PAGES else name
            for name in pages]


def test_the_required_pages_have_commands_to_run():
    for name in REQUIRED_PAGES:
        assert sample_data_blocks(DOCS / name), f"docs/{name} has no block marked {MARK!r}"


# --- running them -----------------------------------------------------------------------------

@pytest.fixture
def clone(tmp_path, data):
    """A folder laid out as a clone is: ``.venv/bin/paretocal`` and ``.venv/bin/python`` run
    the package under test, ``../shared/data`` is the sample data."""
    work = tmp_path / "clone"
    bin_dir = work / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    for name, args in (("paretocal", '-m paretocal "$@"'), ("python", '"$@"')):
        shim = bin_dir / name
        shim.write_text(f"#!/bin/sh\nexec {shlex.quote(sys.executable)} {args}\n")
        shim.chmod(0o755)
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "data").symlink_to(data)
    return work


#: How a Python block runs: ``python RUNNER BLOCK [OPTIONS]``, the options of its shortcut
#: given to ``paretocal.calibrate`` and ``calibrate_run`` as the settings they mean.
PY_RUNNER = '''
import dataclasses, runpy, sys
from pathlib import Path

import paretocal
from paretocal.io import select_frames

block, opts = sys.argv[1], sys.argv[2:]
spec, search, decision = None, {}, {}
while opts:
    name = opts.pop(0)
    if name == "--no-polish":
        decision["polish"] = False
    elif name in ("--pop", "--gens"):
        search[name[2:]] = int(opts.pop(0))
    elif name == "--frames":
        spec = opts.pop(0)
    else:
        sys.exit(f"the docs test does not know {name}")


def quick(settings, path):
    s = (settings or paretocal.Settings()).replace(search=search, decision=decision)
    return dataclasses.replace(s, frames=spec) if spec is not None and path else s


def shortcut(function, at):
    # at: the position of the settings among the arguments after the source
    def call(source, *args, **kwargs):
        args = list(args)
        path = isinstance(source, (str, Path))
        if len(args) > at:
            args[at] = quick(args[at], path)
        else:
            kwargs["settings"] = quick(kwargs.get("settings"), path)
        if spec is not None and not path:
            source = [source[i] for i in select_frames([f.name for f in source], spec)]
        return function(source, *args, **kwargs)
    return call


for name, at in (("calibrate", 1), ("calibrate_run", 2)):
    setattr(paretocal, name, shortcut(getattr(paretocal, name), at))
runpy.run_path(block, run_name="__main__")
'''


def run_block(lines: list[str], cwd: Path, info: str = "bash") -> subprocess.CompletedProcess:
    """Run a block in ``cwd`` (a clone, :func:`clone`): bash, or Python through
    :data:`PY_RUNNER` with the options of its shortcut."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src")]
                                        + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    if info == "python":
        m = PY_ADDS.search(lines[0])
        block = cwd / ".docs_block.py"
        block.write_text("\n".join(lines) + "\n")
        args = [str(cwd / ".venv" / "bin" / "python"), "-c", PY_RUNNER, str(block)]
        return subprocess.run(args + (shlex.split(m["opts"]) if m else []), cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=900)
    script = "set -eu\n" + "\n".join(lines) + "\n"
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)


def run_page(page: Path, clone: Path, after=None) -> None:
    """Run the page's blocks marked to run, in order, in ``clone``; ``after(k, info)`` is
    called after block k."""
    blocks = runnable_blocks(page)
    for k, (info, block) in enumerate(blocks, 1):
        lines = with_shortcut(block) if info == "bash" else block
        proc = run_block(lines, clone, info)
        shown = "\n".join(lines)
        assert proc.returncode == 0, (f"{page.name}, block {k} of {len(blocks)} exited "
                                      f"{proc.returncode}:\n{shown}\n--- stderr:\n"
                                      f"{proc.stderr[-3000:]}")
        for out in outputs(lines):
            path = clone / out
            assert path.exists(), f"{page.name}, block {k}: {out} was not written\n{shown}"
            if path.is_dir():
                assert any(path.iterdir()), f"{page.name}, block {k}: {out} is empty"
            else:
                assert path.stat().st_size > 0, f"{page.name}, block {k}: {out} is empty"
        if after is not None:
            after(k, info)


@pytest.mark.parametrize("page", pages_with_commands())
def test_the_pages_commands_run_on_the_sample_data(page, clone):
    run_page(DOCS / page, clone)


def test_readme_runs_and_its_python_snippet_is_the_command_line(clone):
    """README's blocks run in order: the folder, the command line's calibration of it, then
    the Python snippet, which writes its result into the same run folder: the same result."""
    run = clone / "runs" / "myrig"
    seen = {}

    def after(k, info):
        doc = json.loads((run / "result.json").read_text())
        seen[info] = doc
        if info == "bash":
            assert (run / "run_args.json").exists()
        else:
            # The command line's run was replaced whole (its run_args.json with it).
            assert not (run / "run_args.json").exists()

    run_page(README, clone, after)
    cli, py = seen["bash"], seen["python"]
    assert py["T_cam_lidar"] == cli["T_cam_lidar"] and py["n_points"] == cli["n_points"]
    assert py["config"]["search"] == cli["config"]["search"]           # calib.yaml's 5 deg / 0.2 m
    assert cli["config"]["search"]["init_error_deg"] == 5.0


def test_the_shortcut_adds_options_to_the_named_command_only():
    block = [f"{MARK}; the docs test adds --pop 16 --gens 3 to paretocal calibrate",
             ".venv/bin/paretocal perturb SRC --out a.yaml",
             ".venv/bin/paretocal calibrate SRC \\", "    --init a.yaml --out run"]
    assert with_shortcut(block) == [block[0], ".venv/bin/paretocal perturb SRC --out a.yaml",
                                        ".venv/bin/paretocal calibrate SRC      --init a.yaml "
                                        "--out run --pop 16 --gens 3"]
    assert outputs(with_shortcut(block)) == ["a.yaml", "run"]


def test_getting_started_shows_what_make_demo_runs():
    """The commands the page says ``make demo`` runs are those of the Makefile's recipe (with
    the default data folder, ``../shared/data``)."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    env = {k: v for k, v in os.environ.items() if k not in ("PARETOCAL_DATA", "MAKEFLAGS")}
    proc = subprocess.run(["make", "-n", "demo"], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    recipe = [line.strip() for line in proc.stdout.splitlines()
              if re.search(r"\bparetocal (perturb|calibrate)\b", line)]
    shown = [line.strip() for block in sample_data_blocks(DOCS / "getting-started.md")
             for line in shell_lines(block)
             if re.search(r"\bparetocal (perturb|calibrate)\b", line) and not line.startswith("#")]
    assert recipe and shown[:len(recipe)] == recipe


# --- the README and the links -----------------------------------------------------------------

def test_readme_is_at_most_200_lines():
    n = len(README.read_text().splitlines())
    assert n <= 200, f"README.md has {n} lines; the details belong in docs/"


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def prose(text: str) -> str:
    """The text without fenced blocks and inline code (links there are not links)."""
    kept, fence = [], False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            kept.append(re.sub(r"`[^`]*`", "", line))
    return "\n".join(kept)


def slug(heading: str) -> str:
    """A heading's anchor as Python-Markdown's ``toc`` makes it (MkDocs' default)."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"[`*]", "", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings (outside fenced blocks)."""
    found, fence = set(), False
    for line in page.read_text().splitlines():
        if line.strip().startswith("```"):
            fence = not fence
        elif not fence and (m := re.match(r"^#{1,6}\s+(.+?)\s*#*\s*$", line)):
            found.add(slug(m.group(1)))
    return found


def markdown_files() -> list[Path]:
    return [README] + sorted(DOCS.rglob("*.md"))


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    bad = []
    for target in LINK.findall(prose(path.read_text())):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("/"):
            continue                                       # http:, mailto:, absolute
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            bad.append(f"{target}: {dest} does not exist")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with the anchor #{anchor} in {dest.name}")
    assert not bad, f"{path.relative_to(ROOT)}:\n" + "\n".join(bad)


#: A wall time in prose that a user will hold their own against: "about 15 s", "8 min 19 s",
#: "about 11 minutes".
WALL_TIME = re.compile(r"\babout \d+(?:\.\d+)? ?(?:s|min|minutes)\b(?! of CPU)|\b\d+ min \d+ s\b")
#: The pages whose wall times say where they were measured and what a first run adds.
TIMED_PAGES = (README, DOCS / "getting-started.md", DOCS / "testing.md")


def paragraphs(text: str) -> list[str]:
    """The prose paragraphs of a Markdown text (fenced blocks and inline code left out), each
    on one line."""
    return [" ".join(p.split()) for p in re.split(r"\n\s*\n", prose(text)) if p.strip()]


@pytest.mark.parametrize("page", TIMED_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_wall_times_say_where_they_were_measured(page):
    """A paragraph that gives how long the set-up, the demo or the tests take names the
    machine (its vCPUs) and its load (nothing else running, or the load average), and what a
    first run adds (issue 45: "about 15 s on two cores" and "about 11 minutes" said neither)."""
    bad = [p[:100] for p in paragraphs(page.read_text()) if WALL_TIME.search(p) and not (
        "vCPU" in p and ("nothing else running" in p or "load average" in p)
        and "first run" in p)]
    assert not bad, f"{page.relative_to(ROOT)}: a wall time without its conditions:\n" + \
        "\n".join(bad)


def test_readme_links_into_the_docs_without_anchors():
    """GitHub and MkDocs make different anchors of the same heading: the README links pages."""
    links = [t for t in LINK.findall(prose(README.read_text())) if t.startswith("docs/")]
    assert links, "README.md links no page of docs/"
    assert all("#" not in t for t in links), links


# --- the site and the API reference -----------------------------------------------------------

def test_site_builds_with_warnings_as_errors(tmp_path):
    _require("mkdocs")
    _require("mkdocstrings_handlers.python")
    _require("material")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--clean",
                           "-f", str(ROOT / "mkdocs.yml"), "-d", str(tmp_path / "site")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-5000:]
    assert "WARNING" not in log, log[-5000:]
    site = tmp_path / "site"
    for page in ["index.html", "getting-started.html", "preparing-data.html",
                 "api/index.html", "api/geometry.html"]:
        assert (site / page).is_file(), page
    api = (site / "api" / "index.html").read_text()
    assert 'id="paretocal.calibrate"' in api and 'id="paretocal.resume_run"' in api


def public_names() -> list[str]:
    init = ast.parse((ROOT / "src" / "paretocal" / "__init__.py").read_text())
    for node in init.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__"
                                                 for t in node.targets):
            return [n for n in ast.literal_eval(node.value) if n != "__version__"]
    raise AssertionError("paretocal/__init__.py has no __all__")


def api_directives() -> list[str]:
    return [line.split(":::", 1)[1].strip() for page in sorted((DOCS / "api").glob("*.md"))
            for line in page.read_text().splitlines() if line.startswith(":::")]


def test_api_reference_lists_the_public_api_and_the_core():
    shown = set(api_directives())
    missing = [n for n in public_names() if f"paretocal.{n}" not in shown]
    assert not missing, f"docs/api/ does not document paretocal.{missing}"
    assert {f"paretocal.{m}" for m in CORE_MODULES} <= shown
    # The public names are documented by their public path, not the module that defines them
    # today (the command line, run folders and reports may be reorganised).
    private = [d for d in shown if re.match(r"paretocal\.(cli|rundir|report)\b", d)]
    assert not private, private


def _documented(obj) -> set[str] | None:
    from griffe import DocstringSectionKind as Kind

    if obj.docstring is None:
        return None
    kinds = {Kind.parameters, Kind.other_parameters} | ({Kind.attributes} if obj.is_class else set())
    return {name.strip().lstrip("*") for section in obj.docstring.parsed if section.kind in kinds
            for item in section.value for name in item.name.split(",")}


def _api_objects(package):
    """What the API pages show: the public names, and each core module's public functions and
    classes (its ``__all__`` when it has one), with their public methods."""
    from griffe import AliasResolutionError

    objects = [package[name].final_target for name in public_names()]
    for module_name in CORE_MODULES:
        module = package[module_name]
        for name, member in module.members.items():
            if name.startswith("_"):
                continue
            if member.is_alias:
                if module.exports is None or name not in module.exports:
                    continue
                try:
                    member = member.final_target
                except AliasResolutionError:      # a constant of a tuple assignment
                    continue
            if member.is_function or member.is_class:
                objects.append(member)
    for obj in list(objects):
        if obj.is_class:
            objects += [m for n, m in obj.members.items() if not n.startswith("_")
                        and not m.is_alias and m.is_function and "property" not in m.labels]
    return objects


def test_every_function_in_the_api_reference_documents_its_parameters():
    _require("griffe")
    import griffe

    spec = importlib.util.spec_from_file_location("griffe_lazy_exports",
                                                  DOCS / "griffe_lazy_exports.py")
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    package = griffe.load("paretocal", search_paths=[str(ROOT / "src")], docstring_parser="numpy",
                          extensions=griffe.load_extensions(ext.LazyExports))
    problems, seen = [], set()
    for obj in _api_objects(package):
        if obj.path in seen:
            continue
        seen.add(obj.path)
        params = [p.name for p in obj.parameters if p.name not in ("self", "cls")]
        documented = _documented(obj)
        if documented is None:
            problems.append(f"{obj.path}: no docstring")
        elif missing := [p for p in params if p not in documented]:
            problems.append(f"{obj.path}: parameters not documented: {', '.join(missing)}")
    assert len(seen) > 100
    assert not problems, "\n".join(problems)
