"""The package's layers only look down: inputs at the bottom, the numerical core above them, the
pipeline's stages, then results, reports and the command line (docs/architecture.md)."""

import ast
from pathlib import Path

import paretocal

#: Rank of each top-level module or subpackage; a module may import only from ranks <= its own.
RANKS = {
    "errors": 0,
    "geometry": 1, "camera": 1,
    "io": 2,
    "config": 3,
    "lidar": 4,
    "features": 5, "egomotion": 5,
    "objective": 6, "testing": 6,
    "search": 7, "quality": 7, "decide": 7,
    "inputs": 8, "stage": 8, "crosscheck": 8, "verdict": 8, "result": 8, "wide": 8, "board": 8,
    "pipeline": 9, "check": 9, "depth": 9, "extract": 9,
    "report": 10,
    "apps": 11, "rundir": 11,
    "cli": 12, "__init__": 12,
    "__main__": 13,
}

ROOT = Path(paretocal.__file__).parent


def _unit(path: Path) -> str:
    rel = path.relative_to(ROOT).parts
    return rel[0] if len(rel) > 1 else rel[0][:-3]


def _imports(path: Path) -> set[str]:
    """The top-level paretocal units a module imports (at any depth in the file)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    pkg = path.relative_to(ROOT).parts[:-1]          # the module's package inside paretocal
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:                           # relative: resolve against the package
                base = list(pkg[: len(pkg) - (node.level - 1)])
                parts = base + (node.module.split(".") if node.module else [])
                if not parts:                        # "from . import x": the names are units
                    out.update(a.name for a in node.names)
                else:
                    out.add(parts[0])
            elif node.module and node.module.split(".")[0] == "paretocal":
                parts = node.module.split(".")
                out.add(parts[1] if len(parts) > 1 else "__init__")
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] == "paretocal" and len(parts) > 1:
                    out.add(parts[1])
    return out


def test_every_unit_has_a_rank():
    units = {_unit(p) for p in ROOT.rglob("*.py")}
    assert units <= set(RANKS), sorted(units - set(RANKS))


def test_layers_only_look_down():
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        me = _unit(path)
        for target in _imports(path):
            if target == "__version__":
                continue
            if target in RANKS and RANKS[target] > RANKS[me]:
                upward.append(f"{path.relative_to(ROOT)} imports {target}")
    assert not upward, "\n".join(upward)


def test_lint_and_complexity():
    """ruff with the project's rules (pyproject.toml: pyflakes, pycodestyle, bugbear, a
    cyclomatic complexity of at most 20 and at most 10 arguments per function) finds nothing."""
    import importlib.util
    import subprocess
    import sys

    import pytest

    if importlib.util.find_spec("ruff") is None:
        pytest.skip("ruff is not installed (it comes with the test extras: pip install -e .[test])")
    top = ROOT.parent.parent
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", "src", "tests", "benchmarks"],
                          cwd=top, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_typed_modules_pass_the_type_checker():
    """mypy (its defaults, third-party packages without stubs taken as untyped) finds nothing
    in the package."""
    import importlib.util
    import subprocess
    import sys

    import pytest

    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (it comes with the test extras: pip install -e .[test])")
    proc = subprocess.run([sys.executable, "-m", "mypy", "--ignore-missing-imports",
                           "--follow-imports=silent", "--no-incremental",
                           str(ROOT)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_no_private_name_crosses_a_module():
    """A name with a leading underscore is the module's own: no other module imports it."""
    crossing = []
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (
                    node.level or (node.module or "").split(".")[0] == "paretocal"):
                crossing += [f"{path.relative_to(ROOT)}:{node.lineno} imports {a.name}"
                             for a in node.names
                             if a.name.startswith("_") and not a.name.startswith("__")]
    assert not crossing, "\n".join(crossing)


def test_the_architecture_page_states_these_ranks():
    """docs/architecture.md's layer table says what this test enforces."""
    import re

    page = Path(__file__).parents[1] / "docs" / "architecture.md"
    stated = {}
    for line in page.read_text(encoding="utf-8").splitlines():
        m = re.match(r"\|\s*(\d+)\s*\|([^|]*)\|", line)
        if m:
            stated.update({name: int(m.group(1)) for name in re.findall(r"`(\w+)`", m.group(2))})
    assert stated == RANKS
