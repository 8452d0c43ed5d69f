"""Results of the hybrid simulator: trajectories, their events and per-mode segments.

A :class:`Trajectory` is a frozen value built from the flat arrays the compiled kernel fills
(layouts in :mod:`biped_opt.codegen.kernel`); events and segments are derived from them on
demand.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import numpy.typing as npt

from biped_opt.codegen.runtime import EVENT_TERMINAL, Status
from biped_opt.model.biped import NDOF, NSTATE
from biped_opt.model.modes import ContactMode

__all__ = ["Status", "Event", "Segment", "Trajectory"]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Event:
    """A contact event (touchdown and/or liftoff, possibly of both feet at once) or the end."""

    t: float
    kind: str  #: "touchdown", "liftoff", "touchdown+liftoff" or "terminal"
    touchdown: tuple[int, ...]  #: legs (1 = left, 2 = right) that touched down
    liftoff: tuple[int, ...]  #: legs that lifted off
    mode_before: ContactMode
    mode_after: ContactMode
    state_before: Array = field(repr=False)  #: y just before the reset
    state_after: Array = field(repr=False)  #: y just after the reset (Eq. (1b))

    @property
    def simultaneous(self) -> bool:
        """Whether several constraints flipped at this instant (the nonsmooth case)."""
        return len(self.touchdown) + len(self.liftoff) > 1


@dataclass(frozen=True)
class Segment:
    """A maximal time interval spent in one contact mode."""

    mode: ContactMode
    t_start: float
    t_end: float


_STATUSES = tuple(Status)
_MODES = tuple(ContactMode)


def _legs(mask: int) -> tuple[int, ...]:
    return tuple(j + 1 for j in range(2) if mask >> j & 1)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One simulated maneuver.

    ``outcome`` is th(t_f) (MODEL.md Sec. 4). ``samples`` (if requested) has columns
    ``[t, y (14), mode, lambda_1, lambda_2]`` on a uniform time grid plus two rows per event
    (before and after the reset) and one at t_final.
    """

    maneuver: str
    theta0: float
    inputs: Array
    status: Status
    t_final: float
    state_final: Array
    mode_final: ContactMode
    event_rows: Array = field(repr=False)
    samples: Array | None = field(repr=False)
    nfev: int
    nsteps: int
    nrejected: int

    @classmethod
    def from_kernel(
        cls, maneuver: str, theta0: float, inputs: Array, status: int, t_final: float,
        state_final: Array, mode_final: int, event_rows: Array, samples: Array | None,
        nfev: int, nsteps: int, nrejected: int,
    ) -> Trajectory:
        """Build from the kernel's outputs without the frozen-dataclass ``__init__`` (which sets
        each field through ``object.__setattr__``): this is on the per-trajectory hot path."""
        self = object.__new__(cls)
        object.__setattr__(self, "__dict__", {
            "maneuver": maneuver, "theta0": theta0, "inputs": inputs,
            "status": _STATUSES[status], "t_final": t_final, "state_final": state_final,
            "mode_final": _MODES[mode_final], "event_rows": event_rows, "samples": samples,
            "nfev": nfev, "nsteps": nsteps, "nrejected": nrejected,
        })
        return self

    @property
    def success(self) -> bool:
        return self.status is Status.OK

    @property
    def message(self) -> str:
        return self.status.message

    @property
    def outcome(self) -> float:
        """Body pitch th(t_f) at the terminal event."""
        return float(self.state_final[2])

    @property
    def q_final(self) -> Array:
        return self.state_final[:NDOF]

    @property
    def qdot_final(self) -> Array:
        return self.state_final[NDOF:]

    @cached_property
    def events(self) -> tuple[Event, ...]:
        out = []
        for row in self.event_rows:
            td, lo = int(row[2]), int(row[3])
            if int(row[1]) == EVENT_TERMINAL:
                kind = "terminal"
            else:
                kind = "+".join(k for k, m in (("touchdown", td), ("liftoff", lo)) if m)
            out.append(
                Event(
                    t=float(row[0]),
                    kind=kind,
                    touchdown=_legs(td),
                    liftoff=_legs(lo),
                    mode_before=ContactMode(int(row[4])),
                    mode_after=ContactMode(int(row[5])),
                    state_before=row[6 : 6 + NSTATE].copy(),
                    state_after=row[6 + NSTATE : 6 + 2 * NSTATE].copy(),
                )
            )
        return tuple(out)

    @property
    def contact_events(self) -> tuple[Event, ...]:
        return tuple(e for e in self.events if e.kind != "terminal")

    @cached_property
    def segments(self) -> tuple[Segment, ...]:
        """Per-mode segments from t = 0 to t_final."""
        segs = []
        start = 0.0
        mode = ContactMode(int(self.event_rows[0, 4])) if len(self.event_rows) else self.mode_final
        for e in self.contact_events:
            segs.append(Segment(mode=mode, t_start=start, t_end=e.t))
            start, mode = e.t, e.mode_after
        segs.append(Segment(mode=mode, t_start=start, t_end=self.t_final))
        return tuple(segs)

    @property
    def modes(self) -> list[tuple[float, ContactMode]]:
        """(time of entry, mode) for each mode visited, first at t = 0."""
        return [(s.t_start, s.mode) for s in self.segments]

    @property
    def mode_sequence(self) -> tuple[ContactMode, ...]:
        return tuple(s.mode for s in self.segments)

    @property
    def event_times(self) -> Array:
        return np.array([e.t for e in self.contact_events])

    @property
    def nevents(self) -> int:
        return len(self.contact_events)
