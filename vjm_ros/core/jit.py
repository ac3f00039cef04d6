"""numba's ``njit`` with the project's options, or the plain function where numba is missing."""

from __future__ import annotations

try:  # numba is optional: without it the kernels run as plain Python
    from numba import njit as _njit

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    HAVE_NUMBA = False


def jit(fn):
    """Compile ``fn`` with numba (no Python objects, cached on disk), or return it unchanged."""
    if HAVE_NUMBA:
        return _njit(cache=True, nogil=True, error_model="numpy")(fn)
    return fn
