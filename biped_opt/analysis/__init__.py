"""Nonsmooth analysis: one-sided limits and switch location (:mod:`~biped_opt.piecewise`, below it),
the engine that locates and classifies kinks and jumps along a sweep
(:mod:`~biped_opt.analysis.switches`) and its drivers for any system
(:mod:`~biped_opt.analysis.nonsmooth`), the estimate from a sweep's samples alone, as recorded
(:mod:`~biped_opt.analysis.sampled`), what any system's figures show
(:mod:`~biped_opt.analysis.figure_data`), the (n!)^k pieces (:mod:`~biped_opt.analysis.pieces`)
and gradient methods at kinks and jumps (:mod:`~biped_opt.analysis.gradients`)."""
