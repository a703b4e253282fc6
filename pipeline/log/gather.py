"""Byte gathers shared by the MCAP scanner and the CDR walkers.

Each gather indexes a read-only view of the buffer whose item ``i`` is what starts at byte
``i`` (overlapping items, stride 1 byte): one fancy index copies every item at once,
aligned or not, without a per-call ``as_strided``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def values_at(u8: NDArray[np.uint8], dtype: str, count: int | None = None) -> NDArray[Any]:
    """A read-only view of ``u8`` in which item ``i`` is the value of ``dtype`` (or the row
    of ``count`` consecutive values) starting at byte ``i``.

    Indexing it with N byte offsets gathers N values (or an (N, count) matrix) in one
    copy. ``u8`` must be contiguous.
    """
    item = np.dtype(dtype).itemsize
    width = item * (1 if count is None else count)
    n = max(u8.size - width + 1, 0)
    if n == 0 or width == 0:
        shape: tuple[int, ...] = (n,) if count is None else (n, count)
        return np.zeros(shape, dtype=dtype)
    if count is None:
        view = np.ndarray((n,), dtype=dtype, buffer=u8, strides=(1,))
    else:
        view = np.ndarray((n, count), dtype=dtype, buffer=u8, strides=(1, item))
    view.flags.writeable = False
    return view


def gather_rows(u8: NDArray[np.uint8], starts: NDArray[np.int64], size: int) -> NDArray[np.uint8]:
    """Copy ``size`` bytes at each start into an (N, size) matrix.

    Rows of a read-only strided view are gathered whole (one memcpy each), which
    is some 40x faster than gathering every byte with its own index.
    """
    if size == 0:
        return np.zeros((starts.size, 0), dtype=np.uint8)
    out: NDArray[np.uint8] = values_at(u8, "u1", size)[starts]
    return out


def gather_u64(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> NDArray[np.uint64]:
    """Little-endian uint64 at each offset of ``u8``."""
    out: NDArray[np.uint64] = values_at(u8, "<u8")[offsets]
    return out


def gather_u32(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> NDArray[np.uint32]:
    """Little-endian uint32 at each offset of ``u8``."""
    out: NDArray[np.uint32] = values_at(u8, "<u4")[offsets]
    return out
