"""Driving the machine: step plans, speed ramps, pin maps, ports, the runner, the MAXIMUS host.

This is the only part of `cam` that sleeps or writes to hardware.  Import
from the modules: :mod:`cam.drive.steps` (the step plan),
:mod:`cam.drive.ramps` (speed ramps), :mod:`cam.pins`,
:mod:`cam.drive.ports` (ports opened by name), :mod:`cam.drive.runner`,
:mod:`cam.drive.maximus`.
"""
