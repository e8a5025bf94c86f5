"""cam: drawings and drill files to exact, safe step/dir motion for small 3-axis stepper machines.

One data model flows one way::

    load_image(path)   -> Drawing     classified pixels + rule warnings
    digitize(drawing)  -> Digitized   ordered pixel paths (the digitized matrix)
    plan(digitized)    -> Toolpath    ordered 3D points in pixels, retracts marked
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

from .digitize import digitize
from .digitized import Digitized, load_digitized, save_digitized
from .drawing import Drawing, load_image
from .drive import (
    Controller,
    MockPort,
    Motion,
    PinLog,
    RunResult,
    StepPlan,
    carve,
    decode_pin_log,
    open_port,
    plan_steps,
    read_pin_log,
    run,
    simulate_surface,
    write_pin_log,
)
from .drilljob import DrillPlan, plan_drill
from .drilltour import drill_order
from .excellon import HoleList, load_excellon, parse_excellon
from .gcode import save_gcode, to_gcode
from .hpgl import HpglDrawing, HpglScan, iter_hpgl, load_hpgl, parse_hpgl, plan_hpgl, scan_hpgl
from .errors import CamError, DrawingError, ParseError, PlanError, PortError, SettingsError, TravelError
from .profile import Profile, load_profile, profile_from_expr
from .report import image_report, job_report
from .settings import MachineSettings, load_settings
from .toolpath import Toolpath, goto, plan

__version__ = "0.1.0"

__all__ = [
    "load_image", "Drawing",
    "digitize", "Digitized", "load_digitized", "save_digitized",
    "plan", "goto", "Toolpath",
    "plan_steps", "StepPlan",
    "run", "Controller", "RunResult", "open_port", "MockPort",
    "simulate_surface", "to_gcode", "save_gcode",
    "load_excellon", "parse_excellon", "HoleList", "plan_drill", "DrillPlan", "drill_order",
    "load_hpgl", "parse_hpgl", "scan_hpgl", "iter_hpgl", "plan_hpgl", "HpglDrawing", "HpglScan",
    "decode_pin_log", "read_pin_log", "write_pin_log", "PinLog", "Motion", "carve",
    "Profile", "load_profile", "profile_from_expr",
    "image_report", "job_report",
    "MachineSettings", "load_settings",
    "CamError", "DrawingError", "ParseError", "PlanError", "PortError", "SettingsError", "TravelError",
]
