"""Pin logs as bytes, for tests that compare two runs byte for byte."""
from pathlib import Path

import numpy as np

from cam.drive.ports import MockPort
from cam.drive.runner import run


def pin_log_bytes(job, tmp_path: Path, name: str) -> bytes:
    """Run ``job`` on a mock streaming its pin log to ``tmp_path / name``: the log's arrays and the CSV's bytes."""
    path = tmp_path / name
    result = run(job, MockPort(pin_log_path=path), on_pause=lambda *a: None)
    assert result.status == "finished"
    log = result.pin_log()
    return b"".join(np.ascontiguousarray(a).tobytes() for a in (log.t_ns, log.data, log.strobe)) + path.read_bytes()
