"""``python -m cam``: see :mod:`cam.cli`."""
import sys

from .cli import main_process

if __name__ == "__main__":
    sys.exit(main_process())
