"""How many threads the compiled engine uses.

The engine evaluates the element kernels, the frame updates and the products of the
stabilised index-2 iteration in parts on a small pool of threads (``se3dyn/_core/pool.hpp``),
and the sparse factorisations and triangular solves of large models (3000 unknowns and more
whose graph a two-way dissection splits, a chain or a long mechanism) take the two halves of
the dissection at once (``sparse_lu.hpp``, ``sparse_ldlt.hpp``). The elements are evaluated in a
fixed order of colours and chunks (``se3dyn/_core/engine.hpp``) and the factorisations follow
the dissection whatever the thread count, so **the results are the same to the last bit for any
number of threads**; only the time changes. Models with fewer than 64 elements of every type
and fewer than 3000 unknowns never leave one thread (the parts would cost more than they save).

The number of threads is one setting of the process:

* ``SE3DYN_THREADS`` in the environment (a whole number from 1 to :data:`MAX_THREADS`), read
  when the engine is first loaded (``se3dyn run`` reads it first, before its results file is
  made; ``--threads`` replaces it);
* :func:`set_threads` (``se3dyn run --threads N`` on the command line);
* by default, the cores this process may run on (``os.sched_getaffinity``).

Worker processes of a sweep (:mod:`se3dyn.sweep`) run one thread each: the sweep already
keeps every core busy with a run.
"""
from __future__ import annotations

import numbers
import os

from se3dyn.errors import Se3dynError, _short_repr

__all__ = ["set_threads", "get_threads", "default_threads"]

ENV = "SE3DYN_THREADS"


def default_threads() -> int:
    """The cores this process may run on (``os.sched_getaffinity``; ``os.cpu_count`` where
    that does not exist)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


#: The most threads the engine can use: the pool runs a loop of more parts than this serially
#: (``_core/pool.hpp``: the parts of a loop travel in 8 bits, 255 meaning "stop").
MAX_THREADS = 254


def _check(n, where: str) -> int:
    """``n`` as a thread count (an integer, or a string of decimal digits as in the
    environment and on the command line), or a :class:`Se3dynError` naming ``where``."""
    k = None
    if isinstance(n, numbers.Integral) and not isinstance(n, bool):
        k = int(n)
    elif isinstance(n, str) and n.strip().isascii() and n.strip().isdigit():
        digits = n.strip().lstrip("0") or "0"
        k = int(digits) if len(digits) <= 4 else MAX_THREADS + 1  # (never a 5000-digit int)
    if k is None or not 1 <= k <= MAX_THREADS:
        raise Se3dynError(f"{where}: expected a whole number of threads from 1 to "
                          f"{MAX_THREADS}, got {_short_repr(n)}")
    return k


#: A thread count set before the engine was loaded (:func:`set_threads`): the engine starts
#: with it instead of reading ``SE3DYN_THREADS``.
_requested: int | None = None


def initial_threads() -> int:
    """The thread count the engine starts with when it is loaded: that of a
    :func:`set_threads` before, else :func:`from_environment`."""
    return _requested if _requested is not None else from_environment()


def from_environment() -> int:
    """The thread count of ``SE3DYN_THREADS``, or :func:`default_threads` when it is unset or
    empty."""
    raw = os.environ.get(ENV, "").strip()
    return default_threads() if raw == "" else _check(raw, f"environment variable {ENV}")


def set_threads(n: int | None = None) -> int:
    """Set the number of threads of the compiled engine (the process's one pool).

    Parameters
    ----------
    n : int or None
        Threads, 1 to :data:`MAX_THREADS`; None: ``SE3DYN_THREADS`` or the cores this process
        may run on. Set before the engine is first loaded, it is used instead of
        ``SE3DYN_THREADS`` (which is then not read).

    Raises
    ------
    Se3dynError
        ``n`` (or ``SE3DYN_THREADS``) not a whole number from 1 to :data:`MAX_THREADS`.

    Returns
    -------
    int
        The number now in use.
    """
    global _requested
    k = from_environment() if n is None else _check(n, "set_threads(n)")
    _requested = k
    pool().set_threads(k)
    return k


def get_threads() -> int:
    """The number of threads the compiled engine uses."""
    return int(pool().threads())


_started = False


def pool():
    """The compiled module (its thread pool), started with :func:`initial_threads` once."""
    global _started
    from se3dyn._core import _engine

    if not _started:
        _started = True
        _engine.set_threads(initial_threads())
    return _engine
