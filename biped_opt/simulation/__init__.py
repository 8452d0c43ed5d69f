"""Hybrid simulation of any system: :class:`~biped_opt.simulation.compiled.CompiledSystem` compiles
a description once (disk cache) and runs its maneuvers with the generated event-driven kernel;
every run returns a :class:`~biped_opt.simulation.trajectory.Trajectory` (many at once: a
:class:`~biped_opt.simulation.trajectory.BatchResult`)."""
