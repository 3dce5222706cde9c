"""numpy arrays on the wire.

An `Array` is the bytes of a C-contiguous numpy array with its dtype and shape. msgpack
keeps the bytes raw (no copy on decode beyond the buffer itself); JSON base64-encodes
them. `as_numpy` gives a read-only view of those bytes, so decoding an image costs no
extra copy.
"""

from __future__ import annotations

import msgspec
import numpy as np
from numpy.typing import NDArray

#: dtypes allowed on the wire: fixed-size, no objects, no platform-dependent widths.
WIRE_DTYPES = frozenset(
    {"uint8", "uint16", "int16", "int32", "uint32", "int64", "float32", "float64", "bool"}
)


class ArrayError(ValueError):
    """An `Array` whose dtype, shape and byte count do not agree."""


class Array(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A numpy array as bytes.

    dtype: numpy dtype name, one of `WIRE_DTYPES` (little-endian on the wire).
    shape: the array's shape; the product times the item size equals len(data).
    data: the raw C-ordered bytes.
    """

    dtype: str
    shape: tuple[int, ...]
    data: bytes


def to_wire(array: NDArray[np.generic]) -> Array:
    """Pack a numpy array (copied only if it is not C-contiguous little-endian)."""
    arr = np.asarray(array)
    name = arr.dtype.name
    if name not in WIRE_DTYPES:
        raise ArrayError(f"dtype {name!r} cannot travel; allowed: {sorted(WIRE_DTYPES)}")
    arr = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
    return Array(dtype=name, shape=tuple(int(n) for n in arr.shape), data=arr.tobytes())


def as_numpy(array: Array) -> NDArray[np.generic]:
    """A read-only numpy view of the bytes, checked against dtype and shape."""
    if array.dtype not in WIRE_DTYPES:
        raise ArrayError(f"dtype {array.dtype!r} is not allowed; allowed: {sorted(WIRE_DTYPES)}")
    if any(n < 0 for n in array.shape):
        raise ArrayError(f"negative dimension in shape {array.shape}")
    dtype = np.dtype(array.dtype).newbyteorder("<")
    expected = int(np.prod(array.shape, dtype=np.int64)) * dtype.itemsize
    if expected != len(array.data):
        raise ArrayError(
            f"shape {array.shape} of {array.dtype} needs {expected} bytes, got {len(array.data)}"
        )
    return np.frombuffer(array.data, dtype=dtype).reshape(array.shape)
