"""Machine settings: one place for every number that describes the machine.

The built-in values are the thesis's (``shared/seeds/001``):

* steps per pixel X/Y = 8 and Z = 1, pulse delay X/Y = Z = 5 ms: the drilling
  options of Table 5.1 (section 5.2);
* mm per step X/Y = 0.0289 and Z = 0.0157: the constants of Eq. 4.1 and 4.2;
* the parallel-port pin map of the drive circuit (chapter 3): pin 1 (strobe)
  Half/Full*, held low for full steps; pins 2/3 clock and CW/CCW of Z, 4/5 of
  Y, 6/7 of X.

Settings load from a TOML file (``--machine FILE``); any key may be left out
and then keeps its built-in value.  An unknown key or a bad value is a
:class:`~cam.errors.SettingsError` naming the key.  Example::

    steps_per_px_xy = 8
    steps_per_px_z = 1
    delay_xy_ms = 5.0
    delay_z_ms = 5.0
    mm_per_step_xy = 0.0289
    mm_per_step_z = 0.0157
    half_step = false

    # speed ramps (cam.motion.ramps): "lookahead" (default), "linear40" or "constant"
    ramp = "lookahead"
    start_speed_x_mm_s = 1.445    # pull-in: the axis starts and stops at once at this speed
    start_speed_y_mm_s = 1.445
    start_speed_z_mm_s = 0.785
    max_speed_x_mm_s = 5.78       # = 0.0289 mm / 5 ms: the thesis's constant-delay speed
    max_speed_y_mm_s = 5.78
    max_speed_z_mm_s = 3.14       # = 0.0157 mm / 5 ms
    accel_x_mm_s2 = 50.0
    accel_y_mm_s2 = 50.0
    accel_z_mm_s2 = 50.0

    # where G-code's G28 and G30 go, machine mm in G-code's axes (+Y up, +Z up) from the home
    g28_x_mm = 0.0
    g28_y_mm = 0.0
    g28_z_mm = 0.0
    g30_x_mm = 0.0
    g30_y_mm = 0.0
    g30_z_mm = 0.0

    [travel]            # machine travel in steps, from the home (0, 0, 0)
    x_min_steps = 0
    x_max_steps = 10000
    y_min_steps = 0
    y_max_steps = 10000
    z_min_steps = -640
    z_max_steps = 2000

    [pins]              # parallel-port connector pin numbers (2..9 are data bits D0..D7)
    clock_x = 6
    dir_x = 7
    clock_y = 4
    dir_y = 5
    clock_z = 2
    dir_z = 3

    [maximus]           # the MAXIMUS PIC board (--port maximus:DEV): its PC program's Machine Settings form
    delay_x = 10        # the Delay byte of each axis: pulses at 5000 / Delay Hz
    delay_y = 10
    delay_z_up = 10
    delay_z_down = 10
    half_step_x = true  # the MODE bit of each axis's L297: a clock pulse is half a motor step
    half_step_y = true
    half_step_z = true
    mm_per_full_step_x = 0.00875  # travel per motor step of each axis: a pulse is half of it in half steps
    mm_per_full_step_y = 0.00875  # (on the board these set mm per step, not mm_per_step_xy / _z)
    mm_per_full_step_z = 0.00875
    invert_x = false    # flip the DIR bit of an axis wired the other way round
    invert_y = false
    invert_z = false
    drill_z_up_steps = 0     # Z Drill Up / Down: pulses below the board origin; down 0 = from --travel-height
    drill_z_down_steps = 0   # and --cut-depth (the origin is then the travel height above the board)
    spindle = true      # the spindle (RB2) runs while the board drills
    serial_port = ""    # the device of --port maximus (no device named)
    baud = 115200
    reply_margin_s = 1.0     # a reply is due this long after the move it answers should have ended

    [commands]          # a control unit driven by command bytes on the parallel port (seed 004 section 3.5)
    x_plus = 0x4B       # the byte of one step toward +X (the seed's X_INC); -1 (the default): not declared
    x_minus = -1        # ... y_plus, y_minus, z_plus (one step deeper), z_minus, spindle_on, spindle_off
    init = -1           # sent once before the first command byte of a port (-1: nothing)
    strobe_us = 10.0    # the strobe pulse of each byte
    byte_gap_us = 20.0  # the least time from one command byte to the next

    [tool]              # the cutter drawings are planned for (--tool overrides it)
    shape = "point"     # "point" (the thesis's model), "flat", "ball" or "v"
    diameter_mm = 0.0   # flat and ball: the cutting diameter; V: where the cone ends (0: 1/8 inch)
    angle_deg = 0.0     # V: the included angle
    tip_mm = 0.0        # V: the flat tip's diameter (0: sharp)

    [inputs]            # switches on the status pins 10, 11, 12, 13, 15: "N" active high, "!N" active low
    home_x = "!10"      # "" (the default): not wired
    home_y = "!11"
    home_z = "!12"
    limit_x_min = ""    # a pin may serve several limits (both ends of an axis, or every axis) and its axis's home
    limit_x_max = "!13"
    limit_y_min = ""
    limit_y_max = "!13"
    limit_z_min = ""
    limit_z_max = "!13"
    estop = "!15"       # the e-stop button: a pin of its own
    probe = ""          # the touch probe (cam probe): a pin of its own, closed while the tool touches the work

    [homing]            # cam home (LinuxCNC's HOME_SEARCH_VEL / HOME_LATCH_VEL / HOME_OFFSET)
    order = "zxy"       # the axes homed, one after another (Z first: the tool goes up out of the way)
    search_speed_x_mm_s = 0.0   # toward the switch until it closes (at most the axis's start speed; 0: that)
    latch_speed_x_mm_s = 0.0    # toward it again, slowly, after backing off until it opened (0: search / 10)
    direction_x = "-"   # where the switch is: "-" or "+" (+Z is deeper: "-" is up)
    backoff_x_mm = 0.5  # moved on beyond where the switch opened before the latch
    offset_x_mm = 0.0   # the machine coordinate of the latch point: the machine's zero is offset_x_mm from it
    # ... the same keys for y and z

    [mock]              # the mock port's simulated switches, machine steps (tests and trying cam home on the mock)
    home_x_steps = 0    # home_x closes at or beyond this X on its direction's side
    limit_x_max_steps = 9000    # limit_x_max closes at X >= 9000 (limit_*_min: at or below)
    estop_after_s = 2.0 # the e-stop input closes this long after a run starts (machine time)
    probe_surface = "-1.0,0.001,0,0.0001,50,40"  # the work's surface for inputs.probe: z0,ax,ay,b,cx,cy (below)
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .errors import CamError, SettingsError

__all__ = ["Travel", "Pins", "Maximus", "Commands", "COMMAND_KEYS", "Inputs", "Homing", "MockSwitches",
           "parse_surface", "MachineSettings", "load_settings", "DEFAULT_SETTINGS", "RAMP_MODES", "INPUT_PINS", "INPUT_BITS", "SWITCH_NAMES"]

RAMP_MODES = ("lookahead", "linear40", "constant")
"""Speed ramp modes (see :mod:`cam.motion.ramps`)."""
MIN_SPEED_MM_S = 0.01
"""The slowest start speed, top speed and acceleration (mm/s, mm/s^2) a setting may give: slower ones made
step periods of hours and machine times that overflow."""
MAX_TRAVEL_STEPS = 10**9
"""The farthest a travel limit may lie from the home, in steps."""
MIN_MM_PER_STEP = 1e-6
"""The finest step a setting may give (a nanometre): finer ones turned any coordinate of a file into more steps
than a number holds (issue #33 point 8: ``mm_per_step_xy = 1e-308`` ended in an OverflowError)."""


@dataclass(frozen=True)
class Travel:
    """Machine travel limits in steps, in the machine frame (home = (0, 0, 0); +Z is deeper)."""

    x_min_steps: int = 0
    x_max_steps: int = 10000
    """X: the home at 0, 10000 steps (289 mm) to the right."""
    y_min_steps: int = 0
    y_max_steps: int = 10000
    """Y: the home at 0, 10000 steps toward the operator."""
    z_min_steps: int = -640
    z_max_steps: int = 2000
    """Z: up to 640 steps (10 mm) above the home plane, 2000 steps (31.4 mm) below it (+Z is deeper)."""

    def bounds_steps(self) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
        """((x_min, x_max), (y_min, y_max), (z_min, z_max)) in steps."""
        return (
            (self.x_min_steps, self.x_max_steps),
            (self.y_min_steps, self.y_max_steps),
            (self.z_min_steps, self.z_max_steps),
        )


@dataclass(frozen=True)
class Pins:
    """Parallel-port connector pins of the step/direction signals.

    Pins 2..9 are data-register bits D0..D7; pin 1 is the strobe line, which
    carries Half/Full* (low = full step).  Defaults are the thesis drive
    circuit's wiring (``shared/seeds/001``, chapter 3, Tables 3.2/3.3).
    """

    clock_x: int = 6
    dir_x: int = 7
    """X motor: clock on pin 6 (D4), direction on pin 7 (D5)."""
    clock_y: int = 4
    dir_y: int = 5
    """Y motor: clock on pin 4 (D2), direction on pin 5 (D3)."""
    clock_z: int = 2
    dir_z: int = 3
    """Z motor: clock on pin 2 (D0), direction on pin 3 (D1)."""

    def bit(self, name: str) -> int:
        """Data-register bit (0..7) of the signal ``name`` (e.g. ``"clock_x"``)."""
        return getattr(self, name) - 2


INPUT_PINS = (10, 11, 12, 13, 15)
"""The parallel port's input pins: its status register (``shared/seeds/001`` section 3.1.1.2: "five digital
input terminals, of which one of them is inverted", at base + 1: 379h for LPT1)."""
INPUT_BITS = {10: 6, 11: 7, 12: 5, 13: 4, 15: 3}
"""Input pin -> its bit in :meth:`cam.drive.ports.Port.read_inputs` (the status register's bit: pin 10 ACK = bit 6,
11 BUSY = bit 7, 12 PAPER-OUT = bit 5, 13 SELECT = bit 4, 15 ERROR = bit 3), each bit the pin's electrical level
(1 = high; BUSY's inversion in the hardware undone, as pyparallel's ``getInBusy`` does)."""
SWITCH_NAMES = ("home_x", "home_y", "home_z", "limit_x_min", "limit_x_max", "limit_y_min", "limit_y_max",
                "limit_z_min", "limit_z_max", "estop", "probe")
"""What an input pin may be wired to (the keys of ``[inputs]``)."""


@dataclass(frozen=True)
class Inputs:
    """Switches wired to the parallel port's input pins (``[inputs]``): each key ``""`` (not wired), ``"N"``
    (active high: the switch closed makes pin N high) or ``"!N"`` (active low), N one of :data:`INPUT_PINS`."""

    home_x: str = ""
    home_y: str = ""
    home_z: str = ""
    """Home switches, sought by ``cam home``; they stop nothing."""
    limit_x_min: str = ""
    limit_x_max: str = ""
    limit_y_min: str = ""
    limit_y_max: str = ""
    limit_z_min: str = ""
    limit_z_max: str = ""
    """Limit switches at each end of each axis: one closing stops the motion, the position becomes unknown."""
    estop: str = ""
    """The e-stop button: closed stops the motion and sends nothing more."""
    probe: str = ""
    """The touch probe (``cam probe``): closed while the tool touches the work; it stops nothing but a probing
    move (:mod:`cam.drive.probing`)."""

    def wired(self) -> dict[str, tuple[int, bool]]:
        """Each wired switch's ``name -> (pin, active_high)``."""
        out: dict[str, tuple[int, bool]] = {}
        for name in SWITCH_NAMES:
            text = getattr(self, name).strip()
            if text:
                out[name] = (int(text.lstrip("!").strip()), not text.startswith("!"))
        return out


@dataclass(frozen=True)
class Homing:
    """How ``cam home`` homes each axis (``[homing]``): LinuxCNC's HOME_SEARCH_VEL, HOME_LATCH_VEL, HOME_OFFSET."""

    order: str = "zxy"
    """The axes homed, one after another (Z first: the tool goes up, clear of the work)."""
    search_speed_x_mm_s: float = 0.0
    search_speed_y_mm_s: float = 0.0
    search_speed_z_mm_s: float = 0.0
    """Speed toward the switch until it closes, and away until it opens (at most the axis's start speed: the
    axis stops at once when the switch closes); 0: the axis's start speed."""
    latch_speed_x_mm_s: float = 0.0
    latch_speed_y_mm_s: float = 0.0
    latch_speed_z_mm_s: float = 0.0
    """The slow approach that latches the home (at most the search speed); 0: a tenth of the search speed."""

    def speeds_mm_s(self, settings: "MachineSettings", axis: str) -> tuple[float, float]:
        """``(search, latch)`` speed of ``axis`` ("x", "y", "z") in mm/s, the defaults (0) worked out."""
        search = getattr(self, f"search_speed_{axis}_mm_s") or getattr(settings, f"start_speed_{axis}_mm_s")
        return search, getattr(self, f"latch_speed_{axis}_mm_s") or search / 10
    direction_x: str = "-"
    direction_y: str = "-"
    direction_z: str = "-"
    """Where the switch lies: ``"-"`` or ``"+"`` (+Z is deeper: ``"-"`` is up)."""
    backoff_x_mm: float = 0.5
    backoff_y_mm: float = 0.5
    backoff_z_mm: float = 0.5
    """Moved on, away from the switch, beyond where it opened, before the latch."""
    offset_x_mm: float = 0.0
    offset_y_mm: float = 0.0
    offset_z_mm: float = 0.0
    """The machine coordinate of the latch point (the tool stands there after homing)."""


def parse_surface(text: str, name: str = "probe surface") -> tuple[float, float, float, float, float, float] | None:
    """A probe surface ``"z0,ax,ay,b,cx,cy"`` (:attr:`MockSwitches.probe_surface`) as six floats, missing trailing
    values 0; None for ``""``.

    Raises:
        SettingsError: not one to six finite numbers separated by commas (naming ``name``).
    """
    if not text.strip():
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 6 or not all(math.isfinite(v) and abs(v) <= 1e6 for v in values):
        raise SettingsError(f"'{name}' must be 1 to 6 numbers z0,ax,ay,b,cx,cy (mm; the surface's height "
                            f"z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2)), got {text[:60]!r}")
    return tuple(values + [0.0] * (6 - len(values)))  # type: ignore[return-value]


@dataclass(frozen=True)
class MockSwitches:
    """The mock port's simulated switches (``[mock]``), machine frame: where each closes (None: never)."""

    home_x_steps: int | None = None
    home_y_steps: int | None = None
    home_z_steps: int | None = None
    """A home switch closes at or beyond this coordinate on its ``[homing]`` direction's side."""
    limit_x_min_steps: int | None = None
    limit_x_max_steps: int | None = None
    limit_y_min_steps: int | None = None
    limit_y_max_steps: int | None = None
    limit_z_min_steps: int | None = None
    limit_z_max_steps: int | None = None
    """A ``_min`` limit closes at or below its coordinate, a ``_max`` one at or above it."""
    estop_after_s: float | None = None
    """The e-stop closes this long after a run starts (the run's time: planned on the simulated clock)."""
    probe_surface: str = ""
    """The work's surface the probe input (``inputs.probe``) touches, ``"z0,ax,ay,b,cx,cy"`` (missing trailing
    values 0; "" none): its height in mm (up positive) at machine X, Y in mm is
    ``z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2)``, and the probe is closed while the tool tip (``-z_steps *
    mm_per_step_z`` mm high) is at or below it."""

    def places(self) -> dict[str, float]:
        """Each simulated switch's ``name -> coordinate (steps) or time (s)`` (the probe's surface apart:
        :meth:`surface`)."""
        return {f.name.removesuffix("_steps").removesuffix("_after_s"): getattr(self, f.name)
                for f in dataclasses.fields(self)
                if f.name != "probe_surface" and getattr(self, f.name) is not None}

    def surface(self) -> tuple[float, float, float, float, float, float] | None:
        """The probe surface's six numbers ``(z0, ax, ay, b, cx, cy)``, or None when none is given.

        >>> MockSwitches(probe_surface="-1.5, 0.01").surface()
        (-1.5, 0.01, 0.0, 0.0, 0.0, 0.0)

        Raises:
            SettingsError: not one to six finite numbers separated by commas.
        """
        return parse_surface(self.probe_surface, "mock.probe_surface")


@dataclass(frozen=True)
class ToolShape:
    """The cutter in the spindle (``[tool]``; see :class:`cam.tool.Tool`): drawings are planned for it."""

    shape: str = "point"
    """"point" (the thesis's model), "flat", "ball" or "v"."""
    diameter_mm: float = 0.0
    """Cutting diameter of a flat or ball end mill; where a V bit's cone ends (0: 1/8 inch)."""
    angle_deg: float = 0.0
    """A V bit's included angle."""
    tip_mm: float = 0.0
    """A V bit's flat tip diameter (0: sharp)."""


@dataclass(frozen=True)
class Maximus:
    """The MAXIMUS PCB driller's settings, as its PC program's Machine Settings form keeps them.

    Seed 000, Appendix 2, ``settingsform.cpp`` (the form's INI sections and defaults): "Axis Speeds"
    (``TrackBarDelayX`` ... ``TrackBarDelayZup``, default 10), "Driving Modes" (``RadioXMode`` ...,
    default 1 = half step), "Invert Direction" (``CheckXInvert`` ..., default off) and "Head Movement"
    (``EditDrillStepZup`` / ``EditDrillStepZdown``); the serial port and baud rate are its Com Port
    settings (the firmware listens at 115200 baud, seed 000 Appendix 1 ``#use rs232``).

    Units: a Delay byte is the half period of a step pulse in 100 us (seed 003, "Step frekansı =
    1 / (2 * Delay * 100 us)": 5000 / Delay pulses per second); Z Drill Up / Down are L297 clock pulses
    below the board origin (+ down, as the PC program's ``positionZ`` counts).
    """

    delay_x: int = 10
    delay_y: int = 10
    delay_z_up: int = 10
    delay_z_down: int = 10
    """The Delay bytes of X, Y, Z going up and Z going down (1..255)."""
    half_step_x: bool = True
    half_step_y: bool = True
    half_step_z: bool = True
    """The MODE bit of each axis: True = half steps (one clock pulse = half a motor step)."""
    mm_per_full_step_x: float = 0.00875
    mm_per_full_step_y: float = 0.00875
    mm_per_full_step_z: float = 0.00875
    """Travel of each axis per motor (full) step: 8.75 um, the PC program's OneStepX "008.7500" um (seed 000
    section 9: "theoretical resolution of 4.375 microns" in half steps).  One clock pulse moves an axis this
    far in full-step mode, half of it in half-step mode (:meth:`mm_per_pulse`)."""
    invert_x: bool = False
    invert_y: bool = False
    invert_z: bool = False
    """Flip the DIR bit of an axis (a motor wired the other way round)."""
    drill_z_up_steps: int = 0
    drill_z_down_steps: int = 0
    """Z Drill Up (where the head travels between holes) and Z Drill Down (the bottom of a hole), pulses below
    the board origin.  Down 0: both from the job's travel height and cut depth, the origin being the travel
    height."""
    spindle: bool = True
    """Run the spindle (RB2) while the board drills."""
    serial_port: str = ""
    """The device ``--port maximus`` opens."""
    baud: int = 115200
    """Serial speed (the firmware's ``#use rs232(baud=115200, ...)``)."""
    reply_margin_s: float = 1.0
    """How long after its move should have ended a reply may still come before the board counts as lost."""

    def mm_per_pulse(self) -> tuple[float, float, float]:
        """Travel of X, Y, Z per L297 clock pulse: the axis's mm per full step, halved in half-step mode.

        >>> Maximus(half_step_x=False).mm_per_pulse()
        (0.00875, 0.004375, 0.004375)
        """
        return tuple(getattr(self, f"mm_per_full_step_{a}") / (2 if getattr(self, f"half_step_{a}") else 1)
                     for a in "xyz")  # type: ignore[return-value]

    @property
    def drill_stroke_set(self) -> bool:
        """Whether Z Drill Up / Down are set here (else they come from the job)."""
        return self.drill_z_down_steps > 0


COMMAND_KEYS = ("x_plus", "x_minus", "y_plus", "y_minus", "z_plus", "z_minus", "spindle_on", "spindle_off", "init")
"""The command bytes of ``[commands]``, in the order :class:`Commands` declares them."""


@dataclass(frozen=True)
class Commands:
    """A control unit that takes command bytes on the parallel port (``[commands]``; the ``cmd:`` ports of
    :mod:`cam.drive.cmd_port`).

    Seed 004 section 3.5 ("Control the CNC machine"): the standalone controller drives the CNC machine's
    control unit by sending it commands on the parallel port, one data byte latched by a strobe pulse for
    each; "one step of the stepper motor results in a movement of 0,0254 mm"; a list of commands "controls
    the movement in all three axes, spindle control, initialization of the machine"; a timer interrupt sends
    each command after its delay, "in the order of a couple hundred microseconds" (3.5.1), ramped over 40
    steps (3.5.2).  The seed gives one byte: ``#define X_INC (0x4B)`` (3.5.3), one step in +X.  Every other
    byte is the control unit's own: read it off your unit (the seed's authors found theirs with a logic
    analyser on the port).

    Each byte is -1 (not declared: a job that needs it is refused before anything moves) or 0..255.
    ``<axis>_plus`` is one step toward + of cam's machine frame on that axis (+Z deeper): the step a step/dir
    port makes with that axis's direction bit high; ``<axis>_minus`` the step toward -.
    """

    x_plus: int = -1
    x_minus: int = -1
    y_plus: int = -1
    y_minus: int = -1
    z_plus: int = -1
    z_minus: int = -1
    """One step of an axis toward + (X right, Y toward the operator, Z deeper) or toward - (seed 004: X_INC =
    0x4B is ``x_plus``)."""
    spindle_on: int = -1
    spindle_off: int = -1
    """Switch the spindle."""
    init: int = -1
    """Sent once, before the first command byte a port sends (the seed's "initialization of the machine")."""
    strobe_us: float = 10.0
    """Width of the strobe pulse that latches each byte (us)."""
    byte_gap_us: float = 20.0
    """The least time from one command byte to the next (us): several axes stepping at once go one after
    another, this far apart."""

    def declared(self) -> dict[str, int]:
        """The bytes declared, ``key -> byte``, in the order of :data:`COMMAND_KEYS`.

        >>> Commands(x_plus=0x4B, init=0x01).declared()
        {'x_plus': 75, 'init': 1}
        """
        return {k: getattr(self, k) for k in COMMAND_KEYS if getattr(self, k) >= 0}


@dataclass(frozen=True)
class MachineSettings:
    """Everything `cam` knows about the machine.  Frozen: make changed copies with :meth:`replace`."""

    steps_per_px_xy: int = 8
    steps_per_px_z: int = 1
    """Motor steps per drawing pixel (the thesis: 8 X/Y, 1 Z); used only by the drawing planner."""
    delay_xy_ms: float = 5.0
    delay_z_ms: float = 5.0
    """The thesis's constant step period of each motor (5 ms)."""
    mm_per_step_xy: float = 0.0289
    mm_per_step_z: float = 0.0157
    """Travel per step of the thesis machine's lead screws."""
    mm_per_step_y: float = 0.0
    """Y's travel per step where it differs from X's (0: ``mm_per_step_xy``).  Not a machine-file key: a MAXIMUS
    board's settings set it from its ``[maximus]`` table (an axis in full steps, the other in half steps)."""
    half_step: bool = False
    """Half/Full* on pin 1 (strobe): low = full steps."""
    ramp: str = "lookahead"
    """Speed ramp mode, one of :data:`RAMP_MODES`."""
    start_speed_x_mm_s: float = 1.445
    start_speed_y_mm_s: float = 1.445
    start_speed_z_mm_s: float = 0.785
    """Speeds each axis may start and stop at without a ramp."""
    max_speed_x_mm_s: float = 5.78
    max_speed_y_mm_s: float = 5.78
    max_speed_z_mm_s: float = 3.14
    """Top speed of each axis."""
    accel_x_mm_s2: float = 50.0
    accel_y_mm_s2: float = 50.0
    accel_z_mm_s2: float = 50.0
    """Acceleration of each axis."""
    g28_x_mm: float = 0.0
    g28_y_mm: float = 0.0
    g28_z_mm: float = 0.0
    """Where G-code's G28 goes (LinuxCNC's parameters 5161..5163): machine mm in G-code's axes (+Y up, +Z up),
    from the home; the default is the home itself."""
    g30_x_mm: float = 0.0
    g30_y_mm: float = 0.0
    g30_z_mm: float = 0.0
    """Where G-code's G30 goes (parameters 5181..5183), as for G28."""
    travel: Travel = field(default_factory=Travel)
    pins: Pins = field(default_factory=Pins)
    maximus: Maximus = field(default_factory=Maximus)
    commands: Commands = field(default_factory=Commands)
    tool: ToolShape = field(default_factory=ToolShape)
    inputs: Inputs = field(default_factory=Inputs)
    homing: Homing = field(default_factory=Homing)
    mock: MockSwitches = field(default_factory=MockSwitches)

    def replace(self, **changes: Any) -> "MachineSettings":
        """A copy with some fields changed; values are validated."""
        new = dataclasses.replace(self, **changes)
        _validate(new, source="settings")
        return new

    @property
    def delay_xy_ns(self) -> int:
        """Step period of the X and Y motors in nanoseconds."""
        return int(round(self.delay_xy_ms * 1_000_000))

    @property
    def delay_z_ns(self) -> int:
        """Step period of the Z motor in nanoseconds."""
        return int(round(self.delay_z_ms * 1_000_000))

    @property
    def mm_per_step_axes(self) -> tuple[float, float, float]:
        """Travel per step of X, Y and Z (Y: ``mm_per_step_y`` when set, else ``mm_per_step_xy``)."""
        return self.mm_per_step_xy, self.mm_per_step_y or self.mm_per_step_xy, self.mm_per_step_z

    def axis_limits(self) -> "tuple[tuple[float, float, float], ...]":
        """Per-axis (X, Y, Z) motion limits: (mm_per_step, start_speed_mm_s, max_speed_mm_s, accel_mm_s2)."""
        return (
            self.mm_per_step_axes,
            (self.start_speed_x_mm_s, self.start_speed_y_mm_s, self.start_speed_z_mm_s),
            (self.max_speed_x_mm_s, self.max_speed_y_mm_s, self.max_speed_z_mm_s),
            (self.accel_x_mm_s2, self.accel_y_mm_s2, self.accel_z_mm_s2),
        )

    def px_to_mm_xy(self, n_px: float) -> float:
        """Eq. 4.1: mm = pixels x steps/pixel (X/Y) x mm/step (X/Y)."""
        return n_px * self.steps_per_px_xy * self.mm_per_step_xy

    def px_to_mm_z(self, n_px: float) -> float:
        """Eq. 4.2: mm = pixels x steps/pixel (Z) x mm/step (Z)."""
        return n_px * self.steps_per_px_z * self.mm_per_step_z


DEFAULT_SETTINGS = MachineSettings()

_DERIVED = frozenset({"mm_per_step_y"})
"""Settings no machine file gives: the MAXIMUS board's settings derive them (:class:`MachineSettings`)."""

_SECTIONS = {"travel": Travel, "pins": Pins, "maximus": Maximus, "commands": Commands, "tool": ToolShape,
             "inputs": Inputs, "homing": Homing, "mock": MockSwitches}


def _type_ok(value: Any, kind: type) -> bool:
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is str:
        return isinstance(value, str)
    return False


def _build(cls: type, table: Mapping[str, Any], prefix: str, source: str, base: Any = None) -> Any:
    """``cls`` from a TOML table: the keys given, the others from ``base`` (or the built-in values)."""
    fields = {f.name: f for f in dataclasses.fields(cls) if prefix or f.name not in _DERIVED}
    values: dict[str, Any] = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise SettingsError(f"{source}: unknown key '{name}' (known: {known})")
        f = fields[key]
        if key in _SECTIONS and prefix == "":
            if not isinstance(value, dict):
                raise SettingsError(f"{source}: '{name}' must be a table [{name}]")
            values[key] = _build(_SECTIONS[key], value, f"{key}.", source,
                                 None if base is None else getattr(base, key))
            continue
        kind = {"int": int, "float": float, "bool": bool, "str": str, "int | None": int, "float | None": float}[
            f.type if isinstance(f.type, str) else f.type.__name__]
        if not _type_ok(value, kind):
            raise SettingsError(f"{source}: '{name}' must be {kind.__name__}, got {value!r}")
        try:
            values[key] = kind(value)
        except OverflowError:  # a whole number too large for a float (TOML integers have no bound here)
            raise SettingsError(f"{source}: '{name}' is out of range: {str(value)[:40]}") from None
    return cls(**values) if base is None else dataclasses.replace(base, **values)


def _validate(s: MachineSettings, source: str) -> None:
    def bad(key: str, why: str) -> SettingsError:
        return SettingsError(f"{source}: '{key}' {why}")

    for key in ("steps_per_px_xy", "steps_per_px_z"):
        if not (1 <= getattr(s, key) <= 10000):
            raise bad(key, f"must be 1..10000 steps, got {getattr(s, key)}")
    for key in ("delay_xy_ms", "delay_z_ms"):
        if not (0.001 <= getattr(s, key) <= 10000):
            raise bad(key, f"must be 0.001..10000 ms, got {getattr(s, key)}")
    for key in ("mm_per_step_xy", "mm_per_step_z"):
        if not (MIN_MM_PER_STEP <= getattr(s, key) <= 100):
            raise bad(key, f"must be {MIN_MM_PER_STEP:g}..100 mm, got {getattr(s, key)}")
    if s.mm_per_step_y and not (MIN_MM_PER_STEP <= s.mm_per_step_y <= 100):
        raise bad("mm_per_step_y", f"must be 0 (as X) or {MIN_MM_PER_STEP:g}..100 mm, got {s.mm_per_step_y}")
    if s.ramp not in RAMP_MODES:
        raise bad("ramp", f"must be one of {', '.join(RAMP_MODES)}, got {s.ramp!r}")
    for axis in "xyz":
        start, top, acc = (getattr(s, f"{k}_{axis}_{u}") for k, u in
                           (("start_speed", "mm_s"), ("max_speed", "mm_s"), ("accel", "mm_s2")))
        if not (MIN_SPEED_MM_S <= top <= 10000):
            raise bad(f"max_speed_{axis}_mm_s", f"must be {MIN_SPEED_MM_S:g}..10000 mm/s, got {top}")
        if not (MIN_SPEED_MM_S <= start <= top):
            raise bad(f"start_speed_{axis}_mm_s",
                      f"must be {MIN_SPEED_MM_S:g} mm/s..max_speed_{axis}_mm_s ({top}), got {start}")
        if not (MIN_SPEED_MM_S <= acc <= 1e6):
            raise bad(f"accel_{axis}_mm_s2", f"must be {MIN_SPEED_MM_S:g}..1e6 mm/s^2, got {acc}")
    for key in ("g28_x_mm", "g28_y_mm", "g28_z_mm", "g30_x_mm", "g30_y_mm", "g30_z_mm"):
        if not abs(getattr(s, key)) <= 1e6:
            raise bad(key, f"must be within 1e6 mm of the home, got {getattr(s, key)}")
    for axis, (lo, hi) in zip("xyz", s.travel.bounds_steps()):
        if abs(lo) > MAX_TRAVEL_STEPS or abs(hi) > MAX_TRAVEL_STEPS:
            raise bad(f"travel.{axis}_min_steps", f"and travel.{axis}_max_steps must be within "
                      f"{MAX_TRAVEL_STEPS} steps of the home, got {lo}..{hi}")
        if lo > 0 or hi < 0:
            raise bad(f"travel.{axis}_min_steps", f"and travel.{axis}_max_steps must contain the home 0, got {lo}..{hi}")
    pins = {f.name: getattr(s.pins, f.name) for f in dataclasses.fields(Pins)}
    for name, pin in pins.items():
        if not (2 <= pin <= 9):
            raise bad(f"pins.{name}", f"must be a data pin 2..9, got {pin}")
    seen: dict[int, str] = {}
    for name, pin in pins.items():
        if pin in seen:
            raise bad(f"pins.{name}", f"uses pin {pin}, already used by 'pins.{seen[pin]}'")
        seen[pin] = name
    _validate_maximus(s.maximus, bad)
    _validate_commands(s.commands, bad)
    _validate_tool(s.tool, bad)
    _validate_inputs(s.inputs, bad)
    _validate_homing(s, bad)
    _validate_mock(s.mock, bad, s.inputs)


def _validate_inputs(inputs: Inputs, bad: Any) -> None:
    """Each key a pin of :data:`INPUT_PINS`, ``!`` before it for active low; a pin shared only by limits and
    their axis's home switch, at one level; the e-stop on a pin of its own."""
    users: dict[int, tuple[str, bool]] = {}
    for name in SWITCH_NAMES:
        text = getattr(inputs, name).strip()
        if not text:
            continue
        digits = text.lstrip("!").strip()
        if text.count("!") > 1 or not digits.isdigit() or int(digits) not in INPUT_PINS:
            raise bad(f"inputs.{name}", f"must be an input pin 10, 11, 12, 13 or 15, with '!' before it for "
                      f"active low (e.g. \"!10\"), or \"\" when not wired, got {text[:20]!r}")
        pin, high = int(digits), not text.startswith("!")
        if pin in users:
            other, other_high = users[pin]
            if other_high != high:
                raise bad(f"inputs.{name}", f"reads pin {pin} active {'high' if high else 'low'}, but "
                          f"'inputs.{other}' reads it active {'high' if other_high else 'low'}")
            if not _may_share(name, other):
                raise bad(f"inputs.{name}", f"uses pin {pin}, already used by 'inputs.{other}' (a pin may serve "
                          f"several limits and the home switch of their axis; the e-stop and the probe need a pin "
                          f"of their own)")
        else:
            users[pin] = (name, high)


def _may_share(a: str, b: str) -> bool:
    """Whether switches ``a`` and ``b`` may share a pin: limits, and a home switch with its own axis's limits."""
    if {"estop", "probe"} & {a, b} or (a.startswith("home") and b.startswith("home")):
        return False
    home, other = (a, b) if a.startswith("home") else (b, a)
    return not home.startswith("home") or home[-1] == other[6]


def _validate_homing(s: MachineSettings, bad: Any) -> None:
    h = s.homing
    order = h.order.lower()
    if not order or any(a not in "xyz" for a in order) or len(set(order)) != len(order):
        raise bad("homing.order", f"must be the axes to home, each once, in order (e.g. \"zxy\"), got {h.order!r}")
    start = {"x": s.start_speed_x_mm_s, "y": s.start_speed_y_mm_s, "z": s.start_speed_z_mm_s}
    for a in "xyz":
        search, latch = h.speeds_mm_s(s, a)
        if not MIN_SPEED_MM_S / 10 <= search <= start[a]:
            raise bad(f"homing.search_speed_{a}_mm_s", f"must be {MIN_SPEED_MM_S / 10:g} mm/s..start_speed_{a}_mm_s "
                      f"({start[a]}: the axis stops at once when the switch closes), or 0, got {search}")
        if not MIN_SPEED_MM_S / 10 <= latch <= search:
            raise bad(f"homing.latch_speed_{a}_mm_s",
                      f"must be {MIN_SPEED_MM_S / 10:g} mm/s..the search speed ({search}), or 0, got {latch}")
        if getattr(h, f"direction_{a}") not in ("-", "+"):
            raise bad(f"homing.direction_{a}", f"must be \"-\" or \"+\", got {getattr(h, f'direction_{a}')!r}")
        if not 0 <= getattr(h, f"backoff_{a}_mm") <= 1000:
            raise bad(f"homing.backoff_{a}_mm", f"must be 0..1000 mm, got {getattr(h, f'backoff_{a}_mm')}")
        lo, hi = s.travel.bounds_steps()["xyz".index(a)]
        per = s.mm_per_step_z if a == "z" else s.mm_per_step_xy
        offset = getattr(h, f"offset_{a}_mm")
        if not (math.isfinite(offset) and lo <= round(offset / per) <= hi):
            raise bad(f"homing.offset_{a}_mm", f"must lie in the {a.upper()} travel ({lo * per:g}..{hi * per:g} "
                      f"mm), got {offset}")


def _validate_mock(m: MockSwitches, bad: Any, inputs: Inputs) -> None:
    for f in dataclasses.fields(m):
        v = getattr(m, f.name)
        if v is None:
            continue
        if f.name == "probe_surface":
            try:
                m.surface()
            except SettingsError as exc:
                raise bad("mock.probe_surface", str(exc).split("' ", 1)[1]) from None
            if v.strip() and not inputs.probe.strip():
                raise bad("mock.probe_surface", "needs the probe's input pin: set inputs.probe (e.g. \"!13\")")
            continue
        if f.name == "estop_after_s" and not (0 <= v <= 1e6):
            raise bad("mock.estop_after_s", f"must be 0..1e6 s, got {v}")
        if f.name != "estop_after_s" and abs(v) > MAX_TRAVEL_STEPS:
            raise bad(f"mock.{f.name}", f"must be within {MAX_TRAVEL_STEPS} steps of the home, got {v}")


def _validate_tool(t: ToolShape, bad: Any) -> None:
    from .tool import tool_of_settings

    try:
        tool_of_settings(t)
    except CamError as exc:
        raise bad("tool.shape", str(exc).removeprefix("tool: ")) from None


def _validate_maximus(m: Maximus, bad: Any) -> None:
    for key in ("delay_x", "delay_y", "delay_z_up", "delay_z_down"):
        if not 1 <= getattr(m, key) <= 255:  # one byte; 0 would make no delay at all (seed 000 App. 1 dly_100us)
            raise bad(f"maximus.{key}", f"must be a Delay byte 1..255 (pulses at 5000/Delay Hz), got {getattr(m, key)}")
    for a in "xyz":
        if not MIN_MM_PER_STEP <= getattr(m, f"mm_per_full_step_{a}") <= 100:
            raise bad(f"maximus.mm_per_full_step_{a}", f"must be {MIN_MM_PER_STEP:g}..100 mm, got "
                      f"{getattr(m, f'mm_per_full_step_{a}')}")
    up, down = m.drill_z_up_steps, m.drill_z_down_steps
    if not (0 <= up <= 0xFFFF and (down == 0 or up < down <= 0xFFFF)):  # 16-bit fields (seed 000 App. 1 make16)
        raise bad("maximus.drill_z_down_steps", f"must be deeper (more pulses below the origin) than "
                  f"maximus.drill_z_up_steps, both 0..65535 (down 0: the stroke from the job), got up {up}, "
                  f"down {down}")
    if not 1 <= m.baud <= 4_000_000:
        raise bad("maximus.baud", f"must be 1..4000000, got {m.baud}")
    if not (0.05 <= m.reply_margin_s <= 60):
        raise bad("maximus.reply_margin_s", f"must be 0.05..60 s, got {m.reply_margin_s}")


def _validate_commands(c: Commands, bad: Any) -> None:
    for key in COMMAND_KEYS:
        if not -1 <= getattr(c, key) <= 255:
            raise bad(f"commands.{key}", f"must be a byte 0..255, or -1 when not declared, got {getattr(c, key)}")
    seen: dict[int, str] = {}
    for key, byte in c.declared().items():
        if byte in seen:
            raise bad(f"commands.{key}", f"is 0x{byte:02X}, already the byte of 'commands.{seen[byte]}'")
        seen[byte] = key
    if not 0.1 <= c.strobe_us <= 10000:
        raise bad("commands.strobe_us", f"must be 0.1..10000 us, got {c.strobe_us}")
    if not c.strobe_us <= c.byte_gap_us <= 100000:
        raise bad("commands.byte_gap_us", f"must be commands.strobe_us ({c.strobe_us:g})..100000 us (the strobe "
                  f"pulse ends before the next byte), got {c.byte_gap_us}")


def settings_from_mapping(table: Mapping[str, Any], source: str = "settings",
                          base: MachineSettings | None = None) -> MachineSettings:
    """Build validated settings from a parsed TOML table (keys as in the module docstring); keys left out keep
    their values in ``base`` (default: the built-in settings)."""
    settings = _build(MachineSettings, table, "", source, base)
    _validate(settings, source)
    return settings


def load_settings(path: str | os.PathLike | None = None, base: MachineSettings | None = None) -> MachineSettings:
    """Load machine settings from a TOML file; ``None`` gives ``base`` (default: the thesis defaults).

    Keys the file leaves out keep their values in ``base``.

    Raises :class:`SettingsError` for a missing file, bad TOML, an unknown key
    or a bad value, always naming the file and the key.
    """
    if path is None:
        return base or DEFAULT_SETTINGS
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SettingsError(f"{p}: settings file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SettingsError(f"{p}: cannot read settings file ({exc})") from None
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"{p}: not valid TOML ({exc})") from None
    except ValueError as exc:  # a number the TOML reader refuses to convert (an integer of thousands of digits)
        raise SettingsError(f"{p}: a number is out of range ({str(exc).split(';')[0]})") from None
    return settings_from_mapping(table, source=str(p), base=base)
