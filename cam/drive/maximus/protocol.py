"""The MAXIMUS board's protocol and pin map, declared once (seed 000, Appendix 1; seed 003).

Imported by the host (:mod:`cam.drive.maximus.board`) and by the emulator
(:mod:`cam.sim.maximus`); every value cites the line of the firmware listing
it comes from.
"""
from __future__ import annotations

__all__ = [
    "ISMACHINEREADY",
    "MACHINEREADY",
    "OPENJOGMODE",
    "JOGMODEON",
    "JOGMODEOFF",
    "JOGMODEDONE",
    "OPENDRILLMODE1",
    "DRILLMODE1ON",
    "ONEHOLEDRILLED",
    "DRILLMODE1INITIALIZED",
    "DRILLMODE1DONE",
    "OPENDRILLMODE2",
    "DRILLMODE2ON",
    "DRILLMODE2OFF",
    "DRILLMODE2DONE",
    "ATOFFSETPOS",
    "EMERGENCYSTOP",
    "MACHINESTOPPED",
    "ERRORLIMITSWITCH",
    "HOME_SWITCH_X",
    "LIMIT_SWITCH_X",
    "HOME_SWITCH_Y",
    "LIMIT_SWITCH_Y",
    "HOME_SWITCH_Z",
    "LIMIT_SWITCH_Z",
    "STEPSBACKATLIMIT",
    "BANNER",
    "BAUD_RATE",
    "DELAY_UNIT_NS",
    "DEBOUNCE_NS",
    "SWITCH_NAMES",
    "BYTE_NAMES",
    "PORT_B",
    "PORT_D",
    "MODE_X",
    "STEP_X",
    "DIR_X",
    "ENABLE_X",
    "MODE_Y",
    "STEP_Y",
    "DIR_Y",
    "ENABLE_Y",
    "MODE_Z",
    "STEP_Z",
    "DIR_Z",
    "ENABLE_Z",
    "SPINDLE_BIT",
    "POWER_UP_B",
    "POWER_UP_D",
    "AXIS_PINS",
    "STEP_PIN",
]

# --- Protocol bytes: seed 000, Appendix 1, "#define ISMACHINEREADY 0x61 // Byte definitions" block.
ISMACHINEREADY = 0x61
MACHINEREADY = 0x62
OPENJOGMODE = 0x63
JOGMODEON = 0x64
JOGMODEOFF = 0x65
JOGMODEDONE = 0x66
OPENDRILLMODE1 = 0x67
DRILLMODE1ON = 0x68
ONEHOLEDRILLED = 0x69
DRILLMODE1INITIALIZED = 0x6A
DRILLMODE1DONE = 0x70
OPENDRILLMODE2 = 0x71
DRILLMODE2ON = 0x72
DRILLMODE2OFF = 0x73
DRILLMODE2DONE = 0x74
ATOFFSETPOS = 0x75
EMERGENCYSTOP = 0x80
MACHINESTOPPED = 0x81
ERRORLIMITSWITCH = 0x90

# --- Switch bytes: seed 000, Appendix 1, "#define HOME_SWITCH_X 0x01 // Define outgoing bytes for" block.
# Switch byte 1 << k is the switch on port A bit k (isr_ext: "case 0x3E: // RA0=0" ... "case 0x1F: // RA5=0").
HOME_SWITCH_X = 0x01
LIMIT_SWITCH_X = 0x02
HOME_SWITCH_Y = 0x04
LIMIT_SWITCH_Y = 0x08
HOME_SWITCH_Z = 0x10
LIMIT_SWITCH_Z = 0x20

STEPSBACKATLIMIT = 700  # seed 000, Appendix 1: "#define STEPSBACKATLIMIT 700 // Move 700 steps in limit switch interrupt"
BANNER = b"MAXIMUS_V1.0"  # seed 000, Appendix 1, main(): printf("MAXIMUS_V1.0");
BAUD_RATE = 115200  # seed 000, Appendix 1: "#use rs232(baud=115200, xmit=PIN_C6, rcv=PIN_C7)"
DELAY_UNIT_NS = 100_000  # seed 000, Appendix 1, dly_100us(): "Delay for n * 100us"; constspeed(): "Frequency = 1/(2*delay*100us)"
DEBOUNCE_NS = 300_000_000  # seed 000, Appendix 1, isr_ext(): "delay_ms(300); // debounce button"

SWITCH_NAMES = {
    HOME_SWITCH_X: "HOME_SWITCH_X", LIMIT_SWITCH_X: "LIMIT_SWITCH_X",
    HOME_SWITCH_Y: "HOME_SWITCH_Y", LIMIT_SWITCH_Y: "LIMIT_SWITCH_Y",
    HOME_SWITCH_Z: "HOME_SWITCH_Z", LIMIT_SWITCH_Z: "LIMIT_SWITCH_Z",
}
BYTE_NAMES = {
    ISMACHINEREADY: "ISMACHINEREADY", MACHINEREADY: "MACHINEREADY", OPENJOGMODE: "OPENJOGMODE",
    JOGMODEON: "JOGMODEON", JOGMODEOFF: "JOGMODEOFF", JOGMODEDONE: "JOGMODEDONE",
    OPENDRILLMODE1: "OPENDRILLMODE1", DRILLMODE1ON: "DRILLMODE1ON", ONEHOLEDRILLED: "ONEHOLEDRILLED",
    DRILLMODE1INITIALIZED: "DRILLMODE1INITIALIZED", DRILLMODE1DONE: "DRILLMODE1DONE",
    OPENDRILLMODE2: "OPENDRILLMODE2", DRILLMODE2ON: "DRILLMODE2ON", DRILLMODE2OFF: "DRILLMODE2OFF",
    DRILLMODE2DONE: "DRILLMODE2DONE", ATOFFSETPOS: "ATOFFSETPOS", EMERGENCYSTOP: "EMERGENCYSTOP",
    MACHINESTOPPED: "MACHINESTOPPED", ERRORLIMITSWITCH: "ERRORLIMITSWITCH", **SWITCH_NAMES,
}

# --- Pins: seed 000, Appendix 1, "#define MODE_X PIN_D0 // PIC pin definitions" ... "#define SPINDLE_BIT PIN_B2".
PORT_B = ord("B")
PORT_D = ord("D")
MODE_X, STEP_X, DIR_X, ENABLE_X = (PORT_D, 0), (PORT_D, 1), (PORT_D, 2), (PORT_D, 3)
MODE_Y, STEP_Y, DIR_Y, ENABLE_Y = (PORT_D, 4), (PORT_D, 5), (PORT_D, 6), (PORT_D, 7)
MODE_Z, STEP_Z, DIR_Z, ENABLE_Z = (PORT_B, 4), (PORT_B, 5), (PORT_B, 6), (PORT_B, 7)
SPINDLE_BIT = (PORT_B, 2)
POWER_UP_B = 0xF0  # seed 000, Appendix 1, main(): output_b(0xF0); // Set all Driver Pins
POWER_UP_D = 0xFF  # seed 000, Appendix 1, main(): output_d(0xFF);

# (port, step bit, dir bit, enable bit, sign of a step when DIR is 1) per axis x, y, z.
AXIS_PINS = (
    (PORT_D, 1, 2, 3, +1),
    (PORT_D, 5, 6, 7, +1),
    (PORT_B, 5, 6, 7, -1),  # DIR_Z = 1 is "Z down" (Appendix 1, DRILL_MODE1_INPUT)
)
STEP_PIN = {1: STEP_X, 2: STEP_Y, 3: STEP_Z}  # constspeed(..., pin): 1 = X, 2 = Y, 3 = Z
