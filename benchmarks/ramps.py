"""Benchmark: machine time of the thesis ellipse with each speed ramp, and the look-ahead planner's speed.

    python benchmarks/ramps.py            # 25M periods for the planner speed
    python benchmarks/ramps.py --quick    # 2.5M periods

The ellipse is the thesis's test drawing (``shared/seeds/001``, Figure 5.1:
286 x 144 pixels, 8 steps per pixel), cut 1 Z pixel deep.  All three modes
share the same top speed (the thesis's 5 ms step delay = 5.78 mm/s on X/Y):
``constant`` runs at it everywhere (the thesis; it breaks the start-speed and
acceleration rules), ``linear40`` is the standalone controller's 40-step delay
ramp at both ends of every move (``shared/seeds/004``, section 3.5.2), and
``lookahead`` plans the whole job.  Each plan runs on the mock and its pin log
goes through the ramp checker.  The planner speed is the look-ahead on the
ellipse's periods repeated to 25M (2.5M quick), median of 3.
"""
from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cam  # noqa: E402
from cam.motion.ramps import ramp_periods  # noqa: E402
from cam.verify.ramps import check_ramps  # noqa: E402

MODES = ("constant", "linear40", "lookahead")


def ellipse_times() -> dict[str, tuple[float, bool, "np.ndarray"]]:
    """Machine time (s), checker verdict and step plan of the thesis ellipse per ramp mode."""
    d = cam.digitize(cam.load_image(ROOT / "samples" / "ellipse.png"))
    out = {}
    for mode in MODES:
        settings = cam.MachineSettings().replace(ramp=mode)
        plan = cam.plan_steps(cam.plan(d, depth=1, settings=settings))
        report = check_ramps(cam.run(plan).pin_log(), settings, pause_writes=plan.pause_writes)
        out[mode] = (plan.estimated_time_s, report.ok, plan)
    return out


def planner_rate(plan, n_periods: int, repeats: int = 3) -> tuple[float, int]:
    """Median seconds to plan ``n_periods`` look-ahead periods (the plan's periods repeated)."""
    high = plan.data[1::2]  # each period's rising-edge byte: its directions and clocks
    per = np.diff(plan.t_ns[0::2])
    reps = max(1, n_periods // len(per))
    big = (np.tile(high, reps), np.tile(per, reps))
    settings = cam.MachineSettings()
    ramp_periods(high, per, settings)  # compile
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ramp_periods(*big, settings)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), len(big[1])


def bench_row(quick: bool) -> dict:
    """The benchmark table row (format of ``benchmarks/run.py``): look-ahead vs the 40-step ramp."""
    res = ellipse_times()
    t = {m: res[m][0] for m in MODES}
    ok = {m: res[m][1] for m in MODES}
    plan_s, n = planner_rate(res["constant"][2], 2_500_000 if quick else 25_000_000)
    rate = n / plan_s
    saved = 1 - t["lookahead"] / t["linear40"]
    verdict = ", ".join(f"{m} {'passes' if ok[m] else 'fails'}" for m in MODES)
    text = (f"constant {t['constant']:.1f} s, 40-step ramp {t['linear40']:.1f} s, look-ahead {t['lookahead']:.1f} s "
            f"(saves {100 * saved:.0f}% vs the 40-step ramp, +{100 * (t['lookahead'] / t['constant'] - 1):.0f}% vs "
            f"constant); ramp checker: {verdict}; look-ahead planner {n / 1e6:.1f}M periods in {plan_s:.2f} s")
    met = t["lookahead"] < t["linear40"] and ok["lookahead"] and rate >= 5e6
    return dict(name="ramps: thesis ellipse machine time (Fig. 5.1, 8 steps/px)", cam=t["lookahead"],
                ref=t["linear40"], ratio=text, target="look-ahead < 40-step ramp and passes the checker; >= 5M periods/s",
                met=met, note="machine times, not wall times: cam = look-ahead, reference = 40-step ramp")


if __name__ == "__main__":
    row = bench_row("--quick" in sys.argv[1:])
    print(f"| {row['name']} | {row['cam']:.1f} | {row['ref']:.1f} | {row['ratio']} ({row['note']}) | {row['target']} | "
          f"{'yes' if row['met'] else '**no**'} |")
