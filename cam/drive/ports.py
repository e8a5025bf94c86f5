"""Ports opened by name: the logging mock (default) and the real PC parallel port.

* ``"mock"`` -- the thesis's Debug Mode: nothing leaves the PC; every write is
  logged as ``(t_ns, data, strobe)``.  It ships in the library so that every
  job can run, and be checked, with no hardware.
* a device path such as ``"/dev/parport0"`` -- the real port through
  pyparallel (the optional ``cam[parport]`` extra), imported only when such
  a port is opened.

The port only writes; *when* to write is the runner's business.
"""
from __future__ import annotations

import numpy as np

from ..errors import PortError
from ..verify.pinlog import PinLog

__all__ = ["Port", "MockPort", "ParallelPort", "open_port"]


class Port:
    """A place to send data-register and strobe writes to."""

    name = "port"

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        """Set the data register and pin 1; ``t_ns`` is the job time of the write."""
        raise NotImplementedError

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        """Send a batch of writes in order (used by the simulated clock)."""
        for t, d, s in zip(t_ns.tolist(), data.tolist(), strobe.tolist()):
            self.write(d, s, t)

    def close(self) -> None:
        """Release the port."""

    def __enter__(self) -> "Port":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class MockPort(Port):
    """The logging mock port.  :meth:`pin_log` returns everything written so far."""

    name = "mock"

    def __init__(self) -> None:
        self._t: list[np.ndarray] = []
        self._d: list[np.ndarray] = []
        self._s: list[np.ndarray] = []
        self._pending: list[tuple[int, int, int]] = []

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        self._pending.append((int(t_ns), int(data), int(strobe)))

    def write_many(self, t_ns: np.ndarray, data: np.ndarray, strobe: np.ndarray) -> None:
        self._flush()
        self._t.append(np.asarray(t_ns, np.int64).copy())
        self._d.append(np.asarray(data, np.uint8).copy())
        self._s.append(np.asarray(strobe, np.uint8).copy())

    def _flush(self) -> None:
        if self._pending:
            arr = np.array(self._pending, np.int64)
            self._pending = []
            self._t.append(arr[:, 0])
            self._d.append(arr[:, 1].astype(np.uint8))
            self._s.append(arr[:, 2].astype(np.uint8))

    def pin_log(self) -> PinLog:
        """Every write so far, in order."""
        self._flush()
        if not self._t:
            return PinLog(np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros(0, np.uint8))
        return PinLog(np.concatenate(self._t), np.concatenate(self._d), np.concatenate(self._s))


class ParallelPort(Port):
    """The PC parallel port through pyparallel (Linux ppdev, e.g. ``/dev/parport0``)."""

    def __init__(self, device: str) -> None:
        self.name = device
        try:
            import parallel  # pyparallel, the optional [parport] extra: imported only when a real port is opened
        except ImportError:
            raise PortError(f"{device}: the parallel port needs pyparallel: pip install 'cam[parport]'") from None
        try:
            self._port = parallel.Parallel(port=device)
        except FileNotFoundError:
            raise PortError(
                f"{device}: no such parallel port (load the driver: 'sudo modprobe ppdev'; list ports: ls /dev/parport*)"
            ) from None
        except PermissionError:
            raise PortError(
                f"{device}: permission denied (add yourself to the 'lp' group: 'sudo usermod -aG lp $USER', then log in again)"
            ) from None
        except OSError as exc:
            raise PortError(f"{device}: cannot open the parallel port ({exc.strerror or exc})") from None

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        try:
            self._port.setData(int(data))
            self._port.setDataStrobe(int(strobe))
        except OSError as exc:  # pragma: no cover - hardware
            raise PortError(f"{self.name}: write failed ({exc.strerror or exc})") from None

    def close(self) -> None:  # pragma: no cover - hardware
        port = getattr(self, "_port", None)
        if port is not None:
            try:
                port.setData(0)
            finally:
                del self._port


def open_port(name: str | Port = "mock") -> Port:
    """Open a port by name: ``"mock"`` or a device path (``/dev/parport0``).  A Port passes through."""
    if isinstance(name, Port):
        return name
    if name == "mock":
        return MockPort()
    if name.startswith("/dev/"):
        return ParallelPort(name)
    if name.startswith("maximus:"):
        raise PortError(f"'{name}': the MAXIMUS board takes drill files (Excellon) and jogs only, not step/dir jobs")
    raise PortError(f"unknown port '{name}' (use 'mock' or a device path such as /dev/parport0)")
