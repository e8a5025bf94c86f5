"""Emulators of the machines cam drives (never imported by the host side)."""
