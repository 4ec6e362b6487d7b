"""Loading the engine's compiled code into a process without Numba's probe for BLAS.

The first function Numba compiles or loads from its cache in a process imports Numba's CPU registries,
and one of them (``numba.np.arraymath``) checks whether ``np.dot`` and ``np.linalg`` can be compiled by
importing ``scipy.linalg.cython_blas``: SciPy's whole ``linalg`` package, about 0.2 s, in every
simulation job. The engine's kernels call no BLAS (``tests/test_numba_load.py`` runs the engine with
the probe answered "no BLAS" and gets the same curve to the bit), so a job that only runs them answers
the probe at once: while the engine loads, ``scipy.linalg`` is marked absent in ``sys.modules`` (the
import system then raises ImportError for it, which the probe reads as "no BLAS"), and the mark is
removed afterwards, so a later ``import scipy.linalg`` in the process works as usual. A kernel that
called BLAS would fail to compile inside this block with Numba's message, in the tests, on a fresh
clone (an empty cache), not silently.
"""
from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

_PROBED = "scipy.linalg"


@contextmanager
def without_blas_probe() -> Iterator[None]:
    """Within the block Numba's first load finds no BLAS (module docstring); a process whose registries
    are already loaded, or that imported ``scipy.linalg`` itself, is left as it is."""
    if _PROBED in sys.modules or "numba.np.arraymath" in sys.modules:
        yield
        return
    sys.modules[_PROBED] = None  # type: ignore[assignment]  # import raises ModuleNotFoundError
    try:
        yield
    finally:
        if _PROBED in sys.modules and sys.modules[_PROBED] is None:
            del sys.modules[_PROBED]
