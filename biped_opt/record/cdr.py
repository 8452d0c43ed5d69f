"""Batch CDR serialization of fixed-layout ROS 2 messages with numpy.

A message whose fields are scalars, fixed-size arrays, nested messages and strings has one byte
layout once its strings are known. :func:`compile_layout` derives that layout from the message's
definition (the parsed ``.msg`` in a rosbags typestore) by the CDR rules - each primitive aligned
to its size, relative to the payload after the 4-byte encapsulation header - and returns a numpy
structured dtype with explicit offsets. Filling an array of that dtype serializes a whole trajectory
of messages at once; the bytes equal rosbags' ``serialize_cdr`` message for message (tested).

A sequence of primitives is fixed too once its length is: :func:`compile_layout` takes the
lengths (a trajectory of one system has the same number of coordinates and constraints in every
sample). Other messages with sequences are serialized one by one with rosbags instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from biped_opt.errors import BipedOptError

__all__ = ["LayoutError", "FixedLayout", "compile_layout", "numpy_dtype", "CDR_LE_HEADER"]

#: encapsulation header of little-endian plain CDR (XCDR1), first 4 bytes of every message
CDR_LE_HEADER = b"\x00\x01\x00\x00"

_PRIMITIVES = {
    "bool": "u1", "byte": "u1", "char": "u1", "int8": "i1", "uint8": "u1",
    "int16": "<i2", "uint16": "<u2", "int32": "<i4", "uint32": "<u4",
    "int64": "<i8", "uint64": "<u8", "float32": "<f4", "float64": "<f8",
}


def numpy_dtype(primitive: str) -> np.dtype:
    """Little-endian numpy dtype of a ROS primitive type (``float64``, ``uint8``...)."""
    try:
        return np.dtype(_PRIMITIVES[primitive])
    except KeyError:
        raise LayoutError(f"{primitive!r} is not a fixed-size ROS primitive") from None


class LayoutError(BipedOptError, ValueError):
    """The message has a variable-length part that its strings do not pin down."""


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) // size * size


@dataclass(frozen=True)
class FixedLayout:
    """Byte layout of one message type for given string contents.

    ``dtype`` is a structured dtype whose fields are the message's numeric leaves, named by their
    dotted path (``header.stamp.sec``, ``q``); ``template`` holds the constant bytes (the header,
    string lengths and characters, zero padding).
    """

    typename: str
    dtype: np.dtype
    template: bytes

    @property
    def size(self) -> int:
        return self.dtype.itemsize

    def empty(self, count: int) -> npt.NDArray[Any]:
        """``count`` messages pre-filled with the constant bytes, ready for the numeric fields."""
        raw = np.frombuffer(self.template * count, dtype=np.uint8).copy()
        return raw.view(self.dtype)

    def serialize(self, messages: npt.NDArray[Any]) -> list[bytes]:
        """One ``bytes`` per message."""
        buf = messages.tobytes()
        n = self.size
        return [buf[i : i + n] for i in range(0, len(buf), n)]


def compile_layout(typestore: Any, typename: str, strings: dict[str, str],
                   lengths: dict[str, int] | None = None, *,
                   empty_rest: bool = False) -> FixedLayout:
    """Layout of ``typename`` with the string fields set to ``strings`` (dotted path -> text)
    and the sequences to ``lengths`` (dotted path -> number of elements). The elements of a
    sequence of messages are paths ``<sequence>.<index>.<field>``, those of a sequence of strings
    (given in ``lengths``) ``<sequence>.<index>`` in ``strings``. ``empty_rest``: strings and
    sequences not given are empty (a message with unused optional parts, such as a Marker's
    texture); otherwise each must be given."""
    lengths = lengths or {}
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    constant: dict[int, bytes] = {}

    def numbers(path: str, primitive: str, count: int | None, offset: int) -> int:
        """A numeric leaf (``count`` None: a scalar, else an array of ``count``) at the next
        offset aligned to its size; returns the offset after it."""
        fmt = numpy_dtype(primitive)
        offset = _align(offset, fmt.itemsize)
        names.append(path)
        formats.append(fmt if count is None else (fmt, (count,)))
        offsets.append(offset)
        return offset + fmt.itemsize * (1 if count is None else count)

    def walk(tname: str, prefix: str, offset: int) -> int:
        _consts, fields = typestore.fielddefs[tname]
        for fname, (kind, spec) in fields:
            path = f"{prefix}{fname}"
            kind = getattr(kind, "name", kind)
            if kind == "NAME":
                offset = walk(spec, path + ".", offset)
            elif kind == "BASE":
                base = spec[0]
                if base == "string":
                    if path not in strings and not empty_rest:
                        raise LayoutError(f"{typename}: string field {path} needs a value")
                    data = strings.get(path, "").encode() + b"\x00"
                    offset = _align(offset, 4)
                    constant[offset] = len(data).to_bytes(4, "little") + data
                    offset += 4 + len(data)
                else:
                    offset = numbers(path, base, None, offset)
            elif kind == "SEQUENCE" and getattr(spec[0][0], "name", spec[0][0]) == "NAME" \
                    and (path in lengths or empty_rest):
                count = int(lengths.get(path, 0))  # a sequence of messages: length, elements
                offset = _align(offset, 4)
                constant[offset] = count.to_bytes(4, "little")
                offset += 4
                for i in range(count):
                    offset = walk(spec[0][1], f"{path}.{i}.", offset)
            elif kind == "SEQUENCE" and getattr(spec[0][0], "name", spec[0][0]) == "BASE" \
                    and spec[0][1][0] == "string" and path in lengths:
                count = int(lengths[path])  # strings fixed once: length, then each string
                offset = _align(offset, 4)
                constant[offset] = count.to_bytes(4, "little")
                offset += 4
                for i in range(count):
                    if f"{path}.{i}" not in strings:
                        raise LayoutError(f"{typename}: string {path}.{i} needs a value")
                    data = strings[f"{path}.{i}"].encode() + b"\x00"
                    offset = _align(offset, 4)
                    constant[offset] = len(data).to_bytes(4, "little") + data
                    offset += 4 + len(data)
            elif kind == "ARRAY" or path in lengths or empty_rest:
                what = "array" if kind == "ARRAY" else "sequence"
                (elem_kind, elem_spec), count = spec
                if getattr(elem_kind, "name", elem_kind) != "BASE" or elem_spec[0] == "string":
                    raise LayoutError(f"{typename}: {what} {path} of non-primitives")
                if kind != "ARRAY":  # a sequence: its length, then (if any) its elements
                    count = int(lengths.get(path, 0))
                    offset = _align(offset, 4)
                    constant[offset] = count.to_bytes(4, "little")
                    offset += 4
                if count:  # (an empty sequence is its length alone: no padding follows)
                    offset = numbers(path, elem_spec[0], count, offset)
            else:
                raise LayoutError(f"{typename}: {path} is a sequence of unknown length")
        return offset

    # offsets inside the payload; the dtype covers header + payload
    end = walk(typename, "", 0)
    head = len(CDR_LE_HEADER)
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": [o + head for o in offsets],
         "itemsize": head + end}
    )
    template = bytearray(head + end)
    template[:head] = CDR_LE_HEADER
    for off, data in constant.items():
        template[head + off : head + off + len(data)] = data
    return FixedLayout(typename=typename, dtype=dtype, template=bytes(template))
