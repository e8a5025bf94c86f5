"""The pin log's CSV rows are formatted by a compiled kernel; they must be the text np.savetxt writes."""
import io

import numpy as np

from cam.motion.kernels import pin_rows_kernel


def test_pin_rows_are_the_text_savetxt_writes():
    rng = np.random.default_rng(3)
    t = np.concatenate([[0, 1, 9, 10, 11, 99, 100, 101, 999, 1000, 10**9, 10**18 - 1, 2**62],
                        np.sort(rng.integers(0, 10**15, 5000))]).astype(np.int64)
    data = rng.integers(0, 256, len(t)).astype(np.int64)
    data[:4] = (0, 9, 10, 255)
    strobe = rng.integers(0, 2, len(t)).astype(np.int64)
    want = io.StringIO()
    np.savetxt(want, np.stack([t, data, strobe], axis=1), fmt="%d", delimiter=",")
    assert pin_rows_kernel(t, data, strobe).tobytes().decode("ascii") == want.getvalue()
