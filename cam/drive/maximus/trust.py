"""Which bytes from the MAXIMUS board the host believes (issue #33): the part of
:class:`~cam.drive.maximus.board.MaximusBoard` that turns a reply it cannot explain into a :class:`LinkFault`.

The firmware answers every packet with exactly one byte, and a packet that moves answers only when its move
has ended (seed 000 Appendix 1: ``putc(JOGMODEDONE)``, ``putc(ATOFFSETPOS)``, ``putc(ONEHOLEDRILLED)`` follow
the ``constspeed`` calls).  The host knows each move's length from the packet and the Delay bytes
(:mod:`.packets`), so it refuses:

* the expected byte earlier than :data:`EARLY_FRACTION` of the move's time, less :data:`EARLY_MARGIN_S`
  (a real PIC is never faster than its delays: ``dly_100us`` takes 100 us and 3 us more per call);
* a limit-switch byte during a packet that moves nothing (interrupts are off) or before the switch's
  300 ms debounce (``isr_ext``: ``delay_ms(300)`` before ``putc``) could have ended;
* any other byte, and any byte waiting before a packet is sent or arriving just after the job's last reply.

A fault sends nothing more: the firmware may hold part of a packet, and every byte the host could send
might complete it into a move (docs/maximus.md, "When the link fails").  The position is then unknown.
"""
from __future__ import annotations

import os
import re
import time
from pathlib import Path
from typing import Any, Optional

from ...errors import PortError
from ...fileio import state_dir
from .protocol import BANNER, BYTE_NAMES, DEBOUNCE_NS, SWITCH_NAMES

__all__ = ["LinkFault", "EARLY_FRACTION", "EARLY_MARGIN_S", "QUIET_S", "EMULATOR_SPEEDS_ENV", "emulator_speed",
           "fault_marker", "clear_fault_marker"]

EARLY_FRACTION = 0.95
"""A reply may come no sooner than this share of its move's time at the packet's Delay bytes: the PIC's
delays are never shorter than listed (``dly_100us``: "3us+(1.2us+d)*n", d = 98.8 us); 5 % covers the crystal,
the host's clock and an emulator that runs up to 1 ms ahead of its pacing."""

EARLY_MARGIN_S = 0.002
"""...less this much (the host's timer and the emulator's pacing step)."""

QUIET_S = 0.05
"""After a job's last reply the line must stay quiet this long: a byte then answers nothing the host sent."""

EMULATOR_SPEEDS_ENV = "CAM_MAXIMUS_EMULATOR_SPEEDS"
"""``DEVICE=SPEED,DEVICE=SPEED``: boards that run SPEED times faster than their Delay bytes (``inf``: no
waiting at all).  :mod:`cam.sim.maximus` sets it for the emulators it starts at another speed than the
firmware's own, so that the host's earliest-reply check scales; a real board is never listed."""


class LinkFault(PortError):
    """The serial link delivered a reply the host cannot explain (too early, unexpected, wrong) or none: the
    host sent nothing more, and the head's position is unknown."""


def _name(byte: int) -> str:
    return f"{BYTE_NAMES.get(byte, 'unknown byte')} ({byte:#04x})"


def emulator_speed(device: str) -> float:
    """How many times faster than its Delay bytes the board on ``device`` runs: 1.0 unless
    :data:`EMULATOR_SPEEDS_ENV` lists it."""
    for item in os.environ.get(EMULATOR_SPEEDS_ENV, "").split(","):
        name, _, speed = item.rpartition("=")
        if name and name == device:
            try:
                value = float(speed)
            except ValueError:
                return 1.0
            return value if value > 0 else 1.0
    return 1.0


def fault_marker(device: str) -> Path:
    """The file a link fault on ``device`` leaves (in `cam`'s state folder) until the user removes it, having
    switched the board off and on: until then no command opens the board, because its first byte (the
    handshake's ISMACHINEREADY) would complete a packet the firmware may still hold."""
    slug = re.sub(r"[^A-Za-z0-9._]+", "-", device).strip("-.") or "port"
    return state_dir() / f"maximus-link-fault-{slug}.txt"


def clear_fault_marker(device: str) -> None:
    """The board on ``device`` was switched off and on (its banner was seen, or an emulator powered up)."""
    try:
        fault_marker(device).unlink(missing_ok=True)
    except OSError:
        pass


def _leave_fault_marker(device: str, message: str) -> Optional[Path]:
    """Write the marker (None if it cannot be written: the message itself still says to switch off)."""
    try:
        path = fault_marker(device)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(message + "\n", encoding="utf-8")
        return path
    except OSError:
        return None


class _Trust:
    """The board supplies ``_ser``, ``_state``, ``position_pulses``, ``position_known``, ``_time_scale``,
    ``_where`` and ``_read_byte``."""

    def _earliest_s(self, move_ns: int) -> float:
        """The soonest a move of ``move_ns`` (at the Delay bytes) can be answered, from the packet's send."""
        if not move_ns:
            return 0.0
        scale: float = self._time_scale  # type: ignore[attr-defined]
        return max(0.0, move_ns / 1e9 * EARLY_FRACTION / scale - EARLY_MARGIN_S)

    def _unexplained(self, ex: Any, reply: int, elapsed_s: float) -> Optional[str]:
        """Why ``reply``, read ``elapsed_s`` after ``ex``'s packet was sent, cannot be its answer (None: it can)."""
        if reply == ex.expected:
            earliest = self._earliest_s(ex.move_ns)
            if elapsed_s < earliest:
                return (f"{_name(reply)} came {elapsed_s:.3f} s after the packet, but its move takes "
                        f"{ex.move_ns / 1e9:.3f} s (no answer is plausible before {earliest:.3f} s)")
            return None
        if reply in SWITCH_NAMES:
            if not ex.moving:
                return f"{_name(reply)} answered a packet that moves nothing (the firmware's interrupts are off)"
            earliest = self._earliest_s(DEBOUNCE_NS)
            if elapsed_s < earliest:
                return (f"{_name(reply)} came {elapsed_s:.3f} s after the packet, before a limit switch's "
                        f"{DEBOUNCE_NS / 1e9:.1f} s debounce could have ended")
            return None
        return f"the board answered {_name(reply)} instead of {_name(ex.expected)}"

    def _fault(self, what: str, reason: str) -> LinkFault:
        """Mark the firmware's state and the head's position unknown; the one-line error the job ends with."""
        where = self._where()  # type: ignore[attr-defined]
        self._state = "unknown"
        self.position_known = False
        message = (f"link fault during {what}: {reason}; nothing more sent, the head's position is unknown "
                   f"({where}): the board may still be moving with the spindle on, switch the machine off, then on, "
                   f"and jog to the board origin again")
        marker = _leave_fault_marker(self.device, message)  # type: ignore[attr-defined]
        if marker is not None:
            message += f" (then delete {marker}: until then no command opens this board)"
        return LinkFault(message)

    def _refuse_after_fault(self, seen: bytes) -> None:
        """Before the handshake's first byte: refuse while an earlier link fault's marker stands, unless the
        bytes already waiting hold the power-up banner (the board was switched off and on)."""
        device: str = self.device  # type: ignore[attr-defined]
        marker = fault_marker(device)
        if not marker.exists():
            return
        if BANNER in seen:
            clear_fault_marker(device)
            return
        self._state = "unknown"
        raise LinkFault(f"an earlier command on {device} ended in a link fault, so the board may hold part of a "
                        f"packet that this command's first byte would complete into a move: switch the machine "
                        f"off and on, then delete {marker} and run this again")

    def _stray_bytes(self) -> bytes:
        """Bytes waiting on the line now (read and returned)."""
        try:
            waiting = self._ser.in_waiting  # type: ignore[attr-defined]
            return bytes(self._ser.read(min(int(waiting), 64))) if waiting else b""  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - the read that follows reports a dead port
            return b""

    def _require_quiet(self, before: str) -> None:
        """Before a packet: nothing may wait on the line (no packet asked for it)."""
        stray = self._stray_bytes()
        if stray:
            raise self._fault(before, f"{len(stray)} byte(s) came that answer nothing sent "
                                      f"({' '.join(f'{b:#04x}' for b in stray[:8])}) before its packet was sent")

    def _end_quiet(self, what: str) -> None:
        """After a job's last reply: the line stays quiet for :data:`QUIET_S`."""
        t0 = time.monotonic()
        extra = self._read_byte(QUIET_S)  # type: ignore[attr-defined]
        if extra is not None:
            raise self._fault(what, f"{_name(extra)} came {time.monotonic() - t0:.3f} s after the last reply, "
                                    f"answering nothing sent")
