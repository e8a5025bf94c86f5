"""Test-only oracles and helpers (never shipped in the library)."""
