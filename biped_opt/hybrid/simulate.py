"""Event-driven hybrid simulation of the biped's maneuvers (MODEL.md Sec. 3).

:func:`simulate` runs one maneuver and returns a
:class:`~biped_opt.simulation.trajectory.Trajectory`; :func:`simulate_batch` runs many (th0,
inputs) in parallel compiled threads and returns a
:class:`~biped_opt.simulation.trajectory.BatchResult` (flat arrays), the path sweeps and
optimisation grids take. These are every system's result types: contact modes are masks over the
biped's constraints ``left`` and ``right`` (bit 0 = leg 1, bit 1 = leg 2), which
``ContactMode(mask)`` names in the paper's words. Both validate their inputs once, up front,
and call the compiled module that :mod:`biped_opt.systems` generates from the biped's
description (``systems/library/biped.py``): the biped is simulated by the same kernel as every
other system (:mod:`biped_opt.codegen.kernel`), reached here through :func:`kernel`.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, fields
from types import ModuleType

import numpy as np
import numpy.typing as npt

from biped_opt.errors import InvalidInputError, SimulationError
from biped_opt.maneuvers import Maneuver, check_theta0, parse_maneuver, spec
from biped_opt.model.biped import NSTATE
from biped_opt.model.params import BipedParams
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.simulation.trajectory import BatchResult, Trajectory

__all__ = [
    "SimulatorOptions", "BatchResult", "simulate", "simulate_batch", "check_inputs", "warm_up",
    "kernels_cached", "kernel",
]

Array = npt.NDArray[np.float64]


INPUT_NAMES = ("u1", "u2", "u12")


DEFAULT_PARAMS = BipedParams()


def check_inputs(inputs: npt.ArrayLike | None) -> Array:
    """Inputs as (u1, u2, u12), zero-padded; the error names the offending input."""
    if inputs is None:
        return np.zeros(3)
    if type(inputs) is tuple and len(inputs) == 3:  # the common case, on every trajectory
        u1, u2, u12 = inputs
        if type(u1) is float and type(u2) is float and type(u12) is float:
            if math.isfinite(u1 + u2 + u12):  # a sum of finite numbers is finite (or overflows)
                return np.array(inputs)
    if isinstance(inputs, (tuple, list)) and len(inputs) <= 3:
        try:
            values = [float(v) for v in inputs]
        except (TypeError, ValueError):
            raise InvalidInputError(f"inputs must be numbers, got {inputs!r}") from None
        for name, value in zip(INPUT_NAMES, values):
            if not math.isfinite(value):
                raise InvalidInputError(f"{name} must be finite, got {value}")
        return np.array(values + [0.0] * (3 - len(values)))
    out = np.zeros(3)
    try:
        values = np.asarray(inputs, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InvalidInputError(f"inputs must be numbers, got {inputs!r}") from None
    if values.size > 3:
        raise InvalidInputError(f"at most 3 inputs (u1, u2, u12), got {values.size}")
    out[: values.size] = values
    if not np.isfinite(out).all():
        bad = int(np.flatnonzero(~np.isfinite(out))[0])
        raise InvalidInputError(f"{INPUT_NAMES[bad]} must be finite, got {out[bad]}")
    return out


@dataclass(frozen=True, eq=False)
class BipedKernel:
    """The biped's generated compiled module and how the biped's API addresses it: its
    maneuver codes (by ManeuverSpec.code), parameter order, and the vectors of the defaults
    (looked up without hashing parameters and options: this is on every trajectory's path)."""

    module: ModuleType
    name: str  # the system's name
    constraints: tuple[str, ...]  # the constraints' names (bit j of a mode is the j-th)
    codes: tuple[int, ...]  # the module's maneuver code of each ManeuverSpec.code
    initial_modes: tuple[int, ...]  # the initial mode (mask) of each ManeuverSpec.code
    parameter_names: tuple[str, ...]  # BipedParams fields in the module's parameter order
    default_p: Array
    default_cfg: Array
    no_samples: Array  # a zero-row sample buffer: nothing is ever written to it

    @functools.lru_cache(maxsize=64)  # noqa: B019 (one kernel per process, few parameter sets)
    def parameters(self, params: BipedParams) -> Array:
        """The module's parameter vector for ``params`` (values, then what depends on them)."""
        return _prepared(self.module, self.parameter_names, params)


def _prepared(m: ModuleType, names: tuple[str, ...], params: BipedParams) -> Array:
    # (kept writeable, as the cfg vector: the compiled kernels are typed for writeable arrays,
    # and a read-only one would compile them a second time)
    return m.prepare_parameters(np.array([getattr(params, name) for name in names]))


@functools.cache
def kernel() -> BipedKernel:
    """The biped's compiled module (imported, or generated and compiled, on first use)."""
    from biped_opt.simulation import compiled as generated

    compiled = generated.compile_system("biped")
    m = compiled.module
    names = tuple(compiled.parameters)
    known = {f.name for f in fields(BipedParams) if f.init}
    if set(names) != known:
        raise RuntimeError(f"the biped's description has parameters {names}, BipedParams {known}")
    by_code = sorted((spec(man) for man in Maneuver), key=lambda sp: sp.code)
    codes = tuple(compiled.maneuvers.index(sp.maneuver.value) for sp in by_code)
    return BipedKernel(m, compiled.name, compiled.constraints, codes,
                       tuple(compiled.initial_mode(sp.maneuver.value) for sp in by_code), names,
                       _prepared(m, names, DEFAULT_PARAMS),
                       generated.kernel_config(m, DEFAULT_OPTIONS),
                       np.empty((0, m.SAMPLE_WIDTH)))


@functools.lru_cache(maxsize=64)
def kernel_config(options: SimulatorOptions, sample_dt: float = 0.0,
                  touched_down: bool = False) -> Array:
    """The biped kernel's ``cfg`` vector (:func:`biped_opt.simulation.compiled.kernel_config`),
    cached (not to be written)."""
    from biped_opt.simulation import compiled

    return compiled.kernel_config(kernel().module, options, sample_dt, touched_down)


def simulate(
    maneuver: str,
    theta0: float,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
    sample_dt: float | None = None,
) -> Trajectory:
    """Simulate ``maneuver`` from initial pitch ``theta0`` with inputs (u1, u2, u12).

    ``sample_dt`` requests dense samples on the grid t = k sample_dt (plus the events and t_f).
    The trajectory's ``status`` says how it ended; this function raises only for invalid
    arguments. (An optimiser calls this hundreds of times per policy, so the Python around the
    compiled kernel is kept to the checks and one call.)
    """
    s = spec(maneuver)
    th = check_theta0(s, theta0)
    u = check_inputs(inputs)
    k = kernel()
    p = k.default_p if params is None else k.parameters(params)
    m = k.module
    if sample_dt is None:
        samples = k.no_samples
        cfg = k.default_cfg if options is DEFAULT_OPTIONS else kernel_config(options)
    else:
        if not (math.isfinite(sample_dt) and sample_dt > 0):
            raise InvalidInputError(f"sample_dt must be a positive number, got {sample_dt!r}")
        capacity = int(options.t_end / sample_dt) + 2 * options.max_events + 8
        samples = np.empty((capacity, m.SAMPLE_WIDTH))
        cfg = kernel_config(options, float(sample_dt))
    events = np.empty((options.max_events + 1, m.EVENT_WIDTH))
    y_out = np.empty(NSTATE)
    status, t_f, mode_f, n_ev, n_s, nfev, nsteps, nrej, outcome = m.simulate_maneuver(
        p, k.codes[s.code], th, u, cfg, samples, events, y_out, m.FROM_S, 0
    )
    if n_s > samples.shape[0]:  # cannot happen while capacity covers t_end / sample_dt
        raise SimulationError(f"sample buffer overflow: {n_s} > {samples.shape[0]}")
    # (no budget: the biped's messages are the statuses' own, as its options are the caller's)
    return Trajectory.from_kernel(
        k.name, s.maneuver.value, th, tuple(u.tolist()), status, t_f, outcome, y_out, mode_f,
        k.initial_modes[s.code], n_ev, events, None if sample_dt is None else samples[:n_s],
        nfev, nsteps, nrej, k.constraints, None,
    )


def simulate_batch(
    maneuver: str,
    theta0: npt.ArrayLike,
    inputs: npt.ArrayLike | None = None,
    *,
    params: BipedParams | None = None,
    options: SimulatorOptions = DEFAULT_OPTIONS,
) -> BatchResult:
    """Simulate ``maneuver`` for every th0 in ``theta0`` (shape (N,)) in parallel threads.

    ``inputs`` is one input vector for all (shape (3,) or shorter) or one per angle (N, <=3).
    """
    s = spec(parse_maneuver(maneuver))
    params = params if params is not None else DEFAULT_PARAMS
    th = np.atleast_1d(np.asarray(theta0, dtype=np.float64))
    if th.ndim != 1:
        raise InvalidInputError(f"theta0 must be a 1-D array of angles, got shape {th.shape}")
    n = th.size
    u_arr = np.zeros((n, 3))
    try:
        raw = np.zeros(0) if inputs is None else np.asarray(inputs, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"inputs must be numbers, got {inputs!r}") from None
    if raw.ndim <= 1:
        u_arr[:] = check_inputs(raw)
    elif raw.ndim == 2 and raw.shape[0] == n and raw.shape[1] <= 3:
        u_arr[:, : raw.shape[1]] = raw
        bad = np.argwhere(~np.isfinite(u_arr))
        if bad.size:
            k, i = bad[0]
            raise InvalidInputError(
                f"{INPUT_NAMES[i]} of case {k} must be finite, got {u_arr[k, i]}"
            )
    else:
        raise InvalidInputError(
            f"inputs must have shape (<=3,) or ({n}, <=3) for {n} angles, got {raw.shape}"
        )
    bad = np.flatnonzero(~(np.abs(th) <= s.theta0_limit))  # NaN fails the comparison too
    if bad.size:
        check_theta0(s, th[bad[0]])  # raises, naming theta0 and the valid range
    k = kernel()
    events = np.zeros((n, options.max_events + 1, k.module.EVENT_WIDTH))
    y_out = np.empty((n, NSTATE))
    outcome = np.empty(n)
    info = np.empty((n, 8))
    k.module.simulate_batch_kernel(
        k.parameters(params), k.codes[s.code], th, u_arr, kernel_config(options), events, y_out,
        outcome, info,
    )
    return BatchResult.from_kernel(k.name, s.maneuver.value, th, u_arr, info, outcome, y_out,
                                   events, k.initial_modes[s.code], k.constraints)


def kernels_cached() -> bool:
    """True when the biped's compiled module is on disk and Numba's cache holds its kernels
    for the current sources (a start then loads them in about a second instead of compiling)."""
    from biped_opt.simulation.compiled import cached_module

    m = cached_module("biped")
    if m is None:
        return False
    for fn in (m.simulate_maneuver, m.simulate_batch_kernel):
        if fn.signatures:
            continue  # compiled (or loaded) in this process already
        try:
            if not fn._cache._cache_file._load_index():
                return False
        except (AttributeError, OSError):  # another Numba layout: assume the worst
            return False
    return True


def warm_up() -> float:
    """Compile the simulator's kernels now, or load them from Numba's on-disk cache, rather than
    inside the first call; returns the seconds it took (~15-20 s in a fresh checkout, well under one
    once cached). The nodes call it before they offer their services, so that a client's first
    request is not held up by a compile longer than its timeout."""
    t0 = time.perf_counter()
    simulate("touchdown", 0.1, (0.5, 0.5, 0.0), sample_dt=0.05)  # the single-call kernel
    simulate_batch("liftoff", np.array([0.0, 0.1]), (1.5, 3.0, 0.0))  # the parallel one
    return time.perf_counter() - t0
