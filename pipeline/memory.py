"""Out of memory, told apart from other failures: one line instead of a traceback.

Python says ``MemoryError``; a C extension whose shared library cannot be mapped under an
address-space limit (``ulimit -v``) says ``ImportError: ... failed to map segment`` or
``cannot allocate memory``. Both mean the same to the user: the machine (or the limit) is
too small for this run.

The wording of such failures varies by library and CPython version, so the wordings seen
are only the fallback. The check that does not depend on wording: an address-space limit
(``RLIMIT_AS``) is set and this process is within ``_NEAR_LIMIT_BYTES`` of it, and the
failure is of a kind an allocation can cause (an import, a thread start, a SystemError).
"""

from __future__ import annotations

import errno
import os
import resource

__all__ = [
    "OUT_OF_MEMORY_HINT",
    "address_headroom_bytes",
    "address_limit_below_need",
    "claim_blas_buffer_first",
    "near_address_limit",
    "out_of_memory",
    "quiet_unraisable_memory_errors",
]

_OOM_TEXTS = ("failed to map segment", "cannot allocate memory", "out of memory")
# a thread's stack that cannot be mapped ("can't start new thread") is the same shortage
_ALLOC_TEXTS = ("could not allocate memory", "cannot allocate memory", "can't start new thread")

# CPython's SystemError when an allocation failed inside an import (both wordings seen)
_NO_EXCEPTION_TEXTS = ("NULL without setting an exception", "error return without exception set")

# an allocation that failed was at most this large (a shared library's segment, a thread's
# 8 MiB stack, an arena): closer than this to the limit, the limit is the likely cause
_NEAR_LIMIT_BYTES = 256 * 1024 * 1024
# the failures an allocation can cause without saying so (wording aside)
_ALLOCATION_KINDS: tuple[type[BaseException], ...] = (ImportError, SystemError, RuntimeError)

OUT_OF_MEMORY_HINT = "raise the memory limit (ulimit -v), or use fewer --jobs"

# The address space a command needs at the least: the peak virtual size (VmPeak) of its
# smallest run, rounded up. `record` of one UR5 episode (0.3 s hold, one job) peaked at
# 572 MB on the 2-core test machine (`benches`-free: /proc/self/status at exit, 2026-11-28).
# Under a lower limit the run cannot succeed, and where it fails is luck: glibc may abort
# from C while loading a library ("cannot allocate memory for thread-local data", exit 127),
# before any line of ours. So such a limit is refused before anything is loaded. Above it,
# a run that still runs short is caught where Python sees it (out_of_memory below).
MIN_ADDRESS_SPACE_BYTES = {"record": 600 * 1024 * 1024}


def near_address_limit(*, used_bytes: int | None = None, limit_bytes: int | None = None) -> bool:
    """Whether an address-space limit is set and ``used_bytes`` (default: this process's
    virtual size now) is within ``_NEAR_LIMIT_BYTES`` of it (default: ``RLIMIT_AS``)."""
    if limit_bytes is None:
        soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
        limit_bytes = None if soft == resource.RLIM_INFINITY else soft
    if limit_bytes is None:
        return False
    if used_bytes is None:
        used_bytes = _virtual_size_bytes()
        if used_bytes is None:
            return False
    return used_bytes + _NEAR_LIMIT_BYTES >= limit_bytes


def address_limit_below_need(command: str) -> str | None:
    """The out-of-memory phrase when ``RLIMIT_AS`` is below what ``command`` needs at the
    least (``MIN_ADDRESS_SPACE_BYTES``); None when no limit is set or it is enough."""
    need = MIN_ADDRESS_SPACE_BYTES.get(command)
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if need is None or soft == resource.RLIM_INFINITY or soft >= need:
        return None
    return (
        f"out of memory: `pipeline {command}` needs at least {need >> 20} MiB of address "
        f"space, the limit is {soft >> 20} MiB"
    )


def address_headroom_bytes() -> int | None:
    """Address space left under ``RLIMIT_AS`` (limit minus this process's virtual size);
    None without a limit (or where the size is unreadable)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    used = _virtual_size_bytes()
    if soft == resource.RLIM_INFINITY or used is None:
        return None
    return int(soft) - used


def claim_blas_buffer_first() -> None:
    """Under an address-space limit, make numpy's OpenBLAS take its work buffer now, while
    the process is small. OpenBLAS allocates it at the first matrix product and, when that
    fails, prints "Memory allocation still failed" and exits from C: no exception, no
    one-line error. Taken first, the shortage surfaces later where Python sees it (an
    import that cannot map its library, a MemoryError). Without a limit: nothing."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return
    import numpy as np

    np.dot(np.ones((2, 2)), np.ones((2, 2)))


def _virtual_size_bytes() -> int | None:
    """This process's virtual size (Linux ``/proc/self/statm``); None where unreadable."""
    try:
        with open("/proc/self/statm", encoding="ascii") as statm:
            pages = int(statm.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE")


def out_of_memory(err: BaseException) -> str | None:
    """What ran out of memory (a short phrase) when ``err`` or its cause chain is a
    ``MemoryError`` or an import that failed for lack of memory; None otherwise."""
    seen: set[int] = set()
    cause: BaseException | None = err
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, MemoryError):
            return "out of memory"
        if isinstance(cause, OSError) and cause.errno == errno.ENOMEM:  # e.g. an import's scan
            return "out of memory"
        text = str(cause).lower()
        if isinstance(cause, ImportError) and any(t in text for t in _OOM_TEXTS):
            library = str(cause).split(":", 1)[0].strip() if ":" in str(cause) else ""
            return f"out of memory while loading {os.path.basename(library) or cause.name}"
        if any(t in text for t in _ALLOC_TEXTS):  # MuJoCo's FatalError, among others
            return f"out of memory ({type(cause).__name__}: {str(cause)[:80]})"
        if isinstance(cause, SystemError) and any(t in str(cause) for t in _NO_EXCEPTION_TEXTS):
            return "out of memory (the interpreter failed inside an import)"
        cause = cause.__cause__ or cause.__context__
    if _caused_by_allocation(err) and near_address_limit():
        return f"out of memory (at the address-space limit: {type(err).__name__})"
    return None


def _caused_by_allocation(err: BaseException) -> bool:
    """Whether ``err`` or its cause chain is of a kind a failed allocation can raise."""
    seen: set[int] = set()
    cause: BaseException | None = err
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, _ALLOCATION_KINDS):
            return True
        cause = cause.__cause__ or cause.__context__
    return False


def quiet_unraisable_memory_errors() -> None:
    """Drop the "Exception ignored in ..." tracebacks of MemoryErrors a library swallowed
    (matplotlib's font callbacks): the run then fails, or not, on its own terms, and says
    so in one line; other unraisable exceptions are printed as before."""
    import sys

    default = sys.unraisablehook

    def hook(unraisable: sys.UnraisableHookArgs) -> None:
        if not isinstance(unraisable.exc_value, MemoryError):
            default(unraisable)

    sys.unraisablehook = hook
