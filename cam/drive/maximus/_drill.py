"""Drill mode: the packets of a drill job, checked before anything is sent, and the sessions that send them.

The part of :class:`~cam.drive.maximus.board.MaximusBoard` that drills (its :meth:`drill` documents the
protocol): each tool's holes are one Drill mode session, Offset, Init and SDF packets, one Drill Data Packet per
hole and the closing packet, between tool-change prompts and the head's moves to the start height.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable, Optional, Sequence

import numpy as np

from ...errors import PlanError
from ...settings import Maximus
from ._link import _CLOSE_DRILL, _DRILL, _INIT, _OFFSET, _Exchange
from .packets import (
    MAX_FIELD, close_drill_packet, drill_directions, drill_moved, drill_moves, drill_packet, drill_time_ns, init_packet,
    init_time_ns, offset_packet, offset_time_ns, start_drill_packet,
)
from .protocol import ATOFFSETPOS, DRILLMODE1INITIALIZED, DRILLMODE1ON, ONEHOLEDRILLED, OPENDRILLMODE1


@dataclass(frozen=True)
class _Group:
    """The holes of one tool (or one run of a tool in file order), drilled in one Drill mode session."""

    first: int  # index of its first hole
    notes: list[str]  # tool-change prompts before it
    packets: list[bytes]  # one Drill Data Packet per hole
    moves: np.ndarray  # (n, 2) int64 board-frame dx, dy of each


@dataclass(frozen=True)
class _DrillJob:
    """The packets of one drill job (see :meth:`~cam.drive.maximus.board.MaximusBoard.drill`), checked before
    anything is sent."""

    offset: bytes  # Offset Positioning Packet: Z to where the Init descent ends at Z up
    init: bytes  # Initialize Drill Mode Packet: both fields Z down - Z up
    descent_steps: int  # pulses the Init packet lowers Z
    offset_height_steps: int  # board-frame height move of the offset packet (+ up)
    z_up_steps: int
    groups: list[_Group]
    back_steps: np.ndarray  # (2,) int64 x, y back to the holes' origin after the last hole
    first_number: int = 1  # what messages call the first hole (hole numbers count from 1)

    def number(self, index: int) -> int:
        """The hole number messages give the hole of this job's ``index`` (from 0)."""
        return self.first_number + int(index)


def drill_job(holes_steps: np.ndarray, z_up_steps: int, z_down_steps: int, tool_changes: Sequence[tuple[int, str]] = (),
              settings: Optional[Maximus] = None, *, start_steps: tuple[int, int] = (0, 0),
              first_number: int = 1) -> _DrillJob:
    """The packets of a drill job (see :meth:`~cam.drive.maximus.board.MaximusBoard.drill`), checked: nothing is
    sent.  ``start_steps``: where the head stands, board-frame (x, y) pulses from the holes' origin (the first
    move starts there; the move back ends at the origin); ``first_number``: what messages call the first hole.

    Raises:
        PlanError: a move longer than the 16-bit fields, a bad Z stroke or tool change, an inverted Z.
    """
    m = settings or Maximus()
    if m.invert_z:
        raise PlanError("invert_z cannot apply in Drill mode: the firmware lowers Z with DIR_Z = 1 "
                        "(seed 000 Appendix 1); wire the Z motor the other way round instead")
    start = np.asarray(start_steps, np.int64).reshape(2)
    moves = drill_moves(np.asarray(holes_steps, np.int64).reshape(-1, 2) - start)
    if not 0 <= z_up_steps < z_down_steps <= MAX_FIELD:
        raise PlanError(f"Z drill up {z_up_steps} and down {z_down_steps} pulses below the start: need "
                        f"0 <= up < down <= {MAX_FIELD}")
    stroke_steps = z_down_steps - z_up_steps
    offset_height_steps = stroke_steps - z_up_steps  # the Init descent (the stroke) then ends at -z_up_steps
    if abs(offset_height_steps) > MAX_FIELD:
        raise PlanError(f"Z drill up {z_up_steps} pulses is too far below the start for Z down {z_down_steps}")
    changes: dict[int, list[str]] = {}
    for index, message in tool_changes:
        if not 0 <= int(index) < len(moves):
            raise PlanError(f"tool change before hole {int(index) + first_number}: there are {len(moves)} holes")
        changes.setdefault(int(index), []).append(str(message))
    modes = (m.half_step_x, m.half_step_y, m.half_step_z)
    offset = offset_packet(0, 0, offset_height_steps, delay_x=m.delay_x, delay_y=m.delay_y, delay_z=m.delay_z_up,
                           half_step=modes, invert=(m.invert_x, m.invert_y, m.invert_z))
    init = init_packet(stroke_steps, stroke_steps, delay_x=m.delay_x, delay_y=m.delay_y, delay_z_up=m.delay_z_up,
                       delay_z_down=m.delay_z_down, half_step=modes)
    starts = sorted({0, *changes})
    groups = []
    for a, b in zip(starts, starts[1:] + [len(moves)]):
        part = moves[a:b]
        groups.append(_Group(a, changes.get(a, []), [drill_packet(int(dx), int(dy), invert_x=m.invert_x,
                                                                  invert_y=m.invert_y) for dx, dy in part], part))
    back = -(moves.sum(axis=0) + start)
    return _DrillJob(offset, init, stroke_steps, offset_height_steps, z_up_steps, groups, back, int(first_number))




class _Drilling:
    """Drill mode sessions; the board supplies ``_exchange`` and ``_check_stop`` (:class:`~._link._Link`),
    ``_jog_session`` and ``_move_session``."""

    def _drill_session(self, job: _DrillJob, on_tool_change: Callable[[int, str], None] | None,
                       on_hole: Callable[[int], None] | None, before_hole: Callable[[int], None] | None,
                       spindle: bool, return_to_start: bool) -> int:
        """Every tool's Drill mode session, then the move back; returns the number of holes drilled."""
        drilled = 0
        for group in job.groups:
            for message in group.notes:
                self._check_stop(f"hole {job.number(group.first)}")
                if on_tool_change is not None:
                    on_tool_change(group.first, message)
            self._check_stop(f"hole {job.number(group.first)}")
            if spindle:
                self._jog_session([("z", 0)], spindle=True)
            drilled = self._drill_group(job, group, drilled, on_hole, before_hole)
            self._check_stop(f"raising the head after hole {job.number(drilled - 1)}")
            self._jog_session([("z", job.z_up_steps)])  # spindle bit clear: off as the head rises
        if return_to_start and np.any(job.back_steps):
            self._check_stop("the move back to the start")
            self._move_session(int(job.back_steps[0]), int(job.back_steps[1]), 0)
        return drilled

    def _drill_group(self, job: _DrillJob, group: _Group, drilled: int, on_hole: Callable[[int], None] | None,
                     before_hole: Callable[[int], None] | None) -> int:
        before = f"before hole {job.number(group.first)}"
        self._check_stop(f"Drill mode {before}")
        self._exchange(bytes([OPENDRILLMODE1]), _Exchange(f"OPENDRILLMODE1 {before}", DRILLMODE1ON, False, "drill",
                                                          _OFFSET))
        self._check_stop(f"the offset move {before}")
        self._exchange(job.offset, _Exchange(f"the offset move (Z) {before}", ATOFFSETPOS, True, "drill", _INIT,
                                             offset_time_ns(job.offset), (0, 0, job.offset_height_steps)))
        self._check_stop(f"the Init move {before}")
        self._exchange(job.init, _Exchange(f"the Init move (Z down, not stoppable) {before}", DRILLMODE1INITIALIZED,
                                           False, "drill", _DRILL, init_time_ns(job.init), (0, 0, -job.descent_steps)))
        self._exchange(start_drill_packet(),
                       _Exchange(f"the start (SDF) packet {before}", ONEHOLEDRILLED, False, "drill", _DRILL))
        for k, packet in enumerate(group.packets):
            i = group.first + k
            self._check_stop(f"hole {job.number(i)}")
            if before_hole is not None:
                before_hole(i)
            dx, dy = (int(v) for v in group.moves[k])
            self._exchange(packet, _Exchange(f"hole {job.number(i)}", ONEHOLEDRILLED, True, "drill", _DRILL,
                                             drill_time_ns(packet, job.init), (dx, dy, 0),
                                             partial(drill_moved, dx, dy, job.init, whole=True),
                                             partial(drill_directions, dx, dy, job.init)))
            drilled += 1
            if on_hole is not None:
                on_hole(drilled)
        self._exchange(close_drill_packet(), _CLOSE_DRILL)
        return drilled
