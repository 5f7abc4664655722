"""The monotonic clock inside compiled code, so that one compiled filter cycle can still time its stages.

:func:`monotonic` is ``time.perf_counter()`` for a numba function: it calls the C library's ``clock_gettime`` with
``CLOCK_MONOTONIC`` (the clock behind ``time.perf_counter`` on Linux), about 14 ns per reading. It is declared to
the compiler by name, not through a ctypes address, so functions that use it stay in numba's cache
(:mod:`soabench.cache`). The fused cycle (:func:`soabench.gmphd.cycle.step`) reads it between its stages and
returns the stage times that ``StepResult`` reports (docs/method.md §5.2).
"""

from __future__ import annotations

import sys

from soabench.cache import configure_numba_cache

configure_numba_cache()  # before numba is imported: compiled kernels go to the per-user cache, not site-packages

from llvmlite import ir  # noqa: E402
from numba import njit, types  # noqa: E402
from numba.core import cgutils  # noqa: E402
from numba.extending import intrinsic  # noqa: E402

#: ``CLOCK_MONOTONIC`` of <time.h>: 1 on Linux, 6 on macOS
CLOCK_MONOTONIC = 6 if sys.platform == "darwin" else 1


@intrinsic
def _clock_monotonic(typingctx):  # pragma: no cover - compiled
    """seconds of ``clock_gettime(CLOCK_MONOTONIC)`` as a float64 (tv_sec + 1e-9 tv_nsec)."""

    def codegen(context, builder, signature, args):
        i32, i64, f64 = ir.IntType(32), ir.IntType(64), ir.DoubleType()
        timespec = ir.LiteralStructType([i64, i64])  # struct timespec {time_t tv_sec; long tv_nsec;} on LP64
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(i32, [i32, timespec.as_pointer()]), "clock_gettime"
        )
        ts = cgutils.alloca_once(builder, timespec)
        builder.call(fn, [ir.Constant(i32, CLOCK_MONOTONIC), ts])
        sec = builder.sitofp(builder.load(cgutils.gep_inbounds(builder, ts, 0, 0)), f64)
        nsec = builder.sitofp(builder.load(cgutils.gep_inbounds(builder, ts, 0, 1)), f64)
        return builder.fadd(sec, builder.fmul(nsec, ir.Constant(f64, 1e-9)))

    return types.float64(), codegen


@njit(cache=True)
def monotonic():  # pragma: no cover - compiled
    """``time.perf_counter()`` in compiled code (seconds, arbitrary origin)."""
    return _clock_monotonic()
