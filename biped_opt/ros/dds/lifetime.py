"""Explicit deletion of Cyclone DDS entities, children before parents.

Every owner in this backend (a context and its participant, a node and its topics, an entity
and its reader or writer, an executor and its WaitSet, the service directory) deletes what it
created itself instead of leaving it to the garbage collector: an entity collected during
interpreter shutdown calls into a DDS library that may be tearing down.
"""

from __future__ import annotations

from typing import Any

__all__ = ["delete_dds"]


def delete_dds(*entities: Any) -> None:
    """Delete Cyclone DDS entities now, in the order given (children before parents).

    ``Entity.__del__`` deletes the C entity once and forgets it, so a later garbage collection
    of the Python object does nothing.
    """
    for entity in entities:
        if entity is not None:
            entity.__del__()
