"""The biped's results are every system's: :mod:`biped_opt.simulation.trajectory` (re-exported
here under the names this module gave them first)."""

from biped_opt.simulation.trajectory import BatchResult, Event, Segment, Status, Trajectory

__all__ = ["BatchResult", "Event", "Segment", "Status", "Trajectory"]
