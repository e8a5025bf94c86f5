"""The command line: a thin adapter over the library (``python -m cam``)."""
from .commands import main

__all__ = ["main"]
