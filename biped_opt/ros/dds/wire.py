"""Taking samples off a Cyclone DDS reader without letting one bad sample stop the rest.

``DataReader.take`` of PyPI ``cyclonedds`` removes a batch of serialized samples from the reader
and then decodes them one after another: the first sample that does not decode (a string that is
not UTF-8, a sequence length beyond the data, a truncated sample) raises out of ``take`` and the
rest of the batch is gone with it. Anyone on the domain can write such bytes. Here the batch is
taken serialized and each sample decoded on its own: :func:`take` returns the decoded samples
and, for each one that failed, a :class:`Malformed` record with the reason and, where the first
bytes allow it, the rmw_cyclonedds request header ``{guid, seq}`` so that a service can still
answer the request it cannot read.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from cyclonedds._clayer import ddspy_take
from cyclonedds.core import DDSException, InstanceState, SampleState, ViewState

__all__ = ["Malformed", "take", "TAKE_BATCH"]

#: samples taken from one reader per executor wake-up
TAKE_BATCH = 256

_ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any
#: encapsulation identifiers of XCDR1 (plain CDR) data, big and little endian
_CDR_BE, _CDR_LE = b"\x00\x00", b"\x00\x01"


@dataclass(frozen=True)
class Malformed:
    """A sample that did not decode: why, its size, its writer and, for a service request or
    reply, the ``(guid, seq)`` header when the first 20 bytes hold one."""

    reason: str
    size: int
    publication_handle: int
    header: tuple[int, int] | None


def _header(data: bytes) -> tuple[int, int] | None:
    if len(data) < 20 or data[:2] not in (_CDR_BE, _CDR_LE):
        return None
    order = "<" if data[:2] == _CDR_LE else ">"
    guid, seq = struct.unpack_from(order + "Qq", data, 4)
    return guid, seq


def _reason(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else ""
    text = text if len(text) <= 120 else text[:117] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def take(reader: Any, n: int = TAKE_BATCH) -> tuple[list[Any], list[Malformed]]:
    """Take up to ``n`` samples: (decoded samples with ``sample_info`` set, malformed ones).

    Samples without data (disposals, unregistrations of keyless topics) are skipped.
    """
    raw = ddspy_take(reader._ref, _ANY_STATE, n)
    if isinstance(raw, int):
        raise DDSException(raw, f"Occurred while taking data in {reader!r}")
    data_type = reader.topic.data_type
    good: list[Any] = []
    bad: list[Malformed] = []
    for data, info in raw:
        if not info.valid_data:
            continue
        try:
            sample = data_type.deserialize(data)
        except Exception as exc:  # any decoding failure: the sample is unreadable
            bad.append(Malformed(_reason(exc), len(data), int(info.publication_handle),
                                 _header(data)))
            continue
        sample.sample_info = info
        good.append(sample)
    return good, bad
