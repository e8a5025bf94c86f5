"""A part of :class:`~cam.drive.session.MachineSession`: the pin logs of the last job on the mock (issue #44 point 4).

:class:`SessionPinLogs` keeps the mock ports of the last job and of the travel to its work zero (the runs hold
their writes: bounded memory) and reads them when asked: :attr:`~SessionPinLogs.last_job_pin_log` the job's writes
alone, :attr:`~SessionPinLogs.last_pin_log` every write of it, the travel too, each part marked
(:class:`~cam.verify.pinlog.PinLogPart`).  It works on the attributes ``MachineSession.__init__`` sets (``_lock``,
``settings``, ``_last_job_port``, ``_last_job_log``, ``_last_pin_log``, ``_last_job_parts``, ``_travel_port``).
"""
from __future__ import annotations

from typing import Any, Optional

from ..verify.pinlog import PinLog, PinLogPart, join_pin_logs

__all__ = ["SessionPinLogs"]


class SessionPinLogs:
    """The last job's pin logs on the mock (a mixin; see the module)."""

    @property
    def last_job_pin_log(self) -> Any:
        """The pin log of the last job run on the mock port (a :class:`~cam.verify.pinlog.PinLog`, read from the
        port when first asked: the run itself holds no more than the mock's bounded buffer), or None: the job's
        writes alone, its one part ``job`` saying where it started (machine frame).  :attr:`last_pin_log` holds
        the travel to its work zero too."""
        with self._lock:
            if self._last_job_log is None and self._last_job_port is not None:
                log, start = self._last_job_port.pin_log(), self._last_job_parts[-1][2]
                self._last_job_log = PinLog(log.t_ns, log.data, log.strobe, (PinLogPart("job", 0, start, 0),))
            return self._last_job_log

    @property
    def last_pin_log(self) -> Any:
        """Every write of the last job on the mock port (the page's pin log): the travel to the work zero that
        placed it (part ``travel``, when it travelled) and the job (part ``job``:
        :meth:`~cam.verify.pinlog.PinLog.part` takes it alone), on one time line; or None.  One object per job."""
        with self._lock:
            job = self.last_job_pin_log
            if job is None or len(self._last_job_parts) == 1:
                return job
            if self._last_pin_log is None:
                gap_ns = int(max(self.settings.delay_xy_ns, self.settings.delay_z_ns))  # a step period between
                travel = [(name, port.pin_log(), start) for name, port, start in self._last_job_parts[:-1]]
                self._last_pin_log = join_pin_logs(travel + [("job", job, job.parts[0].start_steps)], gap_ns)
            return self._last_pin_log

    def _book_pin_log(self, activity: Optional[str], pin_log: Any, start: tuple[int, int, int],
                      travel_to_job: bool) -> None:
        """An activity ended (under the lock): keep a job's mock (``pin_log``, None off the mock) with the travel's
        before it; ``travel_to_job``: this one travelled to the work zero of a job that starts next."""
        if activity == "job":
            if pin_log is not None:
                self._last_job_port, self._last_job_log, self._last_pin_log = pin_log, None, None
                travel = [("travel", *self._travel_port)] if self._travel_port is not None else []
                self._last_job_parts = travel + [("job", pin_log, start)]
            self._travel_port = None
        elif pin_log is not None and travel_to_job:
            self._travel_port = (pin_log, start)
        else:
            self._travel_port = None
