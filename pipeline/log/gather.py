"""Byte gathers shared by the MCAP scanner and the CDR walkers."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def gather_rows(u8: NDArray[np.uint8], starts: NDArray[np.int64], size: int) -> NDArray[np.uint8]:
    """Copy ``size`` bytes at each start into an (N, size) matrix.

    Rows of a read-only strided view are gathered whole (one memcpy each), which
    is some 40x faster than gathering every byte with its own index.
    """
    windows = np.lib.stride_tricks.as_strided(
        u8, shape=(u8.size - size + 1, size), strides=(1, 1), writeable=False
    )
    return windows[starts]


def gather_u64(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> NDArray[np.uint64]:
    """Little-endian uint64 at each offset of ``u8``."""
    return gather_rows(u8, offsets, 8).view("<u8").reshape(-1)


def gather_u32(u8: NDArray[np.uint8], offsets: NDArray[np.int64]) -> NDArray[np.uint32]:
    """Little-endian uint32 at each offset of ``u8``."""
    return gather_rows(u8, offsets, 4).view("<u4").reshape(-1)
