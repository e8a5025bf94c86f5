"""Every docstring example in the library runs.

One test per docstring that has examples (``>>>``), found the way :func:`doctest.testmod` finds them (objects
defined in the module itself); a docstring without examples is not collected, so a test that checked nothing
cannot pass.  Each test asserts that its examples ran (``attempted > 0``) and none failed.  A module that fails
to import is one failing test, never a silently smaller list.
"""
import doctest
import importlib
import pkgutil

import pytest

import cam

MODULES = sorted(
    m.name for m in pkgutil.walk_packages(cam.__path__, "cam.")
    if not m.name.endswith("__main__") and "emulator" not in m.name
)


def _doctests() -> list:
    """(docstring name, DocTest) for every docstring with examples; (module name, import error) for a module
    that does not import."""
    finder = doctest.DocTestFinder(exclude_empty=True)
    found = []
    for name in MODULES:
        try:
            module = importlib.import_module(name)
        except Exception as exc:  # reported by the test, not at collection
            found.append(pytest.param(None, exc, id=f"{name} (import)"))
            continue
        for test in finder.find(module):
            if test.examples:
                found.append(pytest.param(test, None, id=test.name))
    return found


DOCTESTS = _doctests()


@pytest.mark.parametrize("test, import_error", DOCTESTS)
def test_docstring_examples(test, import_error):
    assert import_error is None, f"the module does not import: {import_error!r}"
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    result = runner.run(test, out=report.append)
    assert result.attempted > 0, f"{test.name}: no example ran"
    assert result.failed == 0, "".join(report)


def test_the_library_has_docstring_examples():
    """The list above is not empty by accident (a walk of the package that found nothing)."""
    assert len(MODULES) > 50 and len(DOCTESTS) >= 30
