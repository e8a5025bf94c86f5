"""``main()`` of the MAXIMUS firmware (seed 000 Appendix 1): its labels as a state machine.

A part of :class:`cam.sim.maximus.MaximusEmulator`; the module docstring there says where the emulator
follows the listing rather than the report's prose.
"""
from __future__ import annotations

from ..drive.maximus.protocol import (
    ATOFFSETPOS, BANNER, DIR_X, DIR_Y, DIR_Z, DRILLMODE1DONE, DRILLMODE1INITIALIZED, DRILLMODE1ON, DRILLMODE2ON,
    ENABLE_X, ENABLE_Y, ENABLE_Z, ISMACHINEREADY, JOGMODEDONE, JOGMODEOFF, JOGMODEON, MACHINEREADY, MODE_X, MODE_Y,
    MODE_Z, ONEHOLEDRILLED, OPENDRILLMODE1, OPENDRILLMODE2, OPENJOGMODE, PORT_B, PORT_D, POWER_UP_B, POWER_UP_D,
    SPINDLE_BIT,
)
from ._maximus_base import (
    DRILL_MODE1_INITIALIZE, DRILL_MODE1_INPUT, INITIALIZE_DRILL_MODE, JOG_DATA_INPUT, MODE_SELECTION, POWER_UP,
    _Goto,
)


class _Program:
    """The firmware's program: power-up, mode selection, Jog mode and Drill mode 1.

    It runs on :class:`~cam.sim._maximus_hardware._Hardware` (pins, motion, interrupts) and
    :class:`~cam.sim._maximus_uart._Uart` (bytes in and out).
    """

    def _main(self) -> None:
        """``main()`` of Appendix 1, with its labels as a state machine."""
        self._gie = self._int_ext = self._int_rda = self._intf = False
        self._output_port(PORT_B, POWER_UP_B)
        self._output_port(PORT_D, POWER_UP_D)
        self._write_master(BANNER)
        self.power_ups += 1
        self._gie = False  # disable_interrupts(GLOBAL)
        while self._getc(POWER_UP) != ISMACHINEREADY:
            pass
        self._putc(MACHINEREADY)
        label = MODE_SELECTION
        steps = {
            MODE_SELECTION: self._mode_selection,
            JOG_DATA_INPUT: self._jog_data_input,
            DRILL_MODE1_INITIALIZE: self._drill_mode1_initialize,
            DRILL_MODE1_INPUT: self._drill_mode1_input,
        }
        while True:
            try:
                label = steps[label]()
            except _Goto as jump:
                label = jump.label

    def _mode_selection(self) -> str:
        b = self._getc(MODE_SELECTION)
        self._log_packet("mode", bytes([b]))
        if b == ISMACHINEREADY:
            self._putc(MACHINEREADY)
            return MODE_SELECTION
        if b == OPENJOGMODE:
            self._putc(JOGMODEON)
            return JOG_DATA_INPUT
        if b == OPENDRILLMODE1:
            self._putc(DRILLMODE1ON)
            return DRILL_MODE1_INITIALIZE
        if b == OPENDRILLMODE2:  # "!Not Completed!"
            self._putc(DRILLMODE2ON)
            return JOG_DATA_INPUT
        return JOG_DATA_INPUT  # no case matched: execution falls through to the JOG_DATA_INPUT label

    def _jog_data_input(self) -> str:
        self._machine_mode = 0
        data = self._read_packet(4, JOG_DATA_INPUT, "jog")
        self._intf = False  # bit_clear(*0x0B,1)
        if (data[0] >> 6) == 0:
            self._putc(JOGMODEOFF)
            self._gie = False
            return MODE_SELECTION
        axis_step = data[1] | (data[2] << 8)
        self._axis_delay = data[3]
        config = data[0]
        axis_select = (config & 0xC0) >> 6
        axis_mode = int(bool(config & 0x20))
        axis_dir = int(bool(config & 0x10))
        spindle = config & 0x01
        self._begin_move()
        self._enable_interrupts()
        self._output_bit(ENABLE_X, 1)
        self._output_bit(ENABLE_Y, 1)
        self._output_bit(ENABLE_Z, 1)
        self._output_bit(SPINDLE_BIT, spindle)
        pins = {1: (MODE_X, DIR_X), 2: (MODE_Y, DIR_Y), 3: (MODE_Z, DIR_Z)}
        mode_pin, dir_pin = pins[axis_select]
        self._output_bit(mode_pin, axis_mode)
        self._output_bit(dir_pin, axis_dir)
        self._constspeed(axis_step, self._axis_delay, axis_select)
        self._reply_after_move(JOGMODEDONE)
        return JOG_DATA_INPUT

    def _drill_mode1_initialize(self) -> str:
        self._machine_mode = 1
        d = self._read_packet(10, DRILL_MODE1_INITIALIZE, "offset")
        self._intf = False  # bit_clear(*0x0B,1)
        config = d[0]
        step_x = d[1] | (d[2] << 8)
        step_y = d[3] | (d[4] << 8)
        step_z = d[5] | (d[6] << 8)
        self._delay_x, self._delay_y, self._delay_z_up = d[7], d[8], d[9]
        self._begin_move()
        self._enable_interrupts()
        self._output_bit(ENABLE_X, 1)
        self._output_bit(ENABLE_Y, 1)
        self._output_bit(ENABLE_Z, 1)
        self._output_bit(MODE_X, int(bool(config & 0x08)))
        self._output_bit(MODE_Y, int(bool(config & 0x10)))
        self._output_bit(MODE_Z, int(bool(config & 0x20)))
        self._output_bit(DIR_X, int(bool(config & 0x01)))
        self._output_bit(DIR_Y, int(bool(config & 0x02)))
        self._output_bit(DIR_Z, int(bool(config & 0x04)))
        self._constspeed(step_z, self._delay_z_up, 3)
        self._constspeed(step_x, self._delay_x, 1)
        self._constspeed(step_y, self._delay_y, 2)
        self._reply_after_move(ATOFFSETPOS)
        # Initialize Drill Mode: read and run with interrupts disabled
        d = self._read_packet(9, INITIALIZE_DRILL_MODE, "init")
        config = d[0]
        self._drill_step_z_up = d[1] | (d[2] << 8)
        self._drill_step_z_down = d[3] | (d[4] << 8)
        self._delay_x, self._delay_y, self._delay_z_up, self._delay_z_down = d[5], d[6], d[7], d[8]
        self._output_bit(MODE_X, int(bool(config & 0x01)))
        self._output_bit(MODE_Y, int(bool(config & 0x02)))
        self._output_bit(MODE_Z, int(bool(config & 0x04)))
        self._output_bit(DIR_Z, 1)  # Z down
        self._constspeed(self._drill_step_z_up, self._delay_z_up, 3)
        self._putc(DRILLMODE1INITIALIZED)
        return DRILL_MODE1_INPUT

    def _drill_mode1_input(self) -> str:
        d = self._read_packet(5, DRILL_MODE1_INPUT, "drill")
        if not (d[0] >> 7):  # Continue Drilling Flag reset: leave Drill mode
            self._putc(DRILLMODE1DONE)
            self._gie = False
            return MODE_SELECTION
        if (d[0] & 0x40) >> 6:  # Start Drilling Flag set: answer without moving
            self._putc(ONEHOLEDRILLED)
            self._gie = False
            return DRILL_MODE1_INPUT
        config = d[0]
        step_x = d[1] | (d[2] << 8)
        step_y = d[3] | (d[4] << 8)
        self._output_bit(DIR_X, int(bool(config & 0x01)))
        self._output_bit(DIR_Y, int(bool(config & 0x02)))
        self._begin_move()
        self._enable_interrupts()
        self._constspeed_xy(step_x, step_y, self._delay_x, self._delay_y)
        self._output_bit(DIR_Z, 1)  # Z down
        self._constspeed(self._drill_step_z_down, self._delay_z_down, 3)
        if self._drill_step_z_down:
            self._log_hole()  # at the bottom of the stroke
        self._output_bit(DIR_Z, 0)  # Z up
        self._constspeed(self._drill_step_z_up, self._delay_z_up, 3)
        self._reply_after_move(ONEHOLEDRILLED)
        return DRILL_MODE1_INPUT

    def _reply_after_move(self, reply: int) -> None:
        """The end of a move: reply with interrupts still enabled, then disable them."""
        if self._inject_now is not None:  # a move with no pulse: the injected switch trips now
            self._press_injected()
        self._poll_interrupts()
        self._putc(reply)
        # putc() returns as the byte starts out (87 us on the line); disable_interrupts follows a few
        # instructions later, long before a host can answer: only bytes already received count here.
        self._poll_interrupts(fetch=False)
        self._gie = False  # disable_interrupts(GLOBAL)
