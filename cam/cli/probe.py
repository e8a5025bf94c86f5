"""``cam probe z``, ``cam probe tool`` and ``cam probe grid``: find the work's surface with a touch probe (issue #46
point 1).

A thin adapter over the machine session's probing (:meth:`cam.drive.session.MachineSession.probe_z`,
``probe_grid``; :mod:`cam.drive.probing`): the port's back end probes (the mock on its simulated
``[mock] probe_surface``, a parallel port's ``[inputs] probe``, grbl's ``G38.2``); the MAXIMUS board and ``cmd:``
refuse in one line.  ``cam probe z`` then sets the active work offset's Z zero on the surface (a ``--plate``'s
thickness below the contact) in the state file (and grbl's own offset), keeping the contact there; after a tool
change ``cam probe tool`` probes the new tool at that contact's X, Y and shifts the work Z by the difference of the
contacts (:meth:`~cam.drive.session.MachineSession.probe_tool`); ``cam probe grid`` writes the height map.
Ctrl-C stops (the tool lifted); a probe that touches nothing is one line, exit code 2.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


from ..drive.machines import backend_of
from ..drive.probe_grid import grid_plan
from ..drive.probing import job_area_mm
from ..drive.session import MachineSession
from ..drive.state import steps_to_mm
from ..errors import CamError
from ..kinds.jobs import JobOptions, prepare_job
from ..settings import MachineSettings
from .common import port_settings
from .machine_state import hold_machine, run_activity
from .parser import EXIT_BAD_INPUT, EXIT_INTERRUPTED

__all__ = ["cmd_probe"]


def cmd_probe(args: argparse.Namespace) -> int:
    """``cam probe WHAT``: z, tool or grid."""
    settings = port_settings(args, args.port)
    backend_of(args.port).require(args.port, "probes", f"cam probe {args.probe_what}")  # before anything opens
    if args.probe_what == "z":
        return _probe_z(args, settings)
    if args.probe_what == "tool":
        return _probe_tool(args, settings)
    return _probe_grid(args, settings)


def _ended(info: dict) -> int:
    """The exit code and line of a probing activity that did not finish: Ctrl-C and the e-stop 130, else 2."""
    status = info.get("status")
    said = "; ".join(info.get("messages") or [str(status)])
    if status in ("stopped", "emergency-stopped"):
        print(f"cam: probing {status}: {said}", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"cam: error: {said}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _probe_z(args: argparse.Namespace, settings: MachineSettings) -> int:
    depth = int(round(args.depth / settings.mm_per_step_z))
    if depth < 1:
        raise CamError(f"--depth {args.depth:g} is less than one Z step ({settings.mm_per_step_z:g} mm)")
    with hold_machine(args, settings, "cam probe z") as hold:
        session, info = run_activity(args, settings, hold, lambda s: s.probe_work_z(args.plate, args.feed, depth, wait=False))
        if info.get("status") != "finished":
            return _ended(info)
        result = (session.last_probe or [None])[0]
        zero_z = int(hold.state.work_zero_steps()[2])
        name = hold.state.active_offset
        end = hold.state.position_steps
    per = settings.mm_per_step_z
    plate = f", {args.plate:g} mm plate" if args.plate else ""
    print(f"{name} Z zero set on the surface at height {-zero_z * per:.4g} mm (machine Z {zero_z} steps; the contact "
          f"at {result.contact_steps[2]} steps{plate}); the tool is back {(zero_z - end[2]) * per:.4g} mm above it")
    return 0


def _probe_tool(args: argparse.Namespace, settings: MachineSettings) -> int:
    with hold_machine(args, settings, "cam probe tool") as hold:
        before = int(hold.state.work_zero_steps()[2])
        session, info = run_activity(args, settings, hold, lambda s: s.probe_tool(args.plate, args.feed,
                                                                          clearance_mm=args.clearance, wait=False))
        if info.get("status") != "finished":
            return _ended(info)
        result = (session.last_probe or [None])[0]
        zero_z = int(hold.state.work_zero_steps()[2])
        name = hold.state.active_offset
    per = settings.mm_per_step_z
    print(f"{name} Z zero moved {(before - zero_z) * per:+.4g} mm up for the new tool (machine Z {before} -> {zero_z} "
          f"steps; its contact at {result.contact_steps[2]} steps): its tip is at the same work Z as the old one's")
    return 0


def _area_mm(args: argparse.Namespace, settings: MachineSettings, state: Any) -> tuple[float, float, float, float]:
    """The area to probe in machine mm, before the margin: --area (work or machine frame) or --over's job extent."""
    if args.area is not None:
        x0, y0, x1, y1 = args.area
        if args.machine_coords:
            return x0, y0, x1, y1
        zx, zy, _ = steps_to_mm(state.work_zero_steps(), settings)
        return x0 + zx, y0 + zy, x1 + zx, y1 + zy
    if args.machine_coords:
        raise CamError("--machine-coords applies to --area only (--over places the job at the work zero)")
    if not Path(args.over).is_file():
        raise CamError(f"--over {args.over}: no such file")
    job = prepare_job(args.over, JobOptions(), settings, name=args.over, machine_state=state)
    return job_area_mm(job, state, settings, args.origin)


def _probe_grid(args: argparse.Namespace, settings: MachineSettings) -> int:
    if args.origin and args.over is None:
        raise CamError("--origin applies to --over only")
    per_x, per_y, per_z = settings.mm_per_step_axes
    with hold_machine(args, settings, "cam probe grid") as hold:
        area = _area_mm(args, settings, hold.state)
        plan = grid_plan(area, args.spacing, settings, margin_mm=args.margin)  # PlanError before anything opens
        machine = str(Path(args.machine).resolve()) if getattr(args, "machine", None) else None
        zero_z = int(hold.state.work_zero_steps()[2])

        def start(session: MachineSession) -> None:
            session.probe_map(area, args.out, spacing_mm=args.spacing, margin_mm=args.margin,
                              safe_height_mm=args.safe_height, depth_mm=args.depth, feed_mm_min=args.feed,
                              machine=machine, wait=False)  # checked: the travel, the feed
            xs, ys = plan.xs_steps, plan.ys_steps
            depth_mm = args.depth if args.depth is not None else args.safe_height + 2.0
            print(f"probing {len(plan.order)} points ({len(xs)} x {len(ys)}, {args.spacing:g} mm apart) over X "
                  f"{xs[0] * per_x:g}..{xs[-1] * per_x:g}, Y {ys[0] * per_y:g}..{ys[-1] * per_y:g} mm (machine), from "
                  f"{args.safe_height:g} mm above the work Z zero first (the others from just above the contacts before "
                  f"them), never more than {max(1, round(depth_mm / per_z)) * per_z:g} mm below it", file=sys.stderr, flush=True)

        session, info = run_activity(args, settings, hold, start)
        if info.get("status") != "finished":
            return _ended(info)
    heights = session.last_map.height_mm
    print(f"height map of {len(plan.order)} points written to {args.out}: heights {heights.min():.4g}.."
          f"{heights.max():.4g} mm (machine frame; the work Z zero at {-zero_z * per_z:.4g} mm)")
    return 0
