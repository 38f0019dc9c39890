"""The examples in the primitives' docstrings run and print what they show (numpydoc
``Examples`` sections: the transforms, the correction, the pose error, the projection)."""

import doctest
import importlib

import pytest

#: Modules whose docstrings carry examples.
EXAMPLES = ["paretocal.geometry", "paretocal.camera"]


@pytest.mark.parametrize("name", EXAMPLES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE, report=False)
    assert result.attempted > 0, f"{name}: no examples found"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"
