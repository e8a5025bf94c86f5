"""cam: drawings and drill files to exact, safe step/dir motion for small 3-axis stepper machines.

One data model flows one way::

    load_image(path)   -> Drawing     classified pixels + rule warnings
    digitize(drawing)  -> Digitized   ordered pixel paths (the digitized matrix)
    plan(digitized)    -> Job         moves in machine steps, retracts marked (every planner returns one)
    plan_steps(path)   -> StepPlan    timed port writes
    run(job, port)     -> RunResult   writes sent to a port ("mock" by default)

>>> import numpy as np, cam
>>> img = np.full((6, 8), 255, np.uint8); img[2, 2:6] = 0
>>> job = cam.plan(cam.digitize(cam.load_image(img)), depth=3)
>>> result = cam.run(job)                       # the logging mock port
>>> motion = cam.decode_pin_log(result.pin_log())
>>> cam.carve(motion, (6, 8))[2].tolist()       # Z steps cut along row 2
[0, 0, 3, 3, 3, 3, 0, 0]
"""
from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# public name -> module that defines it; loaded on first use, so ``import cam`` stays cheap
# (no numba, OpenCV or web stack until a name that needs them is used)
_LAZY = {
    "load_image": "cam.digitize.drawing", "Drawing": "cam.digitize.drawing",
    "digitize": "cam.digitize",
    "Digitized": "cam.digitize.digitized", "load_digitized": "cam.digitize.digitized",
    "save_digitized": "cam.digitize.digitized",
    "Profile": "cam.digitize.profile", "load_profile": "cam.digitize.profile",
    "profile_from_expr": "cam.digitize.profile",
    "plan": "cam.job.drawing_stream", "goto": "cam.job.moves", "jog": "cam.job.moves", "Job": "cam.job.model",
    "PixelFrame": "cam.job.model",
    "plan_drill": "cam.job.drill", "DrillPlan": "cam.job.drill", "drill_order": "cam.job.drill_order",
    "plan_hpgl": "cam.job.hpgl",
    "load_svg": "cam.formats.svg", "parse_svg": "cam.formats.svg", "SvgDrawing": "cam.formats.svg",
    "plan_svg": "cam.job.svg",
    "load_dxf": "cam.formats.dxf", "parse_dxf": "cam.formats.dxf", "DxfDrawing": "cam.formats.dxf",
    "trace": "cam.digitize.sketch", "TracedDrawing": "cam.digitize.sketch", "load_sketch": "cam.digitize.sketch",
    "load_excellon": "cam.formats.excellon", "parse_excellon": "cam.formats.excellon",
    "HoleList": "cam.formats.excellon",
    "load_hpgl": "cam.formats.hpgl", "parse_hpgl": "cam.formats.hpgl", "scan_hpgl": "cam.formats.hpgl",
    "iter_hpgl": "cam.formats.hpgl", "HpglDrawing": "cam.formats.hpgl", "HpglScan": "cam.formats.hpgl",
    "to_gcode": "cam.kinds.gcode_export", "save_gcode": "cam.kinds.gcode_export",
    "plan_steps": "cam.motion.steps", "StepPlan": "cam.motion.steps",
    "run": "cam.drive.session", "MachineSession": "cam.drive.session",
    "Controller": "cam.drive.runner", "RunResult": "cam.drive.runner",
    "simulate_surface": "cam.drive.runner",
    "open_port": "cam.drive.machines", "MockPort": "cam.drive.ports",
    "decode_pin_log": "cam.verify.pinlog", "read_pin_log": "cam.verify.pinlog",
    "write_pin_log": "cam.verify.pinlog", "PinLog": "cam.verify.pinlog", "Motion": "cam.verify.pinlog",
    "carve": "cam.verify.pinlog",
    "image_report": "cam.render.report", "job_report": "cam.render.report",
    "MachineSettings": "cam.settings", "load_settings": "cam.settings",
    "CamError": "cam.errors", "DrawingError": "cam.errors", "ParseError": "cam.errors",
    "PlanError": "cam.errors", "PortError": "cam.errors", "SettingsError": "cam.errors",
    "TravelError": "cam.errors",
    "job_kind": "cam.kinds", "sniff_kind": "cam.kinds",
    "prepare_job": "cam.kinds.jobs", "resume_job": "cam.kinds.jobs", "JobOptions": "cam.kinds.jobs",
    "PreparedJob": "cam.kinds.jobs", "Journal": "cam.job.resume", "read_journal": "cam.drive.journal",
    "HeightMap": "cam.job.heightmap_level", "load_height_map": "cam.job.heightmap_level",
    "save_height_map": "cam.job.heightmap_level",
}

__all__ = list(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'cam' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


class _CamModule(types.ModuleType):
    """``cam.digitize`` is the function, though ``cam/digitize/`` is also a package.

    Importing a submodule binds it on its parent package; this keeps the
    package ``cam.digitize`` (always in ``sys.modules``) from replacing the
    public function of the same name.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "digitize" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _CamModule


if TYPE_CHECKING:  # pragma: no cover - for type checkers and editors only
    from .digitize import digitize
    from .digitize.digitized import Digitized, load_digitized, save_digitized
    from .digitize.drawing import Drawing, load_image
    from .digitize.profile import Profile, load_profile, profile_from_expr
    from .drive.machines import open_port
    from .drive.ports import MockPort
    from .drive.runner import Controller, RunResult, simulate_surface
    from .drive.session import MachineSession, run
    from .motion.steps import StepPlan, plan_steps
    from .kinds import job_kind, sniff_kind
    from .errors import CamError, DrawingError, ParseError, PlanError, PortError, SettingsError, TravelError
    from .formats.excellon import HoleList, load_excellon, parse_excellon
    from .kinds.gcode_export import save_gcode, to_gcode
    from .formats.hpgl import HpglDrawing, HpglScan, iter_hpgl, load_hpgl, parse_hpgl, scan_hpgl
    from .digitize.sketch import TracedDrawing, load_sketch, trace
    from .formats.svg import SvgDrawing, load_svg, parse_svg
    from .formats.dxf import DxfDrawing, load_dxf, parse_dxf
    from .job.hpgl import plan_hpgl
    from .job.svg import plan_svg
    from .job.drill import DrillPlan, plan_drill
    from .job.drill_order import drill_order
    from .job.drawing_stream import plan
    from .job.model import Job, PixelFrame
    from .kinds.jobs import JobOptions, PreparedJob, prepare_job, resume_job
    from .job.resume import Journal
    from .job.heightmap_level import HeightMap, load_height_map, save_height_map
    from .drive.journal import read_journal
    from .job.moves import goto, jog
    from .render.report import image_report, job_report
    from .settings import MachineSettings, load_settings
    from .verify.pinlog import Motion, PinLog, carve, decode_pin_log, read_pin_log, write_pin_log
