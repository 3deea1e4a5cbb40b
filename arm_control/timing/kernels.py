"""The timing's numba kernels, compiled (or loaded from numba's cache) at the first call of
any of them, not when their modules are imported: a process that imports the timing code but
times nothing yet (the controller, whose plans its worker times) does not load numba, a
third of a second of CPU and a few hundred modules, while it starts.

A kernel is written ``@kernel`` where it would be ``@numba.njit(cache=True)``. At the first
call of any, every kernel defined so far becomes ``numba.njit(cache=True)`` of itself in its
module's globals, where numba resolves one kernel's calls to another when it compiles.
"""

import functools
import threading

_pending = []                   # kernels not yet handed to numba, in the order defined
_lock = threading.Lock()


def kernel(function):
    """``numba.njit(cache=True)``, at the first call of any kernel (see the module)."""
    _pending.append(function)
    return _Deferred(function)


def jit_all() -> None:
    """Every kernel defined so far handed to numba (compiled at its first call, or loaded
    from numba's cache beside its module)."""
    with _lock:
        if not _pending:
            return
        import numba
        for function in _pending:
            function.__globals__[function.__name__] = numba.njit(cache=True)(function)
        _pending.clear()


class _Deferred:
    """A kernel before numba has it: its first call hands them all to numba, then calls the
    compiled one (a caller that kept this object keeps calling through it)."""

    def __init__(self, function):
        self.function = function
        functools.update_wrapper(self, function)

    def __call__(self, *args):
        jit_all()
        return self.function.__globals__[self.function.__name__](*args)
