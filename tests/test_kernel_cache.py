"""The kernels' cache and the pure-Python install (cam/_compiled.py, cam/_kernel_cache.py; issue #48 point 5).

Nothing is compiled at install: ``pip wheel .`` gives one ``py3-none-any``
wheel with no extension module in it, and a machine's first run compiles the
kernels it uses into numba's on-disk cache (``~/.cache/cam/numba`` unless
``NUMBA_CACHE_DIR`` is set), saying so once on stderr; later runs load them
from there and compile nothing.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cam import _compiled
from cam._compiled import load_kernels
from cam._kernel_cache import sample_commands, type_expr

ROOT = Path(__file__).resolve().parents[1]
NOTE = "first run only"
README_JOB = ["drill", str(ROOT / "samples" / "ellipse.png"), "--depth", "5"]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(ROOT)
    env.update(extra)
    return env


def _run(argv: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cam", *argv], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=900, input="\n" * 50)


def _snapshot(folder: Path) -> dict[str, tuple[int, str]]:
    """Every file under ``folder`` -> (mtime in ns, sha256 of its bytes)."""
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(folder.rglob("*")) if p.is_file()}


# -- where the cache is ---------------------------------------------------------------------------------------


def test_the_cache_defaults_to_a_folder_of_the_users(tmp_path, monkeypatch):
    """No NUMBA_CACHE_DIR: cam's folder under XDG_CACHE_HOME (~/.cache without it), made if missing, and put in
    the environment so worker processes share it."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _compiled.use_cache_dir() == tmp_path / "xdg" / "cam" / "numba"
    assert (tmp_path / "xdg" / "cam" / "numba").is_dir()
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "xdg" / "cam" / "numba")
    assert _compiled.cache_dir() == tmp_path / "xdg" / "cam" / "numba"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert _compiled.default_cache_dir() == tmp_path / "home" / ".cache" / "cam" / "numba"


def test_numba_cache_dir_wins(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "given"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _compiled.use_cache_dir() == tmp_path / "given"
    assert not (tmp_path / "xdg").exists()


def test_a_cache_folder_that_cannot_be_made_leaves_numbas_own_choice(tmp_path, monkeypatch):
    """A read-only home: numba then caches next to the sources, or in ~/.cache/numba, or warns; cam still runs."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))
    assert _compiled.use_cache_dir() is None
    assert "NUMBA_CACHE_DIR" not in os.environ
    assert _compiled.cache_dir() is None


def test_every_kernel_is_cached_by_numba():
    """Every kernel Python calls is ``cache=True`` (else each run would compile it again)."""
    load_kernels()
    assert len(_compiled.ENTRIES) >= 20
    for qualname, dispatcher in _compiled.ENTRIES.items():
        assert dispatcher._cache.__class__.__name__ == "FunctionCache", qualname


def test_signature_table_covers_every_kernel_and_round_trips():
    """Every kernel Python calls is in the table, and each type written there evaluates back to itself."""
    import numba.core.types as nbtypes

    from cam._kernel_signatures import SIGNATURES

    load_kernels()
    assert set(SIGNATURES) == set(_compiled.ENTRIES)
    used = [q for q, sigs in SIGNATURES.items() if sigs]
    assert len(used) >= 20
    for sigs in SIGNATURES.values():
        for expr in sigs:
            types = eval(expr, dict(vars(nbtypes)))  # noqa: S307 - the generated table
            assert "(" + "".join(type_expr(t) + ", " for t in types) + ")" == expr


# -- a first run, a second run --------------------------------------------------------------------------------


@pytest.mark.packaging
def test_the_first_run_fills_a_fresh_cache_and_the_second_reuses_it(tmp_path):
    """The README's first command with an empty cache (no NUMBA_CACHE_DIR: cam's folder under XDG_CACHE_HOME):
    one note on stderr, the kernels written there; the same command again: no note, and numba's index and data
    files are the very same files (nothing compiled, nothing rewritten)."""
    env = _env(XDG_CACHE_HOME=str(tmp_path / "xdg"))
    cache = tmp_path / "xdg" / "cam" / "numba"
    first = _run([*README_JOB, "--pin-log", str(tmp_path / "first.csv")], tmp_path, env)
    assert first.returncode == 0, first.stderr[-800:]
    notes = [line for line in first.stderr.splitlines() if NOTE in line]
    assert len(notes) == 1 and str(cache) in notes[0], first.stderr[-800:]
    filled = _snapshot(cache)
    assert any(name.endswith(".nbi") for name in filled) and any(name.endswith(".nbc") for name in filled)
    second = _run([*README_JOB, "--pin-log", str(tmp_path / "second.csv")], tmp_path, env)
    assert second.returncode == 0, second.stderr[-800:]
    assert NOTE not in second.stderr
    assert _snapshot(cache) == filled
    assert (tmp_path / "first.csv").read_bytes() == (tmp_path / "second.csv").read_bytes()


@pytest.mark.packaging
def test_after_compile_no_sample_kind_compiles(tmp_path):
    """``python -m cam._kernel_cache compile`` fills a fresh cache with the table's kernels; then no sample
    command compiles (a failure means a kernel's argument types changed: run python -m cam._kernel_cache
    collect)."""
    env = _env(NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    done = subprocess.run([sys.executable, "-m", "cam._kernel_cache", "compile"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr[-800:]
    assert "already cached" in done.stderr
    for argv in sample_commands(tmp_path):
        run = _run(argv, tmp_path, env)
        assert run.returncode == 0, run.stderr[-800:]
        assert NOTE not in run.stderr, f"cam {' '.join(argv)} compiled a kernel: python -m cam._kernel_cache collect"


# -- the wheel ------------------------------------------------------------------------------------------------


@pytest.mark.packaging
def test_pip_wheel_gives_one_pure_python_wheel(tmp_path):
    """``pip wheel .`` in a copy of the checkout's files (as a clean clone: no build/ folder left by an earlier
    build): one py3-none-any wheel, Root-Is-Purelib, no compiled module in it, the page's files in."""
    source = tmp_path / "src"
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                            capture_output=True, timeout=60)
    if listed.returncode == 0:
        for name in filter(None, listed.stdout.decode().split("\0")):
            if (ROOT / name).is_file():
                (source / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(ROOT / name, source / name)
    else:  # not a git checkout (an unpacked source archive)
        shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns("build", "dist", "*.egg-info", "__pycache__"))
    out = tmp_path / "wheels"
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(source)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=900,
                          env={**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"})
    assert done.returncode == 0, done.stderr[-1500:]
    wheels = sorted(out.glob("*.whl"))
    assert [w.name for w in wheels] == ["cam-0.1.0-py3-none-any.whl"]
    with zipfile.ZipFile(wheels[0]) as whl:
        names = whl.namelist()
        wheel_meta = whl.read("cam-0.1.0.dist-info/WHEEL").decode()
    assert "Root-Is-Purelib: true" in wheel_meta
    assert "Tag: py3-none-any" in wheel_meta
    compiled = [n for n in names if n.endswith((".so", ".pyd", ".dll", ".dylib", ".c"))]
    assert compiled == []
    assert "cam/_compiled.py" in names and "cam/_kernel_signatures.py" in names
    assert "cam/web/static/index.html" in names
    assert not [n for n in names if "_aot" in n]
