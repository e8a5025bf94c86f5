"""Planning: every job source to one job model in machine steps."""
