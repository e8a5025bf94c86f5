"""File kinds: one module per kind of input file, registered in one table (issue #48 point 1)."""
