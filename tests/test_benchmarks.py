"""The benchmark script runs on tiny inputs (no timing is asserted here)."""
import subprocess
import sys

import pytest

from conftest import ROOT


@pytest.mark.slow
def test_quick_benchmarks_print_the_table():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick"], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [line for line in proc.stdout.splitlines() if line.startswith("| ") and "---" not in line]
    header, body = rows[0], rows[1:]
    assert "reference" in header and "target" in header
    names = " ".join(r.split("|")[1] for r in body)
    for workload in ("2D trace", "3D peel", "planning", "relief", "memory", "drill tour", "real-time", "ramps",
                     "2D RGB array -> digitized", "3D RGB PNG file -> digitized", "TSPLIB d198"):
        assert workload in names, workload
    assert len(body) == 14
