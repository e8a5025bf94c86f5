"""Pictures and reports of every stage."""
