"""The fuzz harness's quick mode and its regressions: no input finds a traceback, a hang or a crash
(see tests/fuzz; ``python -m tests.fuzz --count 100000`` is the long mode)."""
from __future__ import annotations

import pytest

from fuzz import campaign, regression_inputs, run_one, seeds, table

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_quick_fuzz_finds_no_failure'}


def test_quick_fuzz_finds_no_failure():
    outcomes = campaign(400, seed=20261123)
    failures = [o for o in outcomes if o.status == "failure"]
    assert not failures, table(outcomes) + "\n" + "\n".join(f"{o.kind}: {o.detail}" for o in failures)
    assert {o.kind for o in outcomes} == set(seeds())  # every kind was tried
    assert sum(o.status == "clean" for o in outcomes) > 100  # the mutations do break things


def test_every_seed_is_accepted(tmp_path):
    """The harness is only as good as its seeds: unmutated, each is a valid input of its kind."""
    for kind, items in seeds().items():
        for name, data in items:
            o = run_one(kind, name, data, tmp_path)
            # a route's body is valid, but its request may be refused in the state the machine is in (an answer
            # with no prompt waiting, a pause with nothing running): a clean refusal, never a failure
            assert o.status == "accepted" or (kind == "web" and o.status == "clean"), (kind, name, o.detail)


@pytest.mark.parametrize("kind,path", regression_inputs(), ids=lambda v: getattr(v, "name", v))
def test_earlier_failures_are_clean_now(kind, path, tmp_path):
    o = run_one(kind, path.name, path.read_bytes(), tmp_path)
    assert o.status in ("clean", "accepted"), o.detail
