"""Run small dense linear algebra on one BLAS thread.

Identification's inner loops (excitation design, the physical projection) factor
matrices of a few hundred rows thousands of times. OpenBLAS threads them; on a shared
machine its spinning threads make a 360x58 SVD 30x slower than one thread (50 ms vs
1.5 ms measured with eight busy processes on two cores). ``one_thread()`` sets the
thread count of every OpenBLAS loaded in the process (NumPy's and SciPy's bundled
copies) to one and restores it after, as ``threadpoolctl`` does; elsewhere (another
BLAS, another OS) it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
from collections.abc import Iterator
from pathlib import Path
from typing import Any

_PREFIXES = ("scipy_openblas", "openblas")
_SUFFIXES = ("64_", "")


def _openblas_handles() -> list[tuple[Any, Any]]:
    maps = Path("/proc/self/maps")
    try:
        lines = maps.read_text().splitlines()
    except OSError:
        return []
    paths = sorted({ln.split()[-1] for ln in lines if "openblas" in ln.split()[-1].lower()})
    out = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in _PREFIXES:
            for suffix in _SUFFIXES:
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    out.append((get, put))
                    break
            else:
                continue
            break
    return out


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """OpenBLAS on one thread inside the block (a no-op without OpenBLAS)."""
    handles = _openblas_handles()
    before = []
    for get, put in handles:
        before.append(int(get()))
        put(1)
    try:
        yield
    finally:
        for (_, put), n in zip(handles, before, strict=True):
            put(n)
