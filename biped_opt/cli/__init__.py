"""Command-line interface ``biped-opt``: a thin layer that maps library errors to exit codes."""
