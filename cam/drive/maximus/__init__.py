"""The MAXIMUS PCB driller's host side (seed 000, protocol seed 003)."""
