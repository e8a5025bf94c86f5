"""Resuming a MAXIMUS board job after a stop: which holes are left, and the journal checked (computation only).

A board job's journal (:class:`cam.drive.journal.HoleJournal`) is a :class:`~cam.job.resume.Journal` whose moves
are the holes in drilling order: ``holes_done`` of them were answered ONEHOLEDRILLED, ``hole_order`` names the
drill file's hole of each, ``position_steps`` is where the head stood when it was written (steps from the job's
home, `cam`'s frame: y toward the operator, z deeper).  The resumed run (:func:`resumed_arguments`):

1. the head to the start height (a lift: after a stop it may stand lower, in a hole or on the way down);
2. the first Drill Data Packet travels from where the head stands to the first hole not drilled, at the
   travel height, as every hole's packet does; the holes after it follow as planned;
3. the tool of that hole is asked for again (its tool-change prompt): the operator may have changed it;
4. at the end the head goes back to the job's home, as a job from the start does.

A hole whose reply never came (the stop came during its packet) is drilled again: it may have been drilled
part of the way, never twice to the bottom and then recorded.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ...errors import CamError
from ...job.resume import Journal, JournalBase, check_journal, check_journal_numbers

__all__ = ["resume_board_job", "resumed_arguments", "holes_left"]


def resume_board_job(job: Any, journal: Journal, where: str = "journal") -> Any:
    """The prepared drill job ``job`` (planned again with the same file, options and settings) resumed after the
    stop its board journal records: ``job.resumed`` says how many holes were drilled and where the head stands.

    Raises:
        CamError: one line naming ``where``: a step/dir job's journal, another file, options, settings or hole
            order, a finished job, or numbers no run on this machine could have written.
    """
    check_journal_numbers(journal, job.settings, where)
    check_journal(journal, job.identity, job.plan_sha256, where, board=True)
    done = int(journal.holes_done or 0)
    plan = getattr(job, "drill_plan", None)
    if plan is None:
        raise CamError(f"journal {where}: {job.name} has no holes to drill on the board")
    order = tuple(int(v) for v in np.asarray(plan.hole_index, np.int64).tolist())
    if journal.hole_order is not None and tuple(journal.hole_order) != order:
        raise CamError(f"journal {where} was written for another order of the holes (--drill-order?); run the "
                       f"same file with the same options, or start the job again without --resume")
    if done > len(order):
        raise CamError(f"journal {where}: holes_done {done} is more than the job's {len(order)} holes")
    base = JournalBase(identity=job.identity, plan_sha256=job.plan_sha256, source=job.source, moves=len(order),
                       last_move=done - 1, resumed_at_move=done,
                       start_position_steps=tuple(int(v) for v in journal.position_steps))  # type: ignore[arg-type]
    report = dict(job.report)
    report.update(resumed_at_hole=done + 1, resumed_at_move=done,
                  start_position_steps=list(journal.position_steps),
                  resumed_from_state=journal.state)
    extent = np.asarray(job.extent_steps, np.int64) - np.asarray(base.start_position_steps, np.int64)[:, None]
    return dataclasses.replace(job, resumed=base, report=report, extent_steps=extent,
                               summary=f"{job.summary}, resumed at hole {done + 1} of {len(order)}")


def holes_left(job: Any) -> tuple[int, tuple[int, int, int]]:
    """``(holes done, where the head stands)`` when a run of ``job`` starts: ``(0, (0, 0, 0))`` from the start,
    else what its journal said (:func:`resume_board_job`); positions in steps from the job's home."""
    base = getattr(job, "resumed", None)
    if base is None:
        return 0, (0, 0, 0)
    return int(base.last_move) + 1, tuple(int(v) for v in base.start_position_steps)  # type: ignore[return-value]


def resumed_arguments(arguments: dict[str, Any], holes_done: int,
                      start_steps: tuple[int, int, int]) -> tuple[dict[str, Any], int]:
    """The :meth:`~cam.drive.maximus.board.MaximusBoard.drill` arguments of the holes after the first
    ``holes_done`` (those of :func:`~cam.drive.maximus.board.drill_arguments`), from ``start_steps`` (`cam`'s
    frame, steps from the job's home), and the board-frame height move that first brings the head to the start
    height (+ up; 0: it is there).

    >>> args = {"holes_steps": np.array([[10, 0], [20, 0], [30, 0]]), "tool_changes": [(0, "T1"), (2, "T2")]}
    >>> run, lift = resumed_arguments(args, 1, (15, 0, 40))
    >>> run["holes_steps"].tolist(), run["tool_changes"], run["start_steps"], run["first_number"], lift
    ([[20, 0], [30, 0]], [(0, 'T1'), (1, 'T2')], (15, 0), 2, 40)
    """
    k = int(holes_done)
    changes = [(int(i) - k, note) for i, note in arguments["tool_changes"] if int(i) >= k]
    before = [note for i, note in arguments["tool_changes"] if int(i) < k]
    holes = np.asarray(arguments["holes_steps"], np.int64).reshape(-1, 2)[k:]
    if before and len(holes) and not any(i == 0 for i, _ in changes):  # the tool of the first hole left, again
        changes.insert(0, (0, before[-1]))
    x, y, z = (int(v) for v in start_steps)
    out = dict(arguments, holes_steps=holes, tool_changes=changes, start_steps=(x, -y), first_number=k + 1)
    return out, z
