"""File formats, text <-> model only: Excellon, HPGL, G-code."""
