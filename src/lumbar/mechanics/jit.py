"""The numba decorators of the compiled cores (lumbar.mechanics.kernel, lumbar.mechanics.kernel_residual,
lumbar.muscles.compiled): one cache rule, one error model; without numba they return the plain Python function."""
from __future__ import annotations

try:  # numba is pinned (environment.txt); without it the numpy reference path runs
    from numba import njit
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only in an environment without the pin
    HAVE_NUMBA = False

    def njit(*args, **kwargs):
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

# machine code cached beside the decorated function's file (or in NUMBA_CACHE_DIR); numpy's error model: a division by zero gives
# inf/nan as in the reference path instead of raising
_jit = njit(cache=True, error_model="numpy")
# the helpers, called only from compiled code: no Python (CPython / C) entry point is built for them (about a tenth of
# the core's compile time, measured in alternating pairs with and without)
_inner = njit(cache=True, error_model="numpy", no_cpython_wrapper=True, no_cfunc_wrapper=True) if HAVE_NUMBA \
    else _jit
# helpers that allocate nothing (no np.empty, no numpy function that returns a new array): compiled without numba's
# reference counting (NRT). With it, every array argument of a call is incref'd on entry and decref'd on exit (two
# atomic operations each) and so is every array a tuple unpacking or an index view (``a[k]``) produces: in the
# residual, called per fibre and per contact point, that was about a third of an evaluation's time (perf). A view
# made inside such a helper borrows its parent's memory, which the caller keeps alive for the call.
_leaf = njit(cache=True, error_model="numpy", no_cpython_wrapper=True, no_cfunc_wrapper=True, _nrt=False) \
    if HAVE_NUMBA else _jit
# a leaf helper whose body numba copies into each caller (numba's IR inlining, before type inference): for a function
# whose arguments cost more to pass than its body costs to run (the residual of one scenario takes the model's 25
# arrays, each passed as its 7-11 machine words: copying them at every Newton trial took about a tenth of a solve).
# Only for small bodies called from few places: numba compiles the body once per call site.
_inline_leaf = njit(cache=True, error_model="numpy", no_cpython_wrapper=True, no_cfunc_wrapper=True, _nrt=False,
                    inline="always") if HAVE_NUMBA else _jit
#: the decorators of every compiled module of the package: one cache rule, one error model, one switch
#: (lumbar.mechanics.kernel.active); ``inner_jit`` for functions called only from compiled code, ``leaf_jit`` for
#: such functions that allocate no array (compiled without reference counting; a numpy call that allocates does not
#: compile there), ``inline_leaf_jit`` for such a function whose body is copied into its callers
jit = _jit
inner_jit = _inner
leaf_jit = _leaf
inline_leaf_jit = _inline_leaf
