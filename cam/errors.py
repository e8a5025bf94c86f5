"""The one error root of `cam`.

Every problem a user can cause (a bad file, a bad option, a job that does not
fit the machine, a port that cannot be opened) raises a subclass of
:class:`CamError`.  The CLI turns any ``CamError`` into one line on stderr and
exit code 2; anything else is a bug in `cam`.
"""
from __future__ import annotations

__all__ = [
    "CamError",
    "DrawingError",
    "ParseError",
    "SettingsError",
    "PlanError",
    "TravelError",
    "StalePlanError",
    "PortError",
    "CapabilityError",
    "BusyError",
]


class CamError(Exception):
    """Root of every error `cam` raises on purpose."""


class DrawingError(CamError):
    """The drawing breaks a rule that makes digitizing impossible."""


class ParseError(CamError):
    """A file (digitized matrix, drill file, ...) cannot be read; the message names file and line."""


class SettingsError(CamError):
    """A machine settings file or option is unknown or out of range; the message names the key."""


class PlanError(CamError):
    """Job options do not fit the digitized drawing (e.g. too few depths)."""


class TravelError(PlanError):
    """A move would leave the configured machine travel."""


class StalePlanError(PlanError):
    """A job was planned for another machine state (the tool elsewhere, another work zero) than the one it would
    start in: it must be planned again there (issue #43 point 6)."""


class PortError(CamError):
    """A port cannot be opened or written."""


class CapabilityError(PortError):
    """The port cannot do what was asked (the MAXIMUS board has no pause, a real port keeps no pin log)."""


class BusyError(CamError):
    """The machine is busy with something else (or idle when something running was expected)."""
