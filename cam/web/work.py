"""The web server's heavy work, as functions its :class:`~cam.worker.Worker` process runs.

Nothing here imports the web packages: the worker process imports this module
and the planners, never Starlette.  The pin log crosses between the processes
as a raw file (:func:`save_pin_log_raw`, written with the interpreter lock
released) rather than through a pipe.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..drive.journal import read_journal
from ..drive.maximus.resume import resume_board_job
from ..drive.probing import job_cuts_mm
from ..job.heightmap_level import load_height_map
from ..kinds.jobs import JobOptions, PreparedJob, prepare_job, resume_job
from ..job.map_picture import height_map_picture
from ..render.picture import encode_png
from ..settings import MachineSettings
from ..verify.pinlog import PinLog, PinLogPart, write_pin_log

__all__ = ["plan_with_preview", "preview_of", "height_map_png", "resumed_from_journal",
           "save_pin_log_raw", "pin_log_csv", "WARM_UP"]

WARM_UP = ("cam.kinds.jobs", "cam.web.work", "cam.digitize._kernels", "cam.motion.ramps", "cv2")
"""What the worker imports as it starts: the first planning does not wait for it."""


def plan_with_preview(path: str, options: JobOptions, settings: MachineSettings,
                      name: str, machine_state: Any = None) -> tuple[PreparedJob, bytes]:
    """Plan an uploaded file and draw its preview: ``(job, PNG bytes)`` (in the worker).  ``machine_state``: the
    session's :class:`~cam.drive.state.MachineState` (a G-code program, or a file placed by its own zero, is
    planned from the work zero in the machine frame, as ``cam drill`` plans it)."""
    job = prepare_job(path, options, settings, name=name, machine_state=machine_state)
    return job, job.preview_png()


def resumed_from_journal(job: PreparedJob, journal_path: str, position_steps: tuple[int, int, int]) -> PreparedJob:
    """The page's job resumed after the stop its journal records, from where the tool stands (in the worker):
    :func:`cam.kinds.jobs.resume_job`, the function ``cam drill --resume`` calls (a MAXIMUS board job's journal:
    :func:`~cam.drive.maximus.resume.resume_board_job`, on from the next hole)."""
    journal = read_journal(journal_path)
    if journal.holes_done is not None:
        return resume_board_job(job, journal, where=Path(journal_path).name)
    return resume_job(job, journal, position_steps=position_steps, where=Path(journal_path).name)


def preview_of(job: PreparedJob) -> bytes:
    """The PNG preview of a planned job (in the worker)."""
    return job.preview_png()


def height_map_png(map_path: str, job: Any, machine_state: Any, settings: MachineSettings) -> bytes:
    """The PNG of the height map at ``map_path`` (:func:`cam.job.map_picture.height_map_picture`) with ``job``'s
    cuts over it where it would run in ``machine_state`` (:func:`cam.drive.probing.job_cuts_mm`; None: the map
    alone), as ``cam preview MAP.json --over FILE`` draws it (in the worker)."""
    cuts = None if job is None else job_cuts_mm(job, machine_state, settings)
    return encode_png(height_map_picture(load_height_map(map_path), cuts_mm=cuts))


def save_pin_log_raw(log: PinLog, path: str | os.PathLike) -> None:
    """Write a pin log's three arrays, one after the other, as ``.npy`` records (the server's side), then its parts
    (the travel to the work zero, the job: :class:`~cam.verify.pinlog.PinLogPart`) as two more: their names and
    ``(first row, x, y, z, t0_ns)``.

    ``numpy`` writes each array's bytes with the interpreter lock released, so the step runner's
    thread is not held up however long the log.
    """
    with open(path, "wb") as handle:
        for values in (log.t_ns, log.data, log.strobe):
            np.save(handle, np.ascontiguousarray(values), allow_pickle=False)
        np.save(handle, np.array([p.name for p in log.parts], dtype="U16"), allow_pickle=False)
        np.save(handle, np.array([(p.first_row, *p.start_steps, p.t0_ns) for p in log.parts], np.int64).reshape(-1, 5),
                allow_pickle=False)


def pin_log_csv(raw_path: str, csv_path: str) -> str:
    """Read a raw pin log of :func:`save_pin_log_raw` and write its CSV (in the worker); returns ``csv_path``."""
    with open(raw_path, "rb") as handle:
        t_ns, data, strobe, names, marks = (np.load(handle, allow_pickle=False) for _ in range(5))
    parts = tuple(PinLogPart(str(n), int(m[0]), (int(m[1]), int(m[2]), int(m[3])), int(m[4]))
                  for n, m in zip(names, marks))
    write_pin_log(PinLog(t_ns, data, strobe, parts), csv_path)
    Path(raw_path).unlink(missing_ok=True)
    return csv_path
