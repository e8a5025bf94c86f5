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


def test_probe_benchmark_prints_its_rows_on_a_tiny_board():
    """benchmarks/bench_probe.py --quick: a 30 x 20 mm board (12 points) and a 20 x 10 mm drawing, a few seconds."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_probe.py"), "--quick"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [line for line in proc.stdout.splitlines() if line.startswith("| ") and "---" not in line]
    header, body = rows[0], rows[1:]
    assert "cam / reference" in header and len(body) == 6
    assert "vs bCNC" in body[0] and "vs OpenCNCPilot" in body[1]
    assert all("| 12 / 12 |" in r for r in body[:2])  # the same points each way
    at_cuts = [float(v) for v in body[2].split("|")[-2:-1]]  # levelled / not levelled at the cut points
    assert at_cuts[0] < 1.0, body[2]
