"""How the event-driven kernel reaches a system's compiled functions: one table, no Numba.

The kernel (:mod:`biped_opt.codegen.kernel`) is the same for every system, so it is compiled
once per installation and kept in Numba's cache beside its source. What differs between
systems reaches it at run time in one int64 vector, the *system vector* ``sv``:

- ``sv[:NFUNC]``: the addresses of the system's functions listed in :data:`FUNCTIONS`, compiled
  as C-callable functions (``numba.cfunc``) by the system's generated module, in that order.
  The kernel calls them through these addresses. An array argument travels as its data pointer
  and its shape (a 1-D array as ``double*, int64``, a 2-D one as ``double*, int64, int64``), an
  integer as int64, a float as double.
- ``sv[NFUNC:]``: the system's table (:func:`system_table`): the state's length, the number of
  constraints and maneuvers, the DOP853 workspace's length, whether some constraints' rows are
  dependent for every configuration, which guards are one state component
  (a constraint's height in the air, a maneuver's terminal velocity: their event roots
  interpolate that one component), and each maneuver's initial mode, final mode and whether its
  terminal guard is armed only after the first touchdown.

The kernel compiled ahead of time for a start without Numba (:mod:`biped_opt.codegen.aot`)
is the same kernel source with each call bound directly to the system's function
(:func:`direct_binding`); it reads the table part of ``sv`` the same way and ignores the
addresses.

A change of this table changes how the compiled kernel must call: the kernel's source carries
:func:`digest` of the table it was written for and refuses to import with another, so that
Numba's cache, keyed on the kernel's own file, never serves a kernel compiled for another table.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

__all__ = ["FUNCTIONS", "NFUNC", "INDEX", "SV_NSTATE", "SV_NCON", "SV_NMAN", "SV_WORKSPACE",
           "SV_DEPENDENT", "SV_GUARDS", "MANEUVER_WIDTH", "CFG_T_END", "CFG_MAX_EVENTS",
           "CFG_RTOL", "CFG_ATOL",
           "CFG_H_MAX", "CFG_SAMPLE_DT", "CFG_TOUCHED_DOWN", "CFG_SIZE", "ENTRIES", "MODULE_CALLS",
           "ENTRY_SIGNATURES",
           "digest",
           "system_table", "cfunc_source", "direct_binding", "binding_names"]

#: the system functions the kernel calls: name -> (argument kinds, result kind). Kinds: ``A`` a
#: C-contiguous float64 vector, ``F`` a C-contiguous float64 matrix, ``i`` int64, ``f``
#: float64, ``v`` (result only) nothing. The names and argument orders are those of the
#: generated module (biped_opt.codegen.render).
FUNCTIONS: dict[str, tuple[str, str]] = {
    "_field_at": ("AiAiAAiAi", "v"),
    "step": ("AiAiAAfAAAAffA", "f"),
    "dense_coefficients": ("AiAAAfAAAF", "v"),
    "apply_impact": ("AiA", "v"),
    "constraint_rates": ("AAiA", "v"),
    "guard_value": ("AiAiAiAii", "f"),
    "guard_values": ("AiAiAiAiA", "v"),
    "initial_state": ("ifAA", "v"),
    "outcome_value": ("iAAi", "f"),
    "reaction": ("AiAAi", "f"),
}
NFUNC = len(FUNCTIONS)
#: name -> the index of its address in ``sv``
INDEX = {name: k for k, name in enumerate(FUNCTIONS)}

# the table part of sv (offsets into sv)
SV_NSTATE = NFUNC
SV_NCON = NFUNC + 1
SV_NMAN = NFUNC + 2
SV_WORKSPACE = NFUNC + 3
#: 1 when the constraints' rows of Da are linearly dependent at a generic configuration (some
#: contact sets are dependent for every q, a face's four corners: the kernel then looks for
#: dependent sets at its events, SYSTEMS.md, "Dependent contacts"), else 0
SV_DEPENDENT = NFUNC + 4
#: (k, sign) per guard of a constraint in the air: the component k of the state (-1 if none)
#: and its sign (+-1) when the guard is sign * y[k]; then MANEUVER_WIDTH entries per maneuver
SV_GUARDS = NFUNC + 5
#: a maneuver's entries: terminal guard's (k, sign), armed after touchdown (0/1), final mode
#: (-1: any), initial mode
MANEUVER_WIDTH = 5


# the kernel's cfg vector (float64): settings of one call
CFG_T_END = 0
CFG_MAX_EVENTS = 1
CFG_RTOL = 2
CFG_ATOL = 3
CFG_H_MAX = 4
CFG_SAMPLE_DT = 5
#: 1: a touchdown happened before y0 (a trajectory continued from an event), so a terminal
#: guard armed after the first touchdown is armed from the start
CFG_TOUCHED_DOWN = 6
CFG_SIZE = 7


#: the kernel's entry points and the types they are called with (biped_opt.simulation.compiled,
#: biped_opt.control.derivatives): name -> (argument kinds, result kinds). Kinds as in
#: :data:`FUNCTIONS`, and ``I`` a C-contiguous int64 vector, ``T`` a C-contiguous float64 array
#: of three dimensions; a result of several kinds is a tuple. What ``make venv`` compiles them
#: for (biped_opt.codegen.kernel.compile_all), and what the kernel compiled ahead of time
#: exports (biped_opt.codegen.aot, biped_opt.codegen.native)
ENTRIES: dict[str, tuple[str, str]] = {
    # (status, t_f, mode_f, events, samples, nfev, steps, rejected, outcome) from
    # (p, sv, code, s, u, cfg, samples, events, y_out, y0, mode0)
    "simulate_maneuver": ("AIifAAFFAAi", "ifiiiiiif"),
    # (p, sv, code, ss, us, cfg, events, y_out, outcome, info, start, stop)
    "simulate_batch_kernel": ("AIiAFATFAFii", "v"),
    # field evaluations from (p, sv, mode, w, u, du, step, steps, weights, out, lam)
    "variational_field": ("AIiAAFfAAAA", "i"),
}

#: the generated module's functions that Python calls one by one (the derivatives and the
#: contact checks: biped_opt.control.derivatives, biped_opt.simulation.contacts), kinds as in
#: :data:`FUNCTIONS`: a kernel library exports them too (biped_opt.codegen.native), so that those
#: paths start without Numba as well
MODULE_CALLS: dict[str, tuple[str, str]] = {
    **{name: FUNCTIONS[name] for name in ("_field_at", "apply_impact", "constraint_rates",
                                          "guard_value", "initial_state", "outcome_value",
                                          "reaction")},
    "constraint_value": ("iAAi", "f"),
    "terminal_value": ("iAAAi", "f"),
}

_SIGNATURE_TYPE = {"A": "f8[::1]", "I": "i8[::1]", "F": "f8[:, ::1]", "T": "f8[:, :, ::1]",
                   "i": "i8", "f": "f8", "v": "void"}


def _signature(kinds: str, result: str) -> str:
    """A Numba signature from the kinds of :data:`ENTRIES`."""
    out = [_SIGNATURE_TYPE[k] for k in result]
    ret = f"Tuple(({', '.join(out)}))" if len(out) > 1 else out[0]
    return f"{ret}({', '.join(_SIGNATURE_TYPE[k] for k in kinds)})"


#: the entry points' Numba signatures (from :data:`ENTRIES`)
ENTRY_SIGNATURES = {name: _signature(*kinds) for name, kinds in ENTRIES.items()}


def digest() -> str:
    """A short hash of :data:`FUNCTIONS` and the table's layout (see the module docstring)."""
    text = repr((FUNCTIONS, SV_GUARDS - NFUNC, MANEUVER_WIDTH, CFG_SIZE, CFG_TOUCHED_DOWN))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def system_table(nstate: int, ncon: int, workspace: int,
                 constraint_components: Sequence[tuple[int, float] | None],
                 maneuvers: Sequence[tuple[tuple[int, float] | None, bool, int, int]],
                 *, dependent: bool = False) -> list[int]:
    """The table part of ``sv``. ``maneuvers``: per maneuver (terminal guard's component,
    armed after touchdown, final mode or -1, initial mode); ``dependent``: see
    :data:`SV_DEPENDENT`."""
    def component(one: tuple[int, float] | None) -> list[int]:
        return [-1, 1] if one is None else [int(one[0]), 1 if one[1] > 0 else -1]

    table = [nstate, ncon, len(maneuvers), workspace, int(dependent)]
    for one in constraint_components:
        table += component(one)
    for terminal, after_touchdown, final, initial in maneuvers:
        table += [*component(terminal), int(after_touchdown), int(final), int(initial)]
    return table


_NUMBA_TYPE = {"A": "types.CPointer(types.float64), types.int64",
               "F": "types.CPointer(types.float64), types.int64, types.int64",
               "i": "types.int64", "f": "types.float64"}
_RESULT_TYPE = {"v": "types.void", "f": "types.float64"}


def cfunc_source() -> str:
    """The part of a generated module that makes its C-callable functions: for each of
    :data:`FUNCTIONS` a wrapper ``<name>_c`` that views the pointers as arrays and calls the
    module's function, and ``function_addresses()``, which compiles the wrappers (or loads them
    from Numba's cache) when first called and returns their addresses in the table's order. The
    module defines ``FIELD_FREE`` and ``_field_ready`` (biped_opt.codegen.render._field_at).
    ``compile_functions(names)`` compiles some of them ahead (a second process does, meanwhile;
    see biped_opt.codegen.precompile)."""
    out = ["# --- C-callable functions: what the shared kernel calls (biped_opt.codegen.abi) ---",
           "", "from numba import types as types  # noqa: E402", ""]
    for name, (kinds, result) in FUNCTIONS.items():
        params, views = [], []
        for k, kind in enumerate(kinds):
            a = f"a{k}"
            if kind == "A":
                params += [a, f"{a}_n"]
                views.append(f"nb.carray({a}, {a}_n)")
            elif kind == "F":
                params += [a, f"{a}_r", f"{a}_c"]
                views.append(f"nb.carray({a}, ({a}_r, {a}_c))")
            else:
                params.append(a)
                views.append(a)
        call = f"{name}({', '.join(views)})"
        out += ["", f"def {name}_c({', '.join(params)}):",
                f"    {'return ' if result != 'v' else ''}{call}", ""]
    sigs = {name: f"{_RESULT_TYPE[result]}({', '.join(_NUMBA_TYPE[k] for k in kinds)})"
            for name, (kinds, result) in FUNCTIONS.items()}
    out += ["", "CFUNC_SIGNATURES = {"]
    out += [f"    {name!r}: {sig}," for name, sig in sigs.items()]
    out += ["}", "_CFUNCS = {}", "", "",
            "def compile_functions(names):",
            '    """The C-callable wrappers of ``names``, compiled or loaded from the cache."""',
            "    for name in names:",
            "        if name not in _CFUNCS:",
            "            if name not in FIELD_FREE:",
            "                _field_ready()",
            "            _CFUNCS[name] = nb.cfunc(CFUNC_SIGNATURES[name], **HOT_PATH)(",
            "                globals()[name + '_c'])",
            "    return [_CFUNCS[name] for name in names]", "", "",
            "def function_addresses():",
            '    """The addresses of the C-callable functions, in the table\'s order."""',
            "    return np.array([f.address for f in compile_functions(list(CFUNC_SIGNATURES))],",
            "                    dtype=np.int64)", ""]
    return "\n".join(out)


def direct_binding() -> str:
    """The kernel's ``sys_*`` calls bound directly to a module's functions (for the kernel
    compiled into one module with them, ahead of time): the same names and arguments as the
    engine's bindings in biped_opt.codegen.kernel, the address vector unused."""
    out = ["# --- the kernel's calls, bound directly (biped_opt.codegen.abi.direct_binding) ---"]
    for name, (kinds, result) in FUNCTIONS.items():
        args = ", ".join(f"a{k}" for k in range(len(kinds)))
        out += ["", "", '@nb.njit(**HOT_PATH, inline="always")',
                f"def {binding_names()[name]}(sv, {args}):",
                f"    {'return ' if result != 'v' else ''}{name}({args})"]
    return "\n".join(out) + "\n"


def binding_names() -> dict[str, str]:
    """name -> the kernel's binding of it (``sys_<name>``)."""
    return {name: f"sys{name if name.startswith('_') else '_' + name}" for name in FUNCTIONS}
