"""Compiled core of the equilibrium solver: force evaluation, Jacobian assembly and the damped Newton step,
per scenario, in numba (machine code cached on disk, ``cache=True``). This module holds the switch, the packing of
the model's arrays, the Newton iteration and the Python entry points; the compiled residual and Jacobian of one
scenario (element laws and assembly) are :mod:`lumbar.mechanics.kernel_residual`, the decorators
:mod:`lumbar.mechanics.jit`.

The reference is the vectorised numpy path (:meth:`lumbar.mechanics.model.SpineModel.evaluate_reference` and
``lumbar.mechanics.solve.newton_reference``); the compiled core computes the same quantities with the same formulas,
element by element, and runs the same Newton iteration (modified Newton with the same eigenvalue shift, step
limits and backtracking line search) scenario by scenario: both paths give the same equilibria, iteration counts
and flags up to round-off (tests/test_kernel.py checks 1e-9 relative). What makes it fast: no per-call numpy
overhead (the batched numpy path spends most of its time in small array operations), slack fibres and open
contact points skipped (they add exact zeros; a point is screened by one affine map per surface and body pair,
:data:`SCREEN_M`, before its exact gap is computed), the Jacobian assembled from one 3x3 stiffness per element, and a
Cholesky test instead of an eigenvalue decomposition for the modified-Newton shift (the eigenvalues are computed
only where the test fails, i.e. where the shift is needed).

Nothing of the model is frozen: :func:`model_data` reads the model's current arrays at every call, so callers may
change ``f_par``, ``f_l0``, ``f_scale``, ``k_stiff``, a disc's ``k_shear`` ... in place between calls (or replace
them). The assembled tuple is kept between calls only while it provably shows the model's state: the same array
objects, passed through without copies, and equal disc and surface values.

Scenarios of a batch that start from the same state with the same element data (a batch of loads from one
equilibrium: the benchmark, the virtual experiments) share the start's internal forces and Jacobian, which do not
depend on the loads: their first residual is their loads plus the shared internal forces, as for each scenario solved
alone (bit-identical, tests/test_kernel.py).

Switch: the environment variable ``LUMBAR_KERNEL`` (``compiled``, the default, or ``reference``) at import, or
:func:`set_mode` / :func:`use` at run time. Without numba the reference path runs (:func:`active` is False) and
one warning says so.
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import tempfile
from pathlib import Path

try:  # POSIX; elsewhere the first use is not serialised between processes
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

import numpy as np

from . import kernel_residual, profile
from .elements.ligament import LAW_CABLE, LAW_RUPP, LAW_SOFTPLUS  # noqa: F401 - the laws' codes, for callers
from .jit import HAVE_NUMBA, njit
from .jit import inner_jit as _inner
from .jit import jit as _jit
from .jit import leaf_jit as _leaf
from .kernel_residual import (
    ACC,
    SCREEN_M,  # noqa: F401 - the contact screen's margin (kernel.SCREEN_M, as before the residual had a module)
    copy2,
    copy3,
    copy_array,
    eval_one,
    evaluate_batch,
    rotation_exp,
    rotation_log,
    same_array,
    same_row,
    zero4,
    zero_array,
)

log = logging.getLogger(__name__)
#: the decorators of the compiled modules (lumbar.mechanics.jit), kept here for lumbar.muscles.compiled
jit = _jit
inner_jit = _inner

#: SHA-256 of kernel_residual.py. numba keys the on-disk cache of a compiled function on its own source file (time
#: stamp and size), and the machine code of newton_batch here holds the residual it calls there: a change of that
#: file alone would leave newton_batch's cached code stale. While the digest matches, newton_batch is cached like
#: every kernel; when it does not (kernel_residual.py edited), newton_batch compiles without the cache in that
#: process, and tests/test_kernel.py fails until the digest here is updated, the edit of this file that retires the
#: cache entry.
RESIDUAL_SHA256 = "62a8f26ca0877c1e8e7c30dfda0e3ab5d348a64df6bfb6d3f146ec7f7fc1699d"


def residual_pinned(digest: str = RESIDUAL_SHA256) -> bool:
    """True when kernel_residual.py is the file whose SHA-256 is ``digest`` (see :data:`RESIDUAL_SHA256`)."""
    try:
        return hashlib.sha256(Path(kernel_residual.__file__).read_bytes()).hexdigest() == digest
    except OSError:           # no source beside the module: nothing to pin, nothing cached from it
        return False


_newton_jit = _jit if residual_pinned() else njit(cache=False, error_model="numpy")
_newton_leaf = _leaf if residual_pinned() else njit(cache=False, error_model="numpy", no_cpython_wrapper=True,
                                                      no_cfunc_wrapper=True, _nrt=False)

#: Newton trials from residuals below LAZY x the tolerances are evaluated without the Jacobian first (newton_batch);
#: on the default unit's benchmark scenarios 1e3, 1e4, 1e5, 1e6 and 1e7 cost 83.9, 83.1, 82.8, 85.3 and 88.2 us of
#: evaluations per equilibrium (counted evaluations x the measured cost with / without the Jacobian; all: 85.7)
LAZY = 1e5
MODES = ("compiled", "reference")
_state = {"mode": os.environ.get("LUMBAR_KERNEL", "compiled"), "warned": False, "ready": False}
if _state["mode"] not in MODES:
    raise ValueError(f"environment variable LUMBAR_KERNEL={_state['mode']!r}; expected one of {MODES}")


def set_mode(mode: str) -> str:
    """Select the solver core for this process: ``compiled`` or ``reference``; returns the previous mode."""
    if mode not in MODES:
        raise ValueError(f"solver kernel mode {mode!r}; expected one of {MODES}")
    old, _state["mode"] = _state["mode"], mode
    return old


def mode() -> str:
    return _state["mode"]


@contextlib.contextmanager
def use(mode_name: str):
    """``with use("reference"): ...`` runs the block on the given solver core."""
    old = set_mode(mode_name)
    try:
        yield
    finally:
        set_mode(old)


def active() -> bool:
    """True when the compiled core serves ``SpineModel.evaluate`` and ``solve.newton``."""
    if _state["mode"] != "compiled":
        return False
    if not HAVE_NUMBA:
        if not _state["warned"]:
            log.warning("numba is not installed (pinned in environment.txt): the equilibrium solver runs on its "
                        "numpy reference path, several times slower; pip install -r environment.txt")
            _state["warned"] = True
        return False
    return True


# ---------------------------------------------------------------------------------------------------- packing
def _f64(a, shape=None):
    """A C-contiguous, writeable float64 array (one compiled signature for every caller: numba types read-only and
    writeable arrays apart, and a broadcast view is read-only)."""
    a = np.asarray(a, dtype=np.float64)
    if shape is not None:
        a = a.reshape(shape)
    f = a.flags
    return a if f.c_contiguous and f.writeable else np.array(a, dtype=np.float64, order="C")


def _i64(a):
    a = np.asarray(a, dtype=np.int64)
    f = a.flags
    return a if f.c_contiguous and f.writeable else np.array(a, dtype=np.int64, order="C")


_TORQUE_ORDER = ("lateral_bending", "flexion", "extension", "axial_rotation")


_MODEL_ARRAYS = ("c", "f_a", "f_b", "f_sa", "f_sb", "f_extra", "f_law", "f_par", "f_scale", "k_a", "k_b", "k_s", "k_surf",
                 "k_stiff")


def _disc_law(d) -> tuple:
    """A disc's lateral shear stiffness [N/m] (its k_shear where none is given) and the code of its torque law."""
    from .elements.disc import TORQUE_LAWS  # noqa: PLC0415
    if d.law not in TORQUE_LAWS:
        raise ValueError(f"disc {d.name!r}: unknown torque law {d.law!r}; expected one of {TORQUE_LAWS}")
    ksl = d.k_shear if d.k_shear_lateral is None else d.k_shear_lateral
    return float(ksl), (kernel_residual.DISC_LAW_CUBIC_DEG if d.law == "cubic_deg" else kernel_residual.DISC_LAW_EQ3)


def _elements_key(surfs, discs) -> tuple:
    """The values of the facet surfaces and discs that the kernel reads (Python objects, changed by attribute)."""
    key = []
    for s in surfs:
        key += (np.asarray(s.origin, float).tobytes(), np.asarray(s.axes, float).tobytes(),
                np.asarray(s.coef, float).tobytes())
    for d in discs:
        key += (d.upper, d.lower, float(d.k_quadratic), float(d.k_linear), float(d.k_shear), *_disc_law(d),
                np.asarray(d.centre, float).tobytes(), np.asarray(d.frame, float).tobytes(),
                np.asarray([d.torque[k] for k in _TORQUE_ORDER], float).tobytes())
    return tuple(key)


def model_data(model) -> tuple:
    """The model's current element arrays as one tuple of contiguous arrays.

    Read at every call: the tuple is rebuilt unless the model's arrays are the same objects as at the last call
    (their contents changed in place are seen through them: every one of them is passed through without a copy)
    and the surfaces' and discs' values are equal (a key of their bytes, cheaper than the arrays' assembly; a
    caller that evaluates small batches many times, the muscle model's levels, spends most of a call here)."""
    surfs, discs = model.surfaces, model.discs
    arrays = tuple(getattr(model, a) for a in _MODEL_ARRAYS)
    key = (tuple(map(id, arrays)), float(model.slack_width_pct), float(model.contact_eps), _elements_key(surfs, discs))
    cached = model.__dict__.get("_kernel_model_data")
    if cached is not None and cached[0] == key:
        return cached[1]
    ns, nd = len(surfs), len(discs)
    md = (
        _f64(model.c, (-1, 3)),
        _i64(model.f_a), _i64(model.f_b), _f64(model.f_sa, (-1, 3)), _f64(model.f_sb, (-1, 3)),
        _f64(model.f_extra), _i64(model.f_law), _f64(model.f_par, (-1, 5)), _f64(model.f_scale),
        float(model.slack_width_pct),
        _i64(model.k_a), _i64(model.k_b), _f64(model.k_s, (-1, 3)), _i64(model.k_surf), _f64(model.k_stiff),
        float(model.contact_eps),
        _f64([s.origin for s in surfs], (ns, 3)), _f64([s.axes for s in surfs], (ns, 3, 3)),
        _f64([s.coef for s in surfs], (ns, 5)),
        _i64([d.upper for d in discs]), _i64([d.lower for d in discs]),
        _f64([d.centre for d in discs], (nd, 3)), _f64([d.frame for d in discs], (nd, 3, 3)),
        _f64([(d.k_quadratic, d.k_linear, d.k_shear, *_disc_law(d)) for d in discs], (nd, 5)),
        _f64([[d.torque[k] for k in _TORQUE_ORDER] for d in discs], (nd, 4, 3)),
    )
    # cache only where every model array was passed through (a copy would not see a later change in place)
    if all(isinstance(a, np.ndarray) and (a.size == 0 or np.may_share_memory(md[i], a))
           for i, a in zip((0, 1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 13, 14), arrays)):
        model.__dict__["_kernel_model_data"] = (key, md)
    return md


def _rows(a, B, n):
    """A per-scenario weight array (scalar, (n,), (B, 1), (B, n), ...) as (1, n) or (B, n)."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim >= 2 and a.shape[0] == B and B > 1:
        return _f64(np.broadcast_to(a.reshape(B, -1), (B, n)))
    return _f64(np.broadcast_to(a.reshape(-1) if a.ndim else a, (n,))[None])


def _is_one(a) -> bool:
    return isinstance(a, (int, float)) and a == 1.0


def scenario_data(model, B, loads, fmask, cmask, params) -> tuple:
    """Per-scenario arrays (rows 1 or B): loads, fibre and contact weights, slack lengths, disc tension, offset.
    The defaults (no loads, every element at full weight, no offset) are arrays kept on the model, read-only to the
    kernel."""
    nb, nf, nc, nd = model.nb, model.nf, model.nc, model.nd
    params = params or {}
    const = model.__dict__.get("_kernel_defaults")
    if const is None or const[0] != (nb, nf, nc):
        const = ((nb, nf, nc), np.zeros((1, nb, 6)), np.ones((1, nf)), np.ones((1, nc)), np.zeros((1, 3)))
        model.__dict__["_kernel_defaults"] = const
    if loads is None:
        L = const[1]
    else:
        L = np.asarray(loads, dtype=np.float64)
        L = _f64(L if L.ndim == 3 and L.shape[0] in (1, B) else np.broadcast_to(L, (B, nb, 6)))
    fm = const[2] if _is_one(fmask) else _rows(fmask, B, nf)
    cm = const[3] if _is_one(cmask) else _rows(cmask, B, nc)
    l0 = np.asarray(model.f_l0, dtype=np.float64)
    sc = params.get("fibre_l0_scale")
    l0 = _f64(l0[None] if sc is None else np.broadcast_to(l0 * np.asarray(sc, float).reshape(B, -1), (B, nf)))
    kt = params.get("k_tension")
    if kt is None:
        kt = _f64([d.k_tension for d in model.discs], (1, nd))
    else:
        kt = np.reshape(np.asarray(kt, float), (-1, 1))
        kt = _f64(np.broadcast_to(kt, (kt.shape[0], nd)))
    off = params.get("disc_phi_offset")
    off = const[4] if off is None else _f64(off, (-1, 3))
    return L, fm, cm, l0, kt, off


def evaluate(model, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
    """Compiled ``SpineModel.evaluate`` (same arguments and results as the reference path)."""
    _first_use()
    x, R = _f64(x), _f64(R)
    B, nb = x.shape[0], model.nb
    L, fm, cm, l0, kt, off = scenario_data(model, B, loads, fmask, cmask, params)
    Q = np.empty((B, nb, 6))
    J = np.empty((B, nb, 6, nb, 6)) if jacobian else np.zeros((1, nb, 6, nb, 6))
    evaluate_batch(x, R, L, fm, cm, l0, kt, off, bool(jacobian), model_data(model), Q, J)
    return Q, (J if jacobian else None)


# ---------------------------------------------------------------------------------------------------- Newton
@_leaf
def _cholesky_ok(A, shift, W):
    """True if A - shift*I is positive definite (Cholesky without pivoting; W is work space)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j] - (shift if i == j else 0.0)
            for k in range(j):
                s -= W[i, k] * W[j, k]
            if i == j:
                if not s > 0.0:
                    return False
                W[i, i] = np.sqrt(s)
            else:
                W[i, j] = s / W[j, j]
    return True


@_leaf
def _lu_solve(A, bvec, out):
    """Solve A out = bvec by LU with partial pivoting (A and bvec are overwritten)."""
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
            bvec[k], bvec[p] = bvec[p], bvec[k]
        for i in range(k + 1, n):
            m = A[i, k] / A[k, k]
            A[i, k] = m
            for j in range(k + 1, n):
                A[i, j] -= m * A[k, j]
            bvec[i] -= m * bvec[k]
    for i in range(n - 1, -1, -1):
        s = bvec[i]
        for j in range(i + 1, n):
            s -= A[i, j] * out[j]
        out[i] = s / A[i, i]


@_leaf
def _merit(Q, lscale):
    m1 = 0.0
    m2 = 0.0
    for k in range(Q.shape[0]):
        for i in range(3):
            m1 += Q[k, i] ** 2
            m2 += (Q[k, 3 + i] / lscale) ** 2
    return m1 + m2


@_leaf
def _norms(Q):
    rf = 0.0
    rm = 0.0
    for k in range(Q.shape[0]):
        for i in range(3):
            v = abs(Q[k, i])
            if v > rf or v != v:
                rf = v
            v = abs(Q[k, 3 + i])
            if v > rm or v != v:
                rm = v
    if rf != rf or rm != rm:
        return np.nan if rf != rf else rf, np.nan if rm != rm else rm
    return rf, rm


@_leaf
def _lowest_eigenvalue(sym, a):
    """The lowest eigenvalue of the symmetric matrix sym, by cyclic Jacobi rotations on the work array a (n, n),
    to round-off (numpy's eigvalsh, the reference path's, allocates: the Newton iteration runs without reference
    counting). Called only where the Cholesky test of the modified Newton step fails."""
    n = sym.shape[0]
    total = 0.0
    for i in range(n):
        for j in range(n):
            a[i, j] = sym[i, j]
            total += sym[i, j] * sym[i, j]
    for _sweep in range(60):
        off = 0.0
        for i in range(n):
            for j in range(i + 1, n):
                off += a[i, j] * a[i, j]
        if not off > 1e-32 * total:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                if abs(theta) > 1e150:
                    t = 0.5 / theta
                else:
                    t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                    if theta < 0.0:
                        t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * c
                for k in range(n):
                    akp, akq = a[k, p], a[k, q]
                    a[k, p] = c * akp - sn * akq
                    a[k, q] = sn * akp + c * akq
                for k in range(n):
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k] = c * apk - sn * aqk
                    a[q, k] = sn * apk + c * aqk
    lam = a[0, 0]
    for i in range(1, n):
        lam = min(lam, a[i, i])
    return lam


@_jit
def lowest_eigenvalue(sym):
    """Python entry of :func:`_lowest_eigenvalue` (for tests)."""
    return _lowest_eigenvalue(np.ascontiguousarray(sym), np.empty_like(sym))


@_leaf
def _step_matrix(J, reg, S, A, sym, W):
    """First half of the modified Newton step (lumbar.mechanics.solve._modified_newton_step): A = (-J + diag(reg))
    in scaled variables and its symmetric part sym; returns (0, scale) where sym is positive definite (no shift),
    (1, scale) where it is not finite, (2, scale) where its lowest eigenvalue decides the shift (numpy's eigvalsh
    allocates: the caller computes it, see _step_solve)."""
    n = reg.shape[0]
    nb = J.shape[0]
    for bi in range(nb):
        for k in range(6):
            i = 6 * bi + k
            for bj in range(nb):
                for m in range(6):
                    j = 6 * bj + m
                    A[i, j] = (-J[bi, k, bj, m] + (reg[i] if i == j else 0.0)) * S[i] * S[j]
    scale = 0.0
    for i in range(n):
        for j in range(n):
            sym[i, j] = 0.5 * (A[i, j] + A[j, i])
        if abs(sym[i, i]) > scale:
            scale = abs(sym[i, i])
    for i in range(n):
        for j in range(n):
            if not np.isfinite(sym[i, j]):
                return 1, scale
    if _cholesky_ok(sym, 1e-8 * scale, W):
        return 0, scale
    return 2, scale


@_leaf
def _step_solve(Q, S, A, W, rhs, d, mu):
    """Second half of the modified Newton step: solve (A + mu I) d = S Q and unscale d."""
    for k in range(Q.shape[0]):
        for m in range(6):
            i = 6 * k + m
            A[i, i] += mu
            rhs[i] = S[i] * Q[k, m]
    _lu_solve(A, rhs, W[0])
    for k in range(d.shape[0]):
        for m in range(6):
            d[k, m] = W[0, 6 * k + m] * S[6 * k + m]


@_newton_jit
def newton_batch(x0, R0, L, fm, cm, l0, kt, off, md, max_iter, tol_f, tol_m, max_st, max_sr, reg, S, lscale,
                 x, R, conv, res_f, res_m, iters):
    """Damped modified Newton, scenario by scenario (lumbar.mechanics.solve.newton_reference, same steps)."""
    nb = x0.shape[1]
    n = 6 * nb
    Q, Qt = np.empty((nb, 6)), np.empty((nb, 6))
    J, Jt = np.empty((nb, 6, nb, 6)), np.empty((nb, 6, nb, 6))
    A, sym, W = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    rhs, d = np.empty(n), np.empty((nb, 6))
    xt, Rt, E = np.empty((nb, 3)), np.empty((nb, 3, 3)), np.empty((3, 3))
    wv = np.empty(3)
    w3, w33, acc = np.empty((16, 4)), np.empty((8, 3, 3)), np.empty((nb, ACC))
    # the internal forces Q0 and the Jacobian J0 at the start state (neither depends on the loads): shared by
    # consecutive scenarios that start from the same state with the same element data (a batch of loads from one
    # equilibrium), whose start residual is then their loads plus Q0, as that of a scenario solved alone (the results
    # are bit-identical to unshared solves)
    J0, Q0 = np.empty((nb, 6, nb, 6)), np.empty((nb, 6))
    _newton_scenarios(x0, R0, L, fm, cm, l0, kt, off, md, max_iter, tol_f, tol_m, max_st, max_sr, reg, S, lscale,
                      x, R, conv, res_f, res_m, iters, Q, Qt, J, Jt, J0, Q0, A, sym, W, rhs, d, xt, Rt, E, wv, w3, w33,
                      acc)


@_newton_leaf
def _newton_scenarios(x0, R0, L, fm, cm, l0, kt, off, md, max_iter, tol_f, tol_m, max_st, max_sr, reg, S, lscale,
                      x, R, conv, res_f, res_m, iters, Q, Qt, J, Jt, J0, Q0, A, sym, W, rhs, d, xt, Rt, E, wv, w3, w33,
                      acc):
    """The iteration of newton_batch on its work arrays, compiled without reference counting (the residual's
    arguments, inlined here, are then plain values: no reference count to raise and lower at every trial)."""
    B, nb = x0.shape[0], x0.shape[1]
    s0 = -1
    # run-time bools: a literal would type (and compile) eval_one a second time
    want_j = max_iter >= 0
    no_j = not want_j
    for s in range(B):
        Ls = L[s if L.shape[0] > 1 else 0]
        fms, cms = fm[s if fm.shape[0] > 1 else 0], cm[s if cm.shape[0] > 1 else 0]
        l0s, kts, offs = l0[s if l0.shape[0] > 1 else 0], kt[s if kt.shape[0] > 1 else 0], off[s if off.shape[0] > 1 else 0]
        xs, Rs = x[s], R[s]
        copy_array(xs, x0[s])
        copy_array(Rs, R0[s])
        if s0 < 0 or not (same_array(x0[s], x0[s0]) and same_array(R0[s], R0[s0]) and same_row(fm, s, s0)
                          and same_row(cm, s, s0) and same_row(l0, s, s0) and same_row(kt, s, s0)
                          and same_row(off, s, s0)):
            zero_array(Q0)
            zero_array(J0)
            eval_one(xs, Rs, Q0, J0, want_j, md, fms, cms, l0s, kts, offs, w3, w33, acc)
            s0 = s
        for k in range(nb):          # the start's residual: its loads plus the internal forces it shares
            for i in range(6):
                Q[k, i] = Ls[k, i] + Q0[k, i]
        copy_array(J, J0)
        conv[s] = False
        iters[s] = 0
        res_f[s] = np.inf
        res_m[s] = np.inf
        for it in range(max_iter + 1):
            rf, rm = _norms(Q)
            res_f[s], res_m[s] = rf, rm
            if rf < tol_f and rm < tol_m:
                conv[s] = True
                break
            if it == max_iter:
                break
            shift, scale = _step_matrix(J, reg, S, A, sym, W)
            mu = 0.0
            if shift == 1:
                mu = np.nan
            elif shift == 2:
                lam = _lowest_eigenvalue(sym, W)
                if lam < 1e-8 * scale:
                    mu = -lam + 1e-6 * scale
            _step_solve(Q, S, A, W, rhs, d, mu)
            st = 0.0
            sr = 0.0
            for k in range(nb):
                a1 = np.sqrt(d[k, 0] ** 2 + d[k, 1] ** 2 + d[k, 2] ** 2)
                a2 = np.sqrt(d[k, 3] ** 2 + d[k, 4] ** 2 + d[k, 5] ** 2)
                st = max(st, a1)
                sr = max(sr, a2)
            lim = max(1.0, max(st / max_st, sr / max_sr))
            for k in range(nb):
                for i in range(6):
                    d[k, i] = d[k, i] / lim
            m0 = _merit(Q, lscale)
            # near the solution (residuals within LAZY x the tolerances: Newton's next step is likely to end the solve)
            # trials are evaluated without the Jacobian, which a rejected trial or a converged one never uses; an
            # accepted trial that has not converged is evaluated again with it (the same residual, bit for bit)
            lazy = rf < LAZY * tol_f and rm < LAZY * tol_m
            alpha = 1.0
            for ls in range(10):
                for k in range(nb):
                    for i in range(3):
                        xt[k, i] = xs[k, i] + alpha * d[k, i]
                        wv[i] = alpha * d[k, 3 + i]
                    rotation_exp(wv, E)
                    for i in range(3):
                        for j in range(3):
                            Rt[k, i, j] = E[i, 0] * Rs[k, 0, j] + E[i, 1] * Rs[k, 1, j] + E[i, 2] * Rs[k, 2, j]
                copy2(Qt, Ls)
                if lazy:
                    eval_one(xt, Rt, Qt, Jt, no_j, md, fms, cms, l0s, kts, offs, w3, w33, acc)
                else:
                    zero4(Jt)
                    eval_one(xt, Rt, Qt, Jt, want_j, md, fms, cms, l0s, kts, offs, w3, w33, acc)
                if _merit(Qt, lscale) < m0 * (1.0 - 1e-4 * alpha) or ls == 9:
                    if lazy and it + 1 < max_iter:
                        rft, rmt = _norms(Qt)
                        if not (rft < tol_f and rmt < tol_m):
                            copy2(Qt, Ls)
                            zero4(Jt)
                            eval_one(xt, Rt, Qt, Jt, want_j, md, fms, cms, l0s, kts, offs, w3, w33, acc)
                    break
                alpha = 1.0 if ls == 8 else alpha * 0.5
            copy2(xs, xt)
            copy3(Rs, Rt)
            Q, Qt = Qt, Q
            J, Jt = Jt, J
            iters[s] += 1


def newton(model, x, R, loads, fmask, cmask, params, max_iter, tol_force, tol_moment, max_step_trans,
           max_step_rot, reg, S, length_scale):
    """Compiled ``lumbar.mechanics.solve.newton`` (same arguments and results as the reference path)."""
    _first_use()
    x0, R0 = _f64(x), _f64(R)
    B = x0.shape[0]
    L, fm, cm, l0, kt, off = scenario_data(model, B, loads, fmask, cmask, params)
    xo, Ro = np.empty_like(x0), np.empty_like(R0)
    conv, res_f, res_m, iters = np.zeros(B, bool), np.empty(B), np.empty(B), np.zeros(B, np.int64)
    newton_batch(x0, R0, L, fm, cm, l0, kt, off, model_data(model), int(max_iter), float(tol_force),
                 float(tol_moment), float(max_step_trans), float(max_step_rot), _f64(reg), _f64(S),
                 float(length_scale), xo, Ro, conv, res_f, res_m, iters)
    return xo, Ro, conv, res_f, res_m, iters


@_jit
def log_batch(flat, out):
    """Rotation vectors ``out`` (n, 3) of the rotation matrices ``flat`` (n, 3, 3), the compiled
    :func:`lumbar.mechanics.so3.log` (the residual's own ``rotation_log``: scipy's steps, bit for bit); False, with ``out``
    unfinished, where a matrix is not orthogonal to 1e-12 or not right-handed (the caller then takes the reference,
    which orthogonalises it or refuses it)."""
    q4 = np.empty(4)
    for n in range(flat.shape[0]):
        m = flat[n]
        for i in range(3):
            for j in range(3):
                g = m[i, 0] * m[j, 0] + m[i, 1] * m[j, 1] + m[i, 2] * m[j, 2] - (1.0 if i == j else 0.0)
                if not abs(g) <= 1e-12:
                    return False
        det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
               + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
        if not det > 0.0:
            return False
        rotation_log(m, out[n], q4)
    return True


def warm_up() -> bool:
    """Compile both kernels, or load them from the on-disk cache, on an empty one-body model (a process that is
    about to start others, e.g. a test session before its Snakemake runs, calls this so that they all load the
    cache instead of compiling at the same time), holding :func:`first_use_lock`. Returns whether the compiled core
    is active."""
    with first_use_lock():
        return _warm_up()


def _warm_up() -> bool:
    if not active():
        return False
    f2, f3, i1 = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    md = (np.zeros((1, 3)), i1, i1.copy(), f2, f2.copy(), np.zeros(0), i1.copy(), np.zeros((0, 5)), np.zeros(0),
          0.5, i1.copy(), i1.copy(), f2.copy(), i1.copy(), np.zeros(0), 5e-5, f2.copy(), f3, np.zeros((0, 5)),
          i1.copy(), i1.copy(), f2.copy(), f3.copy(), f2.copy(), np.zeros((0, 4, 3)))
    x, R = np.zeros((1, 1, 3)), np.eye(3)[None, None].copy()
    rows = (np.zeros((1, 1, 6)), np.ones((1, 0)), np.ones((1, 0)), np.ones((1, 0)), np.zeros((1, 0)), np.zeros((1, 3)))
    evaluate_batch(x, R, *rows, True, md, np.empty((1, 1, 6)), np.empty((1, 1, 6, 1, 6)))
    newton_batch(x, R, *rows, md, 5, 1e-8, 1e-8, 1e-3, 0.05, np.ones(6), np.ones(6), 0.05, np.empty_like(x),
                 np.empty_like(R), np.zeros(1, bool), np.empty(1), np.empty(1), np.zeros(1, np.int64))
    log_batch(np.eye(3)[None].copy(), np.empty((1, 3)))
    return True


def lock_path() -> Path:
    """The lock file of :func:`first_use_lock`: one per numba cache of this package (``NUMBA_CACHE_DIR`` or the
    package's folder), in the system's temporary folder."""
    where = os.environ.get("NUMBA_CACHE_DIR") or str(Path(__file__).resolve().parent)
    return Path(tempfile.gettempdir()) / f"lumbar-kernel-{hashlib.sha256(where.encode()).hexdigest()[:16]}.lock"


@contextlib.contextmanager
def first_use_lock():
    """An exclusive lock (flock) shared by the processes of this machine that use the same numba cache."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    with open(lock_path(), "a+") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _first_use():
    """The first use of the compiled core in this process compiles both kernels, or loads them from the on-disk cache
    (:func:`warm_up`), holding :func:`first_use_lock`: jobs that start together on a fresh clone (an empty cache) do
    not compile the same machine code side by side, each on a core; the first compiles, the others wait and load it
    from the cache (a fraction of a second once it is there)."""
    if _state["ready"]:
        return
    with profile.phase("numba_load"), first_use_lock():
        _warm_up()
    _state["ready"] = True
