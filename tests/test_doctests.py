"""Every docstring example in the library runs."""
import doctest
import importlib
import pkgutil

import pytest

import cam

MODULES = sorted(
    m.name for m in pkgutil.walk_packages(cam.__path__, "cam.")
    if not m.name.endswith("__main__") and "emulator" not in m.name
)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
