"""A 100,000-line G-code file of short moves, as a CAM post writes a 3D finish (``G1 X30.123 Y-29.877 F600`` then
``X30.130 Y-29.870`` lines), read and planned by `cam` against LinuxCNC's own interpreter on the same file.

    python benchmarks/gcode_lines.py                 # 100,000 lines, 3 repeats
    python benchmarks/gcode_lines.py --quick         # 10,000 lines, 1 repeat
    python benchmarks/gcode_lines.py --rev 66d77b4   # also the rows with the G-code reader of that commit

The file (:func:`write_short_moves`): a random walk of steps under 0.05 mm in X and Y within the default mock's
travel (X 1..280 mm, Y -280..-1 mm), the numbers with three decimals, after a short preamble; about 1.8 MB.

Rows, each a whole process and the median wall time of the repeats:

* ``read``: ``cam.formats.gcode.open_gcode`` and every move of the file (the interpreter alone);
* ``prepare_job``: ``cam.prepare_job`` from the file's path to the step plan (the interpreter, the planner, the
  chunks);
* ``cam drill --yes`` on the mock (its state in the run's temporary folder): the whole command, simulated, and the
  ``planning_s`` of its report.

Reference, measured in the same run: ``rs274 -g FILE`` (LinuxCNC's interpreter, canonical calls to stdout, sent to
``/dev/null``); "ratio" is cam's median over rs274's, and "us/line" the median over the file's lines.  Without
``/usr/bin/rs274`` (or ``rs274`` on the PATH) the reference is left out, with a note.  With ``--rev`` each row is
run again with a copy of this tree's `cam` package (its built kernels too) whose G-code reader (:data:`READER`)
is that commit's, first on ``PYTHONPATH``: the rows before and after a change to the reader.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
READER = ("gcode.py", "ngc.py", "_gcode_block.py", "_gcode_cycles.py", "_gcode_data.py", "_gcode_flow.py",
          "_gcode_lines.py", "_gcode_motion.py", "_gcode_state.py")
"""The G-code reader's modules in ``cam/formats``."""

READ = r"""
import sys
from cam.formats.gcode import open_gcode
print(sum(len(b.moves) for b in open_gcode(sys.argv[1]).move_batches()))
"""
PREPARE = r"""
import sys
import cam
job = cam.prepare_job(sys.argv[1])
print(job.summary)
"""


def write_short_moves(path: Path, n: int = 100_000, seed: int = 3) -> int:
    """``n`` lines: a preamble, then ``X.. Y..`` lines of a random walk (steps under 0.05 mm) within X 1..280 mm,
    Y -280..-1 mm; returns the file's size in bytes."""
    rng = random.Random(seed)
    lines = ["G21 G90 G17 G94", "G0 Z5", "G0 X30 Y-30", "G1 Z-1 F300", "G1 X30.123 Y-29.877 F600"]
    x, y = 30.123, -29.877
    while len(lines) < n - 2:
        x = min(280.0, max(1.0, x + rng.uniform(-0.05, 0.05)))
        y = min(-1.0, max(-280.0, y + rng.uniform(-0.05, 0.05)))
        lines.append(f"X{x:.3f} Y{y:.3f}")
    lines += ["G0 Z5", "M2"]
    path.write_text("\n".join(lines) + "\n")
    return path.stat().st_size


def rs274() -> str | None:
    """LinuxCNC's ``rs274`` (linuxcnc-uspace), or None."""
    return "/usr/bin/rs274" if Path("/usr/bin/rs274").is_file() else shutil.which("rs274")


def timed(cmd: list[str], cwd: Path, env: dict) -> tuple[float, str]:
    """One run of ``cmd``: its wall time and its standard output (an error when it fails)."""
    t0 = time.perf_counter()
    out = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} failed ({out.returncode}): {out.stderr.strip()[-500:]}")
    return wall, out.stdout


def cam_rows(label: str, cam_root: Path, ngc: Path, tmp: Path, repeats: int) -> list[dict]:
    """The rows of one `cam` (the package under ``cam_root``): read, prepare_job, cam drill."""
    env = dict(os.environ, PYTHONPATH=str(cam_root), XDG_STATE_HOME=str(tmp / f"state-{label}"))
    rows = []
    for what, code in (("read (open_gcode, all moves)", READ), ("prepare_job (file to step plan)", PREPARE)):
        walls = [timed([sys.executable, "-c", code, str(ngc)], tmp, env)[0] for _ in range(repeats)]
        rows.append({"cam": label, "what": what, "wall_s": statistics.median(walls), "note": ""})
    walls, planning = [], []
    for k in range(repeats):
        report = tmp / f"report-{label}-{k}.json"
        walls.append(timed([sys.executable, "-m", "cam", "drill", str(ngc), "--yes", "--no-progress", "--report",
                            str(report)], tmp, env)[0])
        planning.append(float(json.loads(report.read_text())["planning_s"]))
    rows.append({"cam": label, "what": "cam drill --yes (mock, simulated)", "wall_s": statistics.median(walls),
                 "note": f"planning_s {statistics.median(planning):.2f}"})
    return rows


def bench_rows(quick: bool, repeats: int, rev: str | None) -> tuple[list[dict], float | None, int]:
    """The rows (see the module docstring), rs274's median (None without it) and the file's lines."""
    n = 10_000 if quick else 100_000
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        ngc = tmp / "short.ngc"
        write_short_moves(ngc, n)
        ref = rs274()
        ref_s = None
        if ref is not None:
            ref_s = statistics.median(timed([ref, "-g", str(ngc)], tmp, dict(os.environ))[0] for _ in range(repeats))
        rows = cam_rows("this tree", ROOT, ngc, tmp, repeats)
        if rev:
            old = tmp / "rev"
            shutil.copytree(ROOT / "cam", old / "cam", ignore=shutil.ignore_patterns("__pycache__"))
            for name in READER:
                text = subprocess.run(["git", "show", f"{rev}:cam/formats/{name}"], cwd=ROOT, capture_output=True,
                                      check=True).stdout
                (old / "cam" / "formats" / name).write_bytes(text)
            rows += cam_rows(f"reader of {rev}", old, ngc, tmp, repeats)
    return rows, ref_s, n


def table(rows: list[dict], ref_s: float | None, n: int) -> str:
    ref = "no rs274 (skipped)" if ref_s is None else f"{ref_s:.2f}"
    out = [f"{n:,} short-move lines; reference: rs274 -g FILE > /dev/null, median {ref} s "
           + ("" if ref_s is None else f"({ref_s / n * 1e6:.1f} us/line)"), "",
           "| cam | what | cam wall s (median) | us/line | rs274 -g s (median) | ratio | note |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = "" if ref_s is None else f"{r['wall_s'] / ref_s:.1f}x"
        out.append(f"| {r['cam']} | {r['what']} | {r['wall_s']:.2f} | {r['wall_s'] / n * 1e6:.1f} | {ref} | {ratio} | "
                   f"{r['note']} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10,000 lines, 1 repeat")
    ap.add_argument("--repeats", type=int, default=None, help="runs of each command (default 3; 1 with --quick)")
    ap.add_argument("--rev", default=None, help="also run the rows with the cam package of this git commit")
    args = ap.parse_args()
    repeats = args.repeats or (1 if args.quick else 3)
    print(table(*bench_rows(args.quick, repeats, args.rev)))


if __name__ == "__main__":
    main()
