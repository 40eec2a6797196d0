"""One BLAS thread where matrices are small.

condmon's matrices are small (a regression of a few thousand rows by a few
dozen columns, a covariance of six parameters): a threaded BLAS spends longer
waking its threads than multiplying, and on a busy machine much longer (a
1 ms product took 40 ms with every core asked for), and OpenBLAS's idle
threads spin: ten simulated built-in tests took 0.55 s of CPU in 0.28 s on
two cores, and 0.32 s of CPU on one thread. So every entry point that computes
(``estimate``, ``estimate_joint``, ``isolate``, ``simulate_actuator``,
``simulate_plant``, :class:`~condmon.History`'s ``baseline_add``, ``check``,
``import_table`` and ``forecast``, the command line and the fleet's workers)
runs with the BLAS limited to one thread, through threadpoolctl, and gives the
threads back on return.

A user who wants otherwise sets ``CONDMON_BLAS_THREADS``: a number of
threads, or ``auto`` to leave the BLAS as it is.

Why by hand: threadpoolctl does the limiting; this only chooses the number
once and keeps one controller (a fresh ``threadpool_limits`` looks up every
loaded library again, 0.3 ms a call).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

from condmon.errors import ConfigError

__all__ = ["blas_threads", "small_blas", "one_blas_thread", "ENV"]

#: The environment variable that overrides the number of BLAS threads.
ENV = "CONDMON_BLAS_THREADS"

F = TypeVar("F", bound=Callable[..., Any])

_controller: Any = None


def blas_threads() -> int | None:
    """The BLAS threads condmon's estimation runs with (None: as the BLAS is).

    Example
    -------
    >>> import os
    >>> os.environ.pop("CONDMON_BLAS_THREADS", None) and None
    >>> blas_threads()
    1
    """
    raw = os.environ.get(ENV, "1").strip().lower()
    if raw == "auto":
        return None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ConfigError(f"{ENV}={raw!r}: a number of threads >= 1, or 'auto'")
    return n


@contextmanager
def small_blas() -> Iterator[None]:
    """Run the block with the BLAS limited to :func:`blas_threads` threads."""
    n = blas_threads()
    if n is None:
        yield
        return
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    with _controller.limit(limits=n, user_api="blas"):
        yield


def one_blas_thread(fn: F) -> F:
    """Decorate an estimation entry point to run under :func:`small_blas`."""
    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        with small_blas():
            return fn(*args, **kwargs)

    return wrapped  # type: ignore[return-value]
