"""Code generation: a derived system (:mod:`biped_opt.systems`) becomes a Python module that
Numba compiles, holding the system's vector field, guards and impact map, a DOP853 step for its
dimensions (:mod:`~biped_opt.codegen.dop853`) and the event-driven kernel
(:mod:`~biped_opt.codegen.kernel`, appended verbatim). :mod:`~biped_opt.codegen.runtime` is what
every generated module imports."""
