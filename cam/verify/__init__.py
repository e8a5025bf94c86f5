"""The user-facing proofs: pin-log decoder, carve, ramp checker."""
