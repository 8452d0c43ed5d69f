"""What a simulation returns, for every system: :class:`Trajectory` (one maneuver) and
:class:`BatchResult` (many, as flat arrays).

Both are built from the flat arrays the compiled kernel fills (layouts in
:mod:`biped_opt.codegen.kernel`): the status code becomes a :class:`Status`, and the event rows
``[t, kind, entered mask, left mask, mode before, mode after, y-, y+]`` are kept as they are.
Everything else -- typed :class:`Event` values whose constraints are named as the system
declares them, the :class:`Segment` of each contact mode, the mode sequence -- is derived from
them when first asked for: an optimiser reads only the outcome, and building one object per
simulation is all the hot path pays.

A contact mode is the set J of active unilateral constraints (MODEL.md Sec. 2), stored as a bit
mask over the system's constraints in their declared order (bit j = constraint j); the typed
values carry both the mask and the set of names.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.codegen.status import EVENT_TERMINAL, Status

__all__ = ["BatchResult", "Event", "Segment", "Status", "Trajectory", "constraint_names",
           "mode_name"]

Array = npt.NDArray[np.float64]

_STATUSES = tuple(Status)
#: statuses whose run ends with a terminal event row after the contact events
_TERMINAL_ROW = (Status.OK, Status.APEX_IN_CONTACT)


def mode_name(mode: int, constraints: Sequence[str]) -> str:
    """A contact mode (bit j: constraint j active) by its constraints' names joined with "+"
    (``left+right``); the mode with none is ``air``."""
    names = [c for j, c in enumerate(constraints) if mode >> j & 1]
    return "+".join(names) if names else "air"


def constraint_names(mask: int, names: tuple[str, ...]) -> tuple[str, ...]:
    """The constraints of a mask in their declared order (a bit beyond ``names`` by its
    number)."""
    return tuple(names[j] if j < len(names) else str(j)
                 for j in range(mask.bit_length()) if mask >> j & 1)


@dataclass(frozen=True, eq=False)
class Event:
    """A contact event (constraints entered and/or left, possibly several at once) or the end.

    ``entered``/``left`` name the constraints that became active (an impact, Eq. (1b)) or were
    released; ``mode_before``/``mode_after`` are the contact modes as sets of names, and the
    ``mask_*`` fields the same as bit masks (bit j = the system's constraint j)."""

    t: float
    kind: str  #: "touchdown", "liftoff", "touchdown+liftoff" or "terminal"
    entered: tuple[str, ...]
    left: tuple[str, ...]
    mode_before: frozenset[str]
    mode_after: frozenset[str]
    mask_entered: int
    mask_left: int
    mask_before: int
    mask_after: int
    state_before: Array = field(repr=False)  #: y just before the reset
    state_after: Array = field(repr=False)  #: y just after the reset (Eq. (1b))

    @property
    def touchdown(self) -> tuple[str, ...]:
        """The constraints entered (the contact events' name for it)."""
        return self.entered

    @property
    def liftoff(self) -> tuple[str, ...]:
        """The constraints left."""
        return self.left

    @property
    def simultaneous(self) -> bool:
        """Whether several constraints flipped at this instant (the nonsmooth case)."""
        return self.mask_entered.bit_count() + self.mask_left.bit_count() > 1


@dataclass(frozen=True)
class Segment:
    """A maximal time interval spent in one contact mode."""

    mode: frozenset[str]
    mask: int
    t_start: float
    t_end: float


def _event(row: Array, names: tuple[str, ...], n: int) -> Event:
    entered, left, before, after = int(row[2]), int(row[3]), int(row[4]), int(row[5])
    if int(row[1]) == EVENT_TERMINAL:
        kind = "terminal"
    else:
        kind = "+".join(k for k, m in (("touchdown", entered), ("liftoff", left)) if m)
    return Event(
        t=float(row[0]), kind=kind,
        entered=constraint_names(entered, names), left=constraint_names(left, names),
        mode_before=frozenset(constraint_names(before, names)),
        mode_after=frozenset(constraint_names(after, names)),
        mask_entered=entered, mask_left=left, mask_before=before, mask_after=after,
        state_before=row[6: 6 + n].copy(), state_after=row[6 + n: 6 + 2 * n].copy())


@dataclass(slots=True, eq=False)
class Trajectory:
    """One simulated maneuver of a system (a value: not to be modified; a plain record with
    slots, as a frozen dataclass's construction cost a fifth of the Python around a run).

    ``outcome`` is the maneuver's outcome at the final state (for the biped th(t_f), MODEL.md
    Sec. 4). ``event_rows`` are the kernel's rows: the ``n_events`` contact events, then the
    terminal event's when the run reached it. ``samples`` (when requested, else None) has
    columns ``[t, y, mode, lambda]`` on a uniform time grid plus two rows per event (before and
    after the reset) and one at t_final. ``budget`` (max_events, horizon) lets :attr:`message`
    name the limit a run used up; without it the message is the status's.
    """

    system: str
    maneuver: str
    s: float
    inputs: tuple[float, ...]
    status: Status
    t_final: float
    outcome: float
    y_final: Array = field(repr=False)
    mode_final: int
    initial_mode: int
    n_events: int  #: contact events (the first rows of ``event_rows``)
    event_rows: Array = field(repr=False)
    samples: Array | None = field(repr=False)
    nfev: int
    nsteps: int
    nrejected: int
    constraints: tuple[str, ...] = field(repr=False)  #: the system's constraint names (bits)
    budget: tuple[int, float] | None = field(repr=False)
    _events: tuple[Event, ...] | None = field(default=None, init=False, repr=False)
    _segments: tuple[Segment, ...] | None = field(default=None, init=False, repr=False)

    @classmethod
    def from_kernel(
        cls, system: str, maneuver: str, s: float, inputs: tuple[float, ...], status: int,
        t_final: float, outcome: float, y_final: Array, mode_final: int, initial_mode: int,
        n_events: int, events: Array, samples: Array | None, nfev: int, nsteps: int,
        nrejected: int, constraints: tuple[str, ...], budget: tuple[int, float] | None,
    ) -> Trajectory:
        """From the kernel's outputs (``events``: its whole event buffer)."""
        code = _STATUSES[status]
        return cls(system, maneuver, s, inputs, code, t_final, outcome, y_final, mode_final,
                   initial_mode, n_events,
                   events[: n_events + 1 if code in _TERMINAL_ROW else n_events], samples,
                   nfev, nsteps, nrejected, constraints, budget)

    @property
    def theta0(self) -> float:
        """The maneuver's parameter s (the biped's name for it: the initial pitch)."""
        return self.s

    @property
    def state_final(self) -> Array:
        """The final state y(t_f) (as :attr:`y_final`)."""
        return self.y_final

    @property
    def q_final(self) -> Array:
        return self.y_final[: len(self.y_final) // 2]

    @property
    def qdot_final(self) -> Array:
        return self.y_final[len(self.y_final) // 2:]

    @property
    def success(self) -> bool:
        return self.status is Status.OK

    @property
    def message(self) -> str:
        """How the run ended, in words; with a budget, a budget used up names its limit,
        where to raise it and the last events."""
        status = self.status
        if self.budget is None:
            return status.message
        max_events, horizon = self.budget
        if status is Status.MAX_EVENTS:
            text = (f"{max_events} contact events, the maneuver's event budget, were used up "
                    "before the terminal event (raise max_events on the maneuver, or "
                    "--max-events)")
        elif status is Status.HORIZON:
            text = (f"the horizon t = {horizon:g}, the maneuver's, was reached before the "
                    "terminal event (raise horizon on the maneuver, or --horizon)")
        else:
            text = status.message
        events = self.contact_events
        if status is Status.INCONSISTENT and events:
            last = events[-1]
            text += (f"; after the event at t = {last.t:.10g} no subset of the contacts "
                     f"{{{', '.join(constraint_names(last.mask_after, self.constraints))}}} "
                     "fits")
        elif status is Status.CONSTRAINT_VIOLATED and _zeno(events):
            text += (f"; the last impacts of {'+'.join(events[-1].entered)} come ever closer "
                     "together (a Zeno cascade: infinitely many impacts before a finite time, "
                     "which an event-driven simulation cannot follow to its end; a smaller "
                     "restitution shortens it)")
        if status is not Status.OK and self.n_events:
            text += "; last events: " + ", ".join(
                _describe(e, self.constraints) for e in self.contact_events[-3:])
        return text

    @property
    def events(self) -> tuple[Event, ...]:
        """The events in order, the terminal one last when the run reached it."""
        if self._events is None:
            n = len(self.y_final)
            self._events = tuple(_event(row, self.constraints, n) for row in self.event_rows)
        return self._events

    @property
    def contact_events(self) -> tuple[Event, ...]:
        return self.events[: self.n_events]

    @property
    def segments(self) -> tuple[Segment, ...]:
        """Per-mode segments from t = 0 to t_final."""
        if self._segments is None:
            self._segments = self._cut()
        return self._segments

    def _cut(self) -> tuple[Segment, ...]:
        segs = []
        start, mask = 0.0, self.initial_mode
        for e in self.contact_events:
            segs.append(Segment(self.mode_names(mask), mask, start, e.t))
            start, mask = e.t, e.mask_after
        segs.append(Segment(self.mode_names(mask), mask, start, self.t_final))
        return tuple(segs)

    def mode_names(self, mask: int) -> frozenset[str]:
        """A contact mode's mask as the set of its constraints' names."""
        return frozenset(constraint_names(mask, self.constraints))

    # (read from the event rows when asked for: converting them on every simulation cost a
    # tenth of a trajectory)
    @property
    def mode_sequence(self) -> tuple[int, ...]:
        """The contact modes visited in order (masks), from the initial one."""
        return (self.initial_mode, *map(int, self.event_rows[: self.n_events, 5].tolist()))

    @property
    def modes(self) -> tuple[int, ...]:
        """As :attr:`mode_sequence`."""
        return self.mode_sequence

    @property
    def event_times(self) -> tuple[float, ...]:
        """Times of the contact events."""
        return tuple(self.event_rows[: self.n_events, 0].tolist())

    @property
    def nevents(self) -> int:
        """As :attr:`n_events`."""
        return self.n_events


def _zeno(events: tuple[Event, ...], count: int = 5) -> bool:
    """Whether the last ``count`` events are touchdowns of the same constraints at intervals
    that shrink every time."""
    last = events[-count:]
    if len(last) < count or len({e.mask_entered for e in last}) != 1 or not last[0].mask_entered:
        return False
    gaps = [b.t - a.t for a, b in zip(last, last[1:])]
    return all(0.0 < b < a for a, b in zip(gaps, gaps[1:]))


def _describe(e: Event, names: tuple[str, ...]) -> str:
    """One event in words: ``t = 1.2 touchdown left -> mode right``."""
    def which(found: tuple[str, ...]) -> str:
        return "+".join(found) if found else "air"

    what = " ".join(f"{kind} {which(found)}" for kind, found in (("touchdown", e.entered),
                                                                    ("liftoff", e.left)) if found)
    return f"t = {e.t:.10g} {what} -> mode {which(constraint_names(e.mask_after, names))}"


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Many simulations of one maneuver of a system, as flat arrays (index k = the k-th s and
    input vector). ``event_rows[k]`` holds run k's rows as :attr:`Trajectory.event_rows`
    (``n_events[k]`` contact events, then the terminal one where it was reached).

    Indexing by a field's name (``batch["outcome"]``, and ``"events"`` for the event rows)
    reads the field, as the dictionary this type replaces did."""

    system: str
    maneuver: str
    s: Array  #: (N,)
    inputs: Array  #: (N, inputs) (at least one column)
    status: npt.NDArray[np.int64]  #: (N,) Status codes
    t_final: Array  #: (N,)
    outcome: Array  #: (N,)
    y_final: Array  #: (N, state)
    mode_final: npt.NDArray[np.int64]  #: (N,)
    n_events: npt.NDArray[np.int64]  #: (N,) contact events
    event_rows: Array = field(repr=False)  #: (N, max_events + 1, event width)
    nfev: npt.NDArray[np.int64] = field(repr=False)  #: (N,)
    initial_mode: int = 0
    constraints: tuple[str, ...] = field(default=(), repr=False)

    @classmethod
    def from_kernel(cls, system: str, maneuver: str, s: Array, inputs: Array, info: Array,
                    outcome: Array, y_final: Array, events: Array, initial_mode: int,
                    constraints: tuple[str, ...]) -> BatchResult:
        """From the batch kernel's outputs (``info``: its per-run row of counters)."""
        return cls(system, maneuver, s, inputs, info[:, 0].astype(np.int64), info[:, 1].copy(),
                   outcome, y_final, info[:, 2].astype(np.int64), info[:, 3].astype(np.int64),
                   events, info[:, 5].astype(np.int64), initial_mode, constraints)

    def __len__(self) -> int:
        return len(self.s)

    def __getitem__(self, key: str) -> Any:
        name = "event_rows" if key == "events" else key
        if name not in _BATCH_FIELDS:
            raise KeyError(key)
        return getattr(self, name)

    @property
    def theta0(self) -> Array:
        """As :attr:`s` (the biped's name for it)."""
        return self.s

    @property
    def state_final(self) -> Array:
        """As :attr:`y_final`."""
        return self.y_final

    @property
    def success(self) -> npt.NDArray[np.bool_]:
        return self.status == Status.OK

    def statuses(self) -> tuple[Status, ...]:
        """The status of each run."""
        return tuple(_STATUSES[k] for k in self.status.tolist())

    def event_times(self, k: int) -> Array:
        """Times of run k's contact events."""
        return self.event_rows[k, : self.n_events[k], 0].copy()

    def mode_sequence(self, k: int) -> tuple[int, ...]:
        """The contact modes (masks) run k visited, from the initial one."""
        rows = self.event_rows[k, : self.n_events[k], 5]
        return (self.initial_mode, *map(int, rows.tolist()))


_BATCH_FIELDS = frozenset(f.name for f in fields(BatchResult))
