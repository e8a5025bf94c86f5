"""One packet and its reply, the emergency stop, and closing a mode: the part of
:class:`~cam.drive.maximus.board.MaximusBoard` that keeps host and firmware in step.

The board object tracks where the firmware waits (``_MODE``, ``_JOG``, ``_OFFSET``, ``_INIT``,
``_DRILL``, or ``_UNKNOWN`` after an error); see the safety rules in :mod:`cam.drive.maximus.board`.

Every reply is awaited for as long as the firmware needs to make the move it answers (computed from the
packet by :mod:`.packets`), plus the time a limit switch would add, plus the margin ``timeout_s``: a long
move never times out and a dead board is found soon after its move should have ended.  A reply that comes
too soon for its move, any other byte, or none at all is a link fault (:mod:`.trust`): nothing more is sent.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from typing import Callable, Optional, Sequence, TypeVar

from ...errors import PortError
from .packets import (
    close_drill_packet, finish_pulse_packet, init_packet, jog_exit_packet, jog_moved, jog_packet, offset_packet,
    stopped_between, switch_time_ns,
)
from .trust import LinkFault, _Trust
from .protocol import (
    ATOFFSETPOS, BYTE_NAMES, DRILLMODE1DONE, DRILLMODE1INITIALIZED, EMERGENCYSTOP, JOGMODEDONE, JOGMODEOFF, JOGMODEON,
    MACHINESTOPPED, OPENJOGMODE, SWITCH_NAMES,
)

T = TypeVar("T")

# Host-side model of where the firmware is waiting.
_MODE = "mode selection"
_JOG = "jog data input"
_OFFSET = "offset packet"
_INIT = "init packet"
_DRILL = "drill data input"
_UNKNOWN = "unknown"

SLOWER_FACTOR = 1.1
"""A real PIC is a little slower than its delays (each dly_100us call adds ~3 us, each pulse a few
instructions: seed 000 Appendix 1, ``dly_100us``: "3us+(1.2us+d)*n"); a deadline allows 10 % more."""


@dataclass
class _Exchange:
    """A packet sent whose reply is still due."""

    what: str  # e.g. "hole 3"
    expected: int
    moving: bool  # the firmware has interrupts enabled: an emergency stop is honoured
    mode: str  # "jog" or "drill"
    next_state: str
    move_ns: int = 0  # how long the firmware moves before it answers
    moved: tuple[int, int, int] = (0, 0, 0)  # board-frame pulses (x, y, height) the move makes
    # pulses moved after so many ns of the move, a pulse half made counted whole (packets.drill_moved's ``whole``)
    progress: Optional[Callable[[int], tuple[int, int, int]]] = None
    # the direction (+1, -1, 0: still) each axis steps in after so many ns of the move (default: its move's sign)
    directions: Optional[Callable[[int], tuple[int, int, int]]] = None


def _name(byte: int) -> str:
    return f"{BYTE_NAMES.get(byte, 'unknown byte')} ({byte:#04x})"


_SWITCH_OFF = "nothing more sent, switch the machine off, then on, and jog to the board origin again"

_CLOSE_DRILL = _Exchange("the closing drill packet", DRILLMODE1DONE, False, "drill", _MODE)


class _Link(_Trust):
    """Exchanges, the emergency stop and job bookkeeping; the board supplies ``_write``, ``_read_byte``,
    ``_require``, ``timeout_s``, ``maximus`` and the state attributes set in its ``__init__``."""

    # -------------------------------------------------------------- deadlines and where the head is
    def _deadline_s(self, ex: _Exchange) -> float:
        """How long to wait for the reply to ``ex``: its move, a limit switch's debounce and back-off (when
        interrupts are on during the move), the margin."""
        switch_ns = switch_time_ns(self._back_off_delay()) if ex.moving else 0
        return (ex.move_ns * SLOWER_FACTOR + switch_ns) / 1e9 + self.timeout_s

    def _back_off_delay(self) -> int:
        """The Delay of a limit switch's back-off: the firmware's ``axisDelay``, the last Jog packet's delay
        (at least every delay this machine uses, since an earlier program may have jogged the board)."""
        m = self.maximus
        return max(self._last_jog_delay or 0, m.delay_x, m.delay_y, m.delay_z_up, m.delay_z_down)

    def _where(self) -> str:
        x, y, z = self.position_pulses
        return f"last known position X={x} Y={y} Z={z} pulses (Y up, Z height) from where the board was opened"

    # -------------------------------------------------------------- one packet and its reply
    def _exchange(self, packet: bytes, ex: _Exchange) -> None:
        """Send ``packet`` and check its reply; raises PortError on anything but ``ex.expected``."""
        with self._lock:
            self._require_quiet(ex.what)
            self._pending = ex
            self._estop_sent = False
            self._stop_done.clear()
            self._reader_active = True
            self._send_start_s = time.monotonic()  # the firmware cannot start the move before this
            try:
                self._write(packet)
            except BaseException:
                self._pending = None
                self._reader_active = False
                raise
            self._sent_s = time.monotonic()  # ... and has left by this
            if ex.mode == "jog" and len(packet) == 4 and packet[0] >> 6:
                self._last_jog_delay = packet[3]  # the firmware's axisDelay from now on
        try:
            reply = self._read_byte(self._deadline_s(ex))
        except BaseException:
            with self._lock:
                self._reader_active = False  # the exchange stays pending: emergency_stop() reads its answer
            raise
        self._settle(reply)

    def _take_pending(self) -> tuple[_Exchange, bool]:
        with self._lock:
            ex, estop = self._pending, self._estop_sent
            self._pending = None
            self._reader_active = False
            assert ex is not None
            return ex, estop

    def _settle(self, reply: Optional[int]) -> None:
        """Judge the reply to the pending exchange (called by whichever thread read it)."""
        ex, estop = self._take_pending()
        elapsed_s = time.monotonic() - self._send_start_s
        if estop:
            try:
                error = self._resolve_stop(ex, reply)
            except PortError as exc:
                self._stop_error = error = exc
            finally:
                self._stop_done.set()
            raise error
        if reply is None:
            raise self._lost(ex)
        reason = self._unexplained(ex, reply, elapsed_s)
        if reason is not None:
            raise self._fault(ex.what, reason)
        if reply == ex.expected:
            self._state = ex.next_state
            self.position_pulses = tuple(p + d for p, d in zip(self.position_pulses, ex.moved))  # type: ignore
            return
        if reply in SWITCH_NAMES:
            where = self._where()
            self._after_stop(ex.mode)
            raise PortError(f"limit switch {SWITCH_NAMES[reply]} ({reply:#04x}) tripped during {ex.what}; "
                            f"the board backed off and ended the job ({where})")
        raise self._fault(ex.what, f"the board answered {_name(reply)} instead of {_name(ex.expected)}")

    def _lost(self, ex: _Exchange) -> LinkFault:
        """No reply in time.  Nothing is sent, not even the stop byte: the firmware may be waiting for the
        rest of a packet that lost a byte on the way, and any byte would complete it, as often as not into
        a move (docs/maximus.md, "When the link fails")."""
        waited = (f"the MAXIMUS board did not answer within {self._deadline_s(ex):.1f} s (expected "
                  f"{_name(ex.expected)}")
        waited += f"; the move takes {ex.move_ns / 1e9:.3f} s)" if ex.move_ns else ")"
        return self._fault(ex.what, f"{waited}: a byte of the packet or its answer was lost, or the board is "
                                    f"off or disconnected")

    # -------------------------------------------------------------- after a stop: spindle off, mode closed
    def _after_stop(self, mode: str, finish: Sequence[tuple[str, int]] = ()) -> None:
        """After MACHINESTOPPED or a switch byte: Drill mode is at mode selection, Jog mode still in Jog.

        ``finish``: ``(axis, direction)`` of each axis whose pulse the stop may have left half made; a Jog packet
        of no pulses in that direction ends it (:meth:`_finish_pulses`).  The firmware leaves the spindle pin (RB2)
        as it was (seed 000 Appendix 1: only a Jog packet sets it), so a Jog packet of no pulses with the spindle
        bit clear switches it off (those packets do); then Jog mode is left.
        """
        self._state = _JOG if mode == "jog" else _MODE
        if finish:
            self._finish_pulses(finish)
        self._spindle_off_now()

    def _finish_pulses(self, finish: Sequence[tuple[str, int]]) -> None:
        """End the pulses a stop may have left half made, each in the direction its axis stepped, spindle off.

        A stop between a pulse's falling and rising edge leaves that STEP pin low, and the axis's next move would
        make one rising edge more than it asks, in that move's direction (the listing's "Add last step";
        cam.sim.maximus point 14): the head would stand a pulse off where the host books it.  A Jog packet of no
        pulses ends with that rising edge (:func:`~.packets.finish_pulse_packet`): the pulse is made now, in the
        stopped move's direction, so the head stands where the stopped move's time says to the nearest whole
        pulse, which is what :meth:`_book_stopped_move` books.  A pin left high makes nothing."""
        if self._state == _MODE:
            self._exchange(bytes([OPENJOGMODE]), _Exchange("OPENJOGMODE", JOGMODEON, False, "jog", _JOG))
        m = self.maximus
        for axis, direction in finish:
            i = "xyz".index(axis)
            packet = finish_pulse_packet(axis, direction, delay=(m.delay_x, m.delay_y, m.delay_z_up)[i],
                                         half_step=(m.half_step_x, m.half_step_y, m.half_step_z)[i],
                                         invert=(m.invert_x, m.invert_y, m.invert_z)[i])
            self._exchange(packet, _Exchange(f"the end of the stopped {axis.upper()} pulse (no pulses)", JOGMODEDONE,
                                             True, "jog", _JOG))
            self._spindle_on = False

    def _spindle_off_now(self) -> None:
        """From mode selection or Jog data input: the spindle off, back at mode selection."""
        if self._spindle_on is not False:
            if self._state == _MODE:
                self._exchange(bytes([OPENJOGMODE]), _Exchange("OPENJOGMODE", JOGMODEON, False, "jog", _JOG))
            m = self.maximus
            self._exchange(jog_packet("z", 0, delay=m.delay_z_up, half_step=m.half_step_z, spindle=False),
                           _Exchange("the spindle-off packet (no pulses)", JOGMODEDONE, True, "jog", _JOG))
            self._spindle_on = False
        if self._state == _JOG:
            self._leave_jog()

    def _leave_jog(self) -> None:
        """Send the Jog exit packet and expect JOGMODEOFF (no motion)."""
        self._exchange(jog_exit_packet(), _Exchange("the Jog exit packet", JOGMODEOFF, False, "jog", _MODE))

    def _book_stopped_move(self, ex: _Exchange) -> tuple[int, list[tuple[str, int]]]:
        """A move stopped part of the way: book the pulses its time allowed until the stop byte (an estimate: the
        firmware does not say how far it went).  The move began as the packet's write went out and ended as the
        stop byte's did; each is known between the clock read before its write and the one after (a busy
        computer may pause between them), so the middle is booked, a pulse half made there counted whole.

        Returns how many pulses either end of that time lies from the booking (0 or 1 on an idle computer), and
        ``(axis, direction)`` of each axis the move steps, in its direction at that middle: the pulses
        :meth:`_finish_pulses` ends, so that the head stands where it is booked."""
        progress, directions = ex.progress, ex.directions
        if progress is None and ex.move_ns and sum(1 for d in ex.moved if d) == 1:  # one axis at one delay
            progress = partial(jog_moved, ex.moved, ex.move_ns, whole=True)
        if progress is None or self._estop_sent_s is None:
            return 0, []
        if directions is None:
            signs = tuple(1 if d > 0 else -1 if d < 0 else 0 for d in ex.moved)
            directions = lambda t: signs  # noqa: E731
        scale = 1e9 * self._time_scale  # type: ignore[attr-defined]
        earliest, latest = (int(min(seconds * scale, 2.0 ** 62)) for seconds in (
            self._estop_sent_s - self._sent_s, self._estop_done_s - self._send_start_s))
        moved, bound = stopped_between(progress, earliest, latest)
        self.position_pulses = tuple(p + int(d) for p, d in zip(self.position_pulses, moved))  # type: ignore
        steps = directions((earliest + latest) // 2)
        finish = [(axis, int(d)) for axis, d in zip("xyz", steps) if d]
        return bound, sorted(finish, key=lambda item: item[0] != "z")  # Z first: it switches the spindle off

    def _resolve_stop(self, ex: _Exchange, reply: Optional[int]) -> PortError:
        """The reply to a move during which EMERGENCYSTOP was sent: the error the job ends with."""
        if reply == MACHINESTOPPED:
            bound, finish = self._book_stopped_move(ex)
            self._after_stop(ex.mode, finish)
            busy = (f"; the computer was busy as the stop went out, so where the head stopped is known within "
                    f"±{bound} pulses" if bound > 1 else "")
            return PortError(f"emergency stop during {ex.what}: the board answered MACHINESTOPPED, drivers "
                             f"disabled, spindle off{busy}")
        self.position_known = False  # the stop byte met no move, or the board did not say where it stopped
        if reply is None:
            self._state = _UNKNOWN
            self._stop_error = PortError(f"emergency stop sent during {ex.what} but the board did not "
                                         f"answer within {self._deadline_s(ex):.1f} s: {_SWITCH_OFF}")
            return self._stop_error
        if reply == ex.expected or reply in SWITCH_NAMES:
            # The move ended as the stop byte arrived.  If the UART ISR still caught it,
            # MACHINESTOPPED follows; if not, the firmware took 0x80 as packet data.
            second = self._read_byte(min(0.3, self.timeout_s))
            if second == MACHINESTOPPED:
                self._after_stop(ex.mode)
                return PortError(f"emergency stop at the end of {ex.what}: the board answered "
                                 f"MACHINESTOPPED, drivers disabled, spindle off")
            self._state = _UNKNOWN
            self._stop_error = PortError(f"emergency stop reached the board after {ex.what} had ended; it "
                                         f"read the stop byte as packet data and is out of step: {_SWITCH_OFF}")
            return self._stop_error
        self._state = _UNKNOWN
        self._stop_error = PortError(f"emergency stop during {ex.what}: the board answered {_name(reply)}: "
                                     f"{_SWITCH_OFF}")
        return self._stop_error

    # ------------------------------------------------------------------ emergency stop
    def emergency_stop(self) -> bool:
        """Stop the machine now; safe to call from any thread (e.g. on Ctrl-C).

        During a move (the firmware has interrupts enabled) this sends
        EMERGENCYSTOP (0x80) and waits for MACHINESTOPPED: the firmware cuts
        the drivers and returns to mode selection (Drill) or Jog data input
        (Jog); the spindle is then switched off and Jog mode left, so the board
        is ready for the next command.  Between moves the firmware would
        read 0x80 as packet data, so nothing is sent: the running job stops
        before its next packet, closes its mode with packets that move nothing
        and switches the spindle off.  (The Init move cannot be stopped: the
        listing runs it with interrupts off.)

        Returns:
            True if a move was stopped (MACHINESTOPPED received), False if no
            move was running.

        Raises:
            PortError: the stop byte was sent but not answered, or arrived
                as the move ended and was taken as packet data.
        """
        with self._lock:
            self.stop_asked = True
            ex = self._pending
            between_moves = ex is None or not ex.moving
            if between_moves:
                self._stop_requested = True
                # no job left to act on the request (e.g. it was interrupted by Ctrl-C): finish here
                orphan_reply = ex is not None and not self._reader_active
                finish_here = not self._job_active and (ex is None or orphan_reply)
            elif not self._estop_sent:
                self._estop_sent = True
                self._stop_error = None
                self._estop_sent_s = time.monotonic()  # the stop byte leaves between this and _estop_done_s
                self._write(bytes([EMERGENCYSTOP]))
                self._estop_done_s = time.monotonic()
            reader = self._reader_active
        if between_moves:
            if finish_here:
                if ex is not None:
                    try:
                        self._settle(self._read_byte())  # the answer to a packet that moves nothing stoppable
                    except PortError:
                        pass
                if self._state in (_OFFSET, _INIT, _DRILL, _JOG, _MODE):
                    self._unwind()
            return False
        if reader:
            wait_s = 7 * self.timeout_s + 1.0  # the answer, the packets that end half-made pulses, the exit packets
            if not self._stop_done.wait(wait_s):
                raise PortError(f"emergency stop sent; no answer was read within {wait_s:g} s")
        else:
            # nobody is reading (the job was interrupted): read the answer here
            try:
                self._settle(self._read_byte())
            except PortError:
                pass
        if self._stop_error is not None:
            raise self._stop_error
        return True

    def _unwind(self) -> None:
        """From a waiting firmware state, get back to mode selection without moving anything; spindle off."""
        if self._state == _OFFSET:
            self._exchange(offset_packet(0, 0, 0),
                           _Exchange("the closing offset packet", ATOFFSETPOS, True, "drill", _INIT))
        if self._state == _INIT:
            self._exchange(init_packet(0, 0),
                           _Exchange("the closing init packet", DRILLMODE1INITIALIZED, False, "drill", _DRILL))
        if self._state == _DRILL:
            self._exchange(close_drill_packet(), _CLOSE_DRILL)
        if self._state in (_JOG, _MODE):
            self._spindle_off_now()

    def _check_stop(self, before: str) -> None:
        """Between moves: if a stop was asked for, close the mode cleanly and end the job."""
        with self._lock:
            if not self._stop_requested:
                return
        self._unwind()
        raise PortError(f"emergency stop before {before}: no move was running; job closed, spindle off, "
                        f"nothing more sent")

    # ------------------------------------------------------------------ job bookkeeping
    def _begin_job(self) -> None:
        with self._lock:
            if self._job_active:
                raise PortError("a MAXIMUS job is already running on this board")
            self._job_active = True
            self._stop_requested = False
            self.stop_asked = False

    def _end_job(self) -> None:
        with self._lock:
            self._job_active = False

    def _clean_up_after(self) -> None:
        """An exception left a job: if the firmware waits between moves, close its mode quietly (spindle off).

        During a move (e.g. Ctrl-C while waiting for a reply) nothing is sent:
        :meth:`emergency_stop` deals with the move.
        """
        with self._lock:
            if self._pending is not None or self._state not in (_OFFSET, _INIT, _DRILL, _JOG, _MODE):
                return
        try:
            self._unwind()
        except PortError:
            pass

    def _run_job(self, session: Callable[[], T]) -> T:
        """Run ``session`` as the board's one job, from mode selection; if it fails between moves, close the
        firmware's mode quietly (:meth:`_clean_up_after`)."""
        self._begin_job()
        try:
            self._require(_MODE)
            result = session()
            self._end_quiet("the end of the job")  # the last reply was the last byte
            return result
        except BaseException:
            self._clean_up_after()
            raise
        finally:
            self._end_job()
