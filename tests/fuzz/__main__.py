"""``python -m tests.fuzz --count N``: the fuzz campaign, a table per input kind (see :mod:`tests.fuzz`)."""
from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

from . import TARGETS, campaign, table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="inputs to try (default 1000)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    ap.add_argument("--kinds", help=f"comma-separated kinds (default all: {','.join(TARGETS)})")
    ap.add_argument("--save", default="fuzz-failures", help="folder for failing inputs (default fuzz-failures/)")
    ap.add_argument("--memory-gb", type=float, default=4.0, help="address-space limit (default 4 GiB): an input "
                                                                   "that needs more is a failure, not a swap storm")
    args = ap.parse_args(argv)
    limit = int(args.memory_gb * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    t0 = time.monotonic()

    def report(i, outcome):
        if outcome.status == "failure":
            print(f"[{i}] {outcome.kind}: {outcome.detail}", file=sys.stderr, flush=True)
        elif (i + 1) % 500 == 0:
            print(f"... {i + 1} inputs, {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)

    kinds = args.kinds.split(",") if args.kinds else None
    outcomes = campaign(args.count, args.seed, kinds, Path(args.save), report)
    print(f"fuzz: {args.count} inputs, seed {args.seed}, {time.monotonic() - t0:.0f} s")
    print(table(outcomes))
    return 1 if any(o.status == "failure" for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
