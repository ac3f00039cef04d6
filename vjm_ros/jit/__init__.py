"""Compiled functions: numba's ``njit`` with the project's options, and where and when it runs.

The physics modules use this package's public surface only: :func:`jit` (compile a function),
:func:`variant` (a compiled copy with other module constants) and :data:`HAVE_NUMBA`. The rest
places the compile:

- :mod:`vjm_ros.jit.deferred`: compiled functions made before numba is imported, and its import
  when the first one is needed;
- :mod:`vjm_ros.jit.sources`: the files that key numba's cache of every compiled function;
- :mod:`vjm_ros.jit.tiers`: entry points that run as plain Python while numba compiles them;
- :mod:`vjm_ros.jit.compile_server`: the process that compiles them in the background;
- :mod:`vjm_ros.jit.numba_internals`: the only module that uses numba's private internals.
"""

from vjm_ros.jit.deferred import HAVE_NUMBA, jit, variant

__all__ = ["HAVE_NUMBA", "jit", "variant"]
