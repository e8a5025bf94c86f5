"""The MAXIMUS board as the firmware drives it: step pulses and their timing, output ports B and D and the
limit switches they move towards, and the two interrupts (limit switch, UART).

A part of :class:`cam.sim.maximus.MaximusEmulator`.
"""
from __future__ import annotations

from ..drive.maximus.protocol import (
    AXIS_PINS, DEBOUNCE_NS, DELAY_UNIT_NS, DIR_X, DIR_Y, EMERGENCYSTOP, ENABLE_X, ENABLE_Y, ENABLE_Z, HOME_SWITCH_X,
    HOME_SWITCH_Y, HOME_SWITCH_Z, LIMIT_SWITCH_X, LIMIT_SWITCH_Y, LIMIT_SWITCH_Z, MACHINESTOPPED, MODE_X, MODE_Y,
    MODE_Z, STEP_PIN, STEP_X, STEP_Y, STEPSBACKATLIMIT,
)
from ._maximus_base import JOG_DATA_INPUT, MODE_SELECTION, _Goto

# isr_ext(): port A as read (switches active low) -> the switch byte sent, and the DIR pin, its value and the
# axis (constspeed's pin number) of the STEPSBACKATLIMIT back-off; the Z switches get no back-off.
_SWITCH_ACTIONS = {
    0x3E: (HOME_SWITCH_X, DIR_X, 1, 1),  # RA0 = 0
    0x3D: (LIMIT_SWITCH_X, DIR_X, 0, 1),  # RA1 = 0
    0x3B: (HOME_SWITCH_Y, DIR_Y, 1, 2),  # RA2 = 0
    0x37: (LIMIT_SWITCH_Y, DIR_Y, 0, 2),  # RA3 = 0
    0x2F: (HOME_SWITCH_Z, None, 0, 0),  # RA4 = 0
    0x1F: (LIMIT_SWITCH_Z, None, 0, 0),  # RA5 = 0
}


_MODE_PINS = (MODE_X, MODE_Y, MODE_Z)


class _Hardware:
    """Motion (``constspeed``), the simulated clock, the pins and the interrupt service routines."""

    # ------------------------------------------------------------------ motion
    def _constspeed(self, n: int, delay: int, pin: int) -> None:
        """``constspeed()`` / ``constspeed2()``: n pulses of period 2 * delay * 100 us on one axis."""
        step = STEP_PIN[pin]
        for _ in range(n):
            self._output_bit(step, 1)
            self._dly_100us(delay)
            self._output_bit(step, 0)
            self._dly_100us(delay)
        self._output_bit(step, 1)  # "Add last step": back to the idle level

    def _constspeed_xy(self, step_x: int, step_y: int, delay_x: int, delay_y: int) -> None:
        """``constspeed_xy()``: the dog-leg XY move."""
        delay_xy = delay_y if delay_x < delay_y else delay_x
        if step_x > step_y:
            step_xy, axis, step_more = step_y, 0, step_x - step_y
        else:
            step_xy, axis, step_more = step_x, 1, step_y - step_x
        for _ in range(step_xy):
            self._output_bit(STEP_X, 1)
            self._output_bit(STEP_Y, 1)
            self._dly_100us(delay_xy)
            self._output_bit(STEP_X, 0)
            self._output_bit(STEP_Y, 0)
            self._dly_100us(delay_xy)
        self._output_bit(STEP_X, 1)
        self._output_bit(STEP_Y, 1)
        pin, delay = (STEP_X, delay_x) if axis == 0 else (STEP_Y, delay_y)
        for _ in range(step_more):
            self._output_bit(pin, 1)
            self._dly_100us(delay)
            self._output_bit(pin, 0)
            self._dly_100us(delay)
        self._output_bit(pin, 1)

    def _dly_100us(self, n: int) -> None:
        self._advance(n * DELAY_UNIT_NS)

    def _advance(self, ns: int) -> None:
        """Simulated time runs ``ns`` on, at ``speed`` on the wall clock.  With the UART interrupt on, a byte that
        arrives within that time is served at its arrival, in the middle of the delay as on the PIC; if the
        thread is late (a busy computer) it catches up to that time first, never stopping sooner."""
        end = self._t_ns + ns
        self._check_halt()
        if self._speed is None:
            self._t_ns = end
            return
        while True:
            if self._gie and self._int_rda:
                at = self._arrival_by(end)
                if at is not None:
                    self._t_ns = at
                    self._poll_interrupts(fetch=False)  # the UART ISR, now: it may stop the move (_Goto)
                    if self._t_ns >= end:
                        break
                    continue
            if not self._wait_for_wall(end, self._gie and self._int_rda):
                break
            self._check_halt()
        self._t_ns = end
        self._check_halt()

    # ------------------------------------------------------------------ pins
    def _output_bit(self, pin: tuple[int, int], value: int) -> None:
        port, bit = pin
        old = self._ports[port]
        self._output_port(port, (old & ~(1 << bit)) | ((1 if value else 0) << bit))

    def _output_port(self, port: int, value: int) -> None:
        old = self._ports[port]
        self._ports[port] = value
        with self._lock:
            self._port_rows.append((self._t_ns, port, value))
        for axis, (p, step_b, dir_b, en_b, sign) in enumerate(AXIS_PINS):
            if p != port:
                continue
            if (value >> step_b) & 1 and not (old >> step_b) & 1 and (value >> en_b) & 1:
                step = sign if (value >> dir_b) & 1 else -sign
                self._pos[axis] += step
                mode_port, mode_bit = _MODE_PINS[axis]
                # a clock pulse is half a motor step with MODE high, a whole one (two halves) with MODE low
                self._half_steps[axis] += step * (1 if (self._ports[mode_port] >> mode_bit) & 1 else 2)
                self._after_step()
        if self._gie:
            self._poll_interrupts()

    def _after_step(self) -> None:
        if self._inject_now is not None:
            self._press_injected()
        else:
            self._update_switches()

    def _press_injected(self) -> None:
        self._injected |= self._inject_now or 0
        self._inject_now = None
        self._update_switches()

    def _update_switches(self) -> None:
        bits = self._injected
        x, y, z = self._pos
        tx, ty, tz = self._travel
        if tx is not None:
            bits |= HOME_SWITCH_X if x < tx[0] else 0
            bits |= LIMIT_SWITCH_X if x > tx[1] else 0
        if ty is not None:
            bits |= HOME_SWITCH_Y if y < ty[0] else 0
            bits |= LIMIT_SWITCH_Y if y > ty[1] else 0
        if tz is not None:
            bits |= HOME_SWITCH_Z if z > tz[1] else 0
            bits |= LIMIT_SWITCH_Z if z < tz[0] else 0
        if self._pressed == 0 and bits != 0:
            self._intf = True  # the AND gate's output falls: RB0 H_TO_L edge
        self._pressed = bits

    def _input_a(self) -> int:
        return 0x3F & ~self._pressed  # RA0..RA5, switches active low

    # ------------------------------------------------------------------ interrupts
    def _begin_move(self) -> None:
        self.moves_started += 1
        with self._lock:
            for trip in self._trips:
                if trip[1] > 0:
                    trip[1] -= 1
                    continue
                self._inject_now = trip[0]
                self._trips.remove(trip)
                break

    def _enable_interrupts(self) -> None:
        self._int_ext = self._int_rda = True
        self._gie = True
        self._poll_interrupts()

    def _poll_interrupts(self, fetch: bool = True) -> None:
        while self._gie:
            if self._int_ext and self._intf:
                self._isr_ext()
                continue
            if self._int_rda and self._byte_due(fetch):
                self._isr_rda()
                continue
            return

    def _isr_ext(self) -> None:
        """``isr_ext()``: a limit switch was pressed."""
        self._gie = False
        self._advance(DEBOUNCE_NS)
        conditions = self._input_a()
        self._injected = 0
        self._update_switches()
        action = _SWITCH_ACTIONS.get(conditions)
        if action is None:  # 0x3F (released) or several switches: return from the ISR
            self._intf = False
            self._gie = True
            return
        switch, dir_pin, direction, axis = action
        if dir_pin is not None:
            self._output_bit(dir_pin, direction)
            self._constspeed(STEPSBACKATLIMIT, self._axis_delay, axis)
        self._putc(switch)
        raise _Goto(self._label_after_stop())

    def _label_after_stop(self) -> str:
        """Where an ISR that stopped the move jumps: Jog mode waits for the next Jog packet, Drill mode
        goes back to mode selection."""
        return JOG_DATA_INPUT if self._machine_mode == 0 else MODE_SELECTION

    def _isr_rda(self) -> None:
        """``serial_isr()``: a byte arrived during a move."""
        self._gie = False
        b = self._pop_byte()
        with self._lock:
            self._rx_rows.append((self._t_ns, b, "isr"))
        if b == EMERGENCYSTOP:
            self._output_bit(ENABLE_X, 0)
            self._output_bit(ENABLE_Y, 0)
            self._output_bit(ENABLE_Z, 0)
            self._putc(MACHINESTOPPED)
            raise _Goto(self._label_after_stop())
        self._gie = True  # any other byte: read and forgotten
