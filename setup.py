"""Install hook: compile cam's numba kernels ahead of time, so a first run compiles nothing.

Everything else about the package is in pyproject.toml.  The kernels are built
by ``python -m cam._aot build`` (see cam/_compiled.py for why ahead of time);
when that fails (no C compiler, a numba without ``numba.pycc``) the install
still succeeds and numba compiles the kernels on first use instead.
"""
import os
import subprocess
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


class BuildWithKernels(build_py):
    """build_py, then the ahead-of-time kernels into the package (the source tree for an editable install)."""

    def run(self) -> None:
        super().run()
        editable = getattr(self, "editable_mode", False)
        out_dir = ROOT / "cam" if editable else Path(self.build_lib) / "cam"
        # ROOT first, then pip's own PYTHONPATH: in an isolated build that is what makes the build's
        # requirements (numba, numpy, and what cam imports) visible to the child process
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                                          if p))
        print(f"cam: compiling kernels ahead of time into {out_dir} (about a minute)", file=sys.stderr)
        done = subprocess.run([sys.executable, "-m", "cam._aot", "build", "--out", str(out_dir)], cwd=ROOT,
                              env=env, check=False)
        if done.returncode != 0:
            print("cam: WARNING: the ahead-of-time kernels could not be built; numba compiles them on first use",
                  file=sys.stderr)


class BinaryDistribution(Distribution):
    """The package holds a compiled extension module: its wheel is platform specific."""

    def has_ext_modules(self) -> bool:
        return True


setup(cmdclass={"build_py": BuildWithKernels}, distclass=BinaryDistribution)
