"""The ``pipeline`` command: a thin Typer app. Parse, call, print, exit code.

Errors that are the user's input (:class:`PipelineError`) print one
``error: ...`` line and exit 1; ``--debug`` shows the traceback instead.

Each command group is a module registered on the one Typer app (:mod:`pipeline.cli.root`):
:mod:`~pipeline.cli.kinematics_cmd` (``robots``, ``fk``, ``ik``, ``ik-check``),
:mod:`~pipeline.cli.teach_cmd`, :mod:`~pipeline.cli.controllers_cmd` (``check-controller``),
:mod:`~pipeline.cli.record_cmd` (``record``, ``campaigns``), :mod:`~pipeline.cli.report_cmd`
and :mod:`~pipeline.cli.identify_cmd`.
"""

from __future__ import annotations

import errno
import os
import signal
import sys
import threading
from typing import NoReturn

from pipeline.cli.root import app, console

# isort: off
# the command modules register their commands on ``app``; `pipeline --help` lists them in
# this order
from pipeline.cli import (  # noqa: F401
    kinematics_cmd,
    teach_cmd,
    controllers_cmd,
    record_cmd,
    report_cmd,
    identify_cmd,
)

# isort: on
from pipeline import supervise
from pipeline.argv import hoist_root_options
from pipeline.errors import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    PipelineError,
    handle_sigterm,
    interrupt_exit,
)
from pipeline.memory import (
    OUT_OF_MEMORY_HINT,
    claim_blas_buffer_first,
    out_of_memory,
    quiet_unraisable_memory_errors,
)

__all__ = ["app", "console", "main"]


def _interrupt_in_chain(err: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or :class:`Terminated` for SIGTERM) anywhere in the
    exception's cause chain, or None."""
    seen: set[int] = set()
    cause: BaseException | None = err
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


def _stop(err: BaseException) -> NoReturn:
    """One line (``interrupted`` or ``terminated``) and 130 or 143."""
    word, code = interrupt_exit(err)
    sys.stderr.write(f"{word}\n")
    sys.exit(code)


_DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS, errno.EFBIG})


def main() -> None:
    """Console-script entry point."""
    sys.argv = [sys.argv[0], *hoist_root_options(sys.argv[1:])]
    debug = "--debug" in sys.argv[1:]
    # A job started in the background by a non-interactive shell inherits SIGINT ignored;
    # `kill -INT` must still stop a run (and say what it finished).
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    handle_sigterm()  # SIGTERM takes Ctrl-C's path: the same cleanup, then 143
    # rerun-sdk's own log lines (a failing .rrd file sink prints three) would follow our
    # one-line error; RUST_LOG set by the user still wins
    os.environ.setdefault("RUST_LOG", "off")
    if not debug:
        quiet_unraisable_memory_errors()
    try:
        claim_blas_buffer_first()  # before any library can fill the address space
        app()
    except SystemExit as exit_:
        if exit_.code == EXIT_INTERRUPTED:  # typer ends a command's Ctrl-C silently with 130
            _stop(_interrupt_in_chain(exit_) or KeyboardInterrupt())
        raise
    except KeyboardInterrupt as err:
        if debug:
            raise
        _stop(err)
    except ImportError as err:
        # Ctrl-C inside a C extension's module init surfaces as "initialization failed"
        interrupt = _interrupt_in_chain(err)
        if not debug and interrupt is None and out_of_memory(err):
            _out_of_memory(err)
        if debug or interrupt is None:
            raise
        _stop(interrupt)
    except OSError as err:
        if not debug and out_of_memory(err):  # ENOMEM, e.g. an import's directory scan
            _out_of_memory(err)
        # a full or failing disk on a write path no stage turned into a PipelineError
        if debug or err.errno not in _DISK_ERRNOS:
            raise
        where = f"{err.filename}: " if err.filename else ""
        sys.stderr.write(f"error: {where}{err.strerror or err}\n")
        sys.exit(1)
    except PipelineError as err:
        if debug:
            raise
        code = getattr(err, "exit_code", 1)
        if code in (EXIT_INTERRUPTED, EXIT_TERMINATED):  # record's Interrupted
            sys.stderr.write(f"{err}\n")
            sys.exit(code)
        sys.stderr.write(f"error: {err}\n")
        sys.exit(1)
    except Exception as err:
        if debug or not out_of_memory(err):
            raise
        _out_of_memory(err)


def _out_of_memory(err: BaseException) -> NoReturn:
    """One line for a run that ran out of memory (a MemoryError, or a library that could not
    be loaded for lack of it), and exit 1."""
    sys.stderr.write(f"error: {out_of_memory(err)}: {OUT_OF_MEMORY_HINT}\n")
    sys.stderr.flush()
    sys.stdout.flush()
    # Out of memory, the libraries' own teardown may crash (Polars' allocator, after a
    # thread it could not start): end here, with the exit mark a supervisor waits for
    supervise.write_exit_mark()
    os._exit(1)
