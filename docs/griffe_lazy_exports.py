"""A griffe extension for the API reference (mkdocstrings): two things static analysis misses.

* ``paretocal/__init__.py`` imports nothing at start-up; it maps each public name to the module
  that defines it (``_LAZY``) and imports it on first use (PEP 562). This extension reads that
  mapping and adds each name to the package as an alias of its definition, so
  ``::: paretocal.calibrate`` documents it wherever it is defined.
* The docstrings cross-reference with Sphinx roles (``:func:`name```); they are shown as code
  (the name's last component for ``~name``), as Sphinx would show them without the link.
"""

from __future__ import annotations

import ast
import re

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|mod|data|obj|exc|const)?:"
                  r"`(~?)([^`<]+?)(?:\s*<([^`>]+)>)?`")


def _role_as_code(match: re.Match) -> str:
    tilde, text, target = match.groups()
    if target is not None:                       # :func:`title <target>`
        return f"`{text.strip()}`"
    return f"`{text.rsplit('.', 1)[-1] if tilde else text}`"


class LazyExports(griffe.Extension):
    """Add ``paretocal.<name>`` for every entry of ``paretocal._LAZY``; show roles as code."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        if pkg.path != "paretocal" or "_LAZY" not in pkg.members:
            return
        mapping = ast.literal_eval(str(pkg.members["_LAZY"].value))
        for name, module in mapping.items():
            if name not in pkg.members:
                pkg.set_member(name, griffe.Alias(name, f"paretocal.{module}.{name}", parent=pkg))

    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None and ":`" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(_role_as_code, obj.docstring.value)
