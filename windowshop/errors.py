"""Errors a user can act on: the CLI and the service print their message, never a traceback.

The service sorts a failed try by its exception: a `UserError` (photos that cannot be placed, an
unreadable or too small upload) fails the job at once with its message; a transient fault (out of
memory, a timeout, a lost connection) is tried again; anything else is a bug, failed at once too.
"""

from __future__ import annotations

import errno


class UserError(Exception):
    """Bad input or a failed step, with a message naming the problem and what to do."""


# Exception classes (by name, so this module imports neither torch nor httpx) that another try
# may not meet: torch's CUDA or CPU allocator out of memory, httpx's lost or refused connection.
_TRANSIENT_NAMES = {"OutOfMemoryError", "TransportError"}


def is_transient(err: BaseException) -> bool:
    """Whether `err` is a fault of the moment (retried), not of the job's input or of the code."""
    if isinstance(err, (MemoryError, TimeoutError, ConnectionError)):
        return True
    return any(cls.__name__ in _TRANSIENT_NAMES for cls in type(err).__mro__)


def failure_reason(err: BaseException) -> str:
    """What a failed job shows for `err`: a user's error as it is, otherwise what happened."""
    if isinstance(err, UserError):
        return str(err)
    if isinstance(err, OSError) and err.errno == errno.ENOSPC:
        return "the service's disk filled up while the job wrote its files; try again later"
    if isinstance(err, MemoryError) or type(err).__name__ == "OutOfMemoryError":
        return f"out of memory ({err}); try fewer or smaller photos"
    return f"internal error ({type(err).__name__}: {err})"
