"""Driving the machine: step plans, ports, the runner and the pin-log decoder.

This is the only part of `cam` that sleeps or writes to hardware.
"""
from .pinlog import Motion, PinLog, carve, decode_pin_log, read_pin_log, write_pin_log
from .ports import MockPort, ParallelPort, Port, open_port
from .runner import EMERGENCY_STOPPED, FINISHED, STOPPED, Controller, RunResult, run, simulate_surface
from .steps import StepPlan, axis_bits, plan_steps

__all__ = [
    "Motion", "PinLog", "carve", "decode_pin_log", "read_pin_log", "write_pin_log",
    "MockPort", "ParallelPort", "Port", "open_port",
    "Controller", "RunResult", "run", "simulate_surface", "FINISHED", "STOPPED", "EMERGENCY_STOPPED",
    "StepPlan", "axis_bits", "plan_steps",
]
