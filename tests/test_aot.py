"""The ahead-of-time kernels (cam/_compiled.py, cam/_aot.py; issue #17 point 2, cold start).

The install compiles the kernels; these tests check that a first run with an
empty numba cache then compiles nothing, that the ahead-of-time kernels give
exactly what numba's JIT gives, and that a call they were not built for, or a
build from other sources, never reaches them.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cam import _compiled
from cam._aot import sample_commands, type_expr

ROOT = Path(__file__).resolve().parents[1]
NOTE = "preparing compiled kernels, first run only"


def _built() -> bool:
    import cam.digitize._kernels  # noqa: F401 - loads the table

    return _compiled.aot_status().startswith("built")


needs_build = pytest.mark.skipif("not _built()", reason="the ahead-of-time kernels are not built here "
                                                        "(pip install -e . builds them)")


def _run(argv: list[str], tmp_path: Path, **env_extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    env.update(env_extra)
    return subprocess.run([sys.executable, "-m", "cam", *argv], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=600, input="\n" * 50)


@pytest.mark.packaging
def test_the_install_built_the_kernels_for_these_sources():
    """pip install builds them (setup.py); without them every first run compiles for 10-30 s. After editing a
    kernel module, rebuild with: python -m cam._aot build (a machine without a C compiler fails here on
    purpose: cam still runs, on numba's JIT)."""
    if os.environ.get("CAM_NO_AOT"):
        pytest.skip("CAM_NO_AOT is set")
    assert _built(), _compiled.aot_status()


@needs_build
@pytest.mark.packaging
def test_first_run_of_every_sample_kind_compiles_nothing(tmp_path):
    """Every sample command with an empty numba cache: no compile (numba reports each one, and the CLI then
    prints its note). A failure here means a kernel's argument types changed: run python -m cam._aot collect."""
    for argv in sample_commands(tmp_path):
        done = _run(argv, tmp_path)
        assert done.returncode == 0, done.stderr[-800:]
        assert NOTE not in done.stderr, f"cam {' '.join(argv)} compiled a kernel: python -m cam._aot collect"
    assert not list((tmp_path / "numba-cache").rglob("*.nbi"))


@needs_build
@pytest.mark.packaging
def test_ahead_of_time_pin_logs_equal_the_jit_ones(tmp_path):
    """The README's job, a drill file and an HPGL file give byte-identical pin logs both ways."""
    samples = ROOT / "samples"
    for name, extra in (("ellipse.png", ["--depth", "5"]), ("board.drl", ["--yes"]),
                        ("seed_tools.plt", ["--yes"]), ("disc.png", ["--depth", "4"])):
        logs = []
        for off in ("", "1"):
            log = tmp_path / f"{name}-{off or 'aot'}.csv"
            done = _run(["drill", str(samples / name), *extra, "--pin-log", str(log)], tmp_path,
                        **({"CAM_NO_AOT": off, "NUMBA_CACHE_DIR": str(tmp_path / "jit")} if off else {}))
            assert done.returncode == 0, done.stderr[-800:]
            logs.append(log.read_bytes())
        assert logs[0] == logs[1], name


@needs_build
def test_a_call_with_other_types_goes_to_the_jit():
    """The ahead-of-time code does not check types: a call it was not built for must take numba's dispatcher
    (same result, no crash)."""
    from cam.digitize._kernels import pad_mask_kernel

    assert isinstance(pad_mask_kernel, _compiled._Kernel)
    image = (np.arange(30).reshape(5, 6) % 3 == 0).astype(np.uint8)
    flat_c, scan_c = pad_mask_kernel(image, np.uint8(1))
    # int32 image: not a built variant; a Fortran-ordered one neither
    flat_i, scan_i = pad_mask_kernel(image.astype(np.int32), np.int32(1))
    flat_f, scan_f = pad_mask_kernel(np.asfortranarray(image), np.uint8(1))
    assert np.array_equal(scan_c, scan_i) and np.array_equal(scan_c, scan_f)
    assert np.array_equal(flat_c, flat_f)
    from numba import typeof

    key = (str(typeof(image.astype(np.int32))), "int32")
    assert key not in pad_mask_kernel._table


def test_a_build_from_other_sources_is_not_used(tmp_path, monkeypatch):
    """The manifest's digest must equal the digest of the kernel sources on disk."""
    manifest = tmp_path / _compiled.MANIFEST
    manifest.write_text('{"digest": "0000", "kernels": {}}')
    monkeypatch.setattr(_compiled, "_ROOT", tmp_path)
    monkeypatch.setattr(_compiled, "_TABLE", None)
    monkeypatch.setattr(_compiled, "source_digest", lambda: "1111")
    assert _compiled._load() == {}
    assert _compiled.aot_status().startswith("stale")


def test_a_build_for_another_cpu_is_not_used(tmp_path, monkeypatch):
    """The module is compiled for the installing machine's instruction set: another CPU must not load it."""
    manifest = tmp_path / _compiled.MANIFEST
    manifest.write_text('{"digest": "1111", "cpu": "pentium4 +sse2", "kernels": {}}')
    monkeypatch.setattr(_compiled, "_ROOT", tmp_path)
    monkeypatch.setattr(_compiled, "_TABLE", None)
    monkeypatch.setattr(_compiled, "source_digest", lambda: "1111")
    assert _compiled._load() == {}
    assert _compiled.aot_status().startswith("built for another CPU")


def test_no_build_means_the_jit(tmp_path, monkeypatch):
    monkeypatch.setattr(_compiled, "_ROOT", tmp_path)
    monkeypatch.setattr(_compiled, "_TABLE", None)
    assert _compiled._load() == {}
    assert _compiled.aot_status().startswith("not built")
    monkeypatch.setattr(_compiled, "_TABLE", None)
    monkeypatch.setenv("CAM_NO_AOT", "1")
    assert _compiled.aot_status().startswith("turned off")


def test_signature_table_covers_every_kernel_and_round_trips():
    """Every kernel Python calls is in the table, and each type written there evaluates back to itself."""
    import numba.core.types as nbtypes

    from cam._aot import _load_kernels
    from cam._aot_signatures import SIGNATURES

    _load_kernels()
    assert set(SIGNATURES) == set(_compiled.ENTRIES)
    used = [q for q, sigs in SIGNATURES.items() if sigs]
    assert len(used) >= 20
    for sigs in SIGNATURES.values():
        for expr in sigs:
            types = eval(expr, dict(vars(nbtypes)))  # noqa: S307 - the generated table
            assert "(" + "".join(type_expr(t) + ", " for t in types) + ")" == expr


def test_type_keys_are_numbas_names():
    """The guard names argument types itself (numba's typeof interns a type on every call); its names must be
    exactly numba's, which the build wrote into the manifest."""
    from numba import typeof

    a = np.arange(12, dtype=np.int64).reshape(3, 4)
    ro = np.zeros(5, np.uint8)
    ro.flags.writeable = False
    values = [a, a.T, a[:, ::2], a[0], np.zeros(3, bool), np.zeros((2, 2), np.float64), ro, np.zeros(1, np.int32),
              True, 3, 2.5, np.int64(4), np.uint8(1), np.float64(1.5), np.bool_(True), np.int32(2)]
    for v in values:
        assert _compiled.type_key(v) == str(typeof(v)), v
    assert _compiled.type_key("text") is None
