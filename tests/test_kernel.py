"""The compiled solver core (lumbar.mechanics.kernel) against the numpy reference path: the same residuals and
Jacobians, the same equilibria (1e-9 relative) on the L4-L5 unit (Visible Human, all stages, all directions), the
L2-S1 model with cables and the muscle model's L1-S1 use; exact Jacobians of the compiled path against finite
differences; model arrays changed in place between calls; per-fibre parameters; the switch; the on-disk cache."""
import copy
import os
import re
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest

from lumbar.experiments import l2s1
from lumbar.experiments.fsu import DIRECTIONS, build_fsu, range_of_motion
from lumbar.geometry import load_geometry
from lumbar.geometry.synthetic import symmetric_fsu
from lumbar.inputs.tables import STAGES
from lumbar.mechanics import kernel, so3
from lumbar.mechanics.solve import solve

from conftest import make_charset
from test_model import _two_level_model, fd_jacobian, perturbed_state

needs_numba = pytest.mark.skipif(not kernel.HAVE_NUMBA, reason="numba not installed (pinned in environment.txt)")
ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-9


def both(m, *args, **kw):
    with kernel.use("compiled"):
        Qc, Jc = m.evaluate(*args, **kw)
    Qr, Jr = m.evaluate_reference(*args, **kw)
    return Qc, Jc, Qr, Jr


def assert_same(a, b, rtol=RTOL):
    """Equal to ``rtol`` of the array's largest magnitude (round-off of differently ordered sums)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    scale = max(np.abs(b).max(initial=0.0), 1e-300)
    assert np.abs(a - b).max(initial=0.0) <= rtol * scale, np.abs(a - b).max() / scale


def _rich_params(m, B, rng):
    """Every ``params`` extension, masks with arbitrary weights, and per-fibre law parameters and slack lengths
    that differ inside a group (as a per-fibre calibration would write them)."""
    m.f_par[:, 1] += rng.uniform(-0.5, 0.5, m.nf) * (m.f_law == kernel.LAW_SOFTPLUS)
    m.f_l0[:] *= rng.uniform(0.995, 1.005, m.nf)
    params = {"k_tension": rng.uniform(0, 2e6, B), "disc_phi_offset": rng.normal(0, 0.01, (B, 3)),
              "fibre_l0_scale": rng.uniform(0.98, 1.02, (B, m.nf))}
    return params, rng.uniform(0, 1.5, (B, m.nf)), rng.uniform(0, 2, (B, m.nc))


@needs_numba
@pytest.mark.parametrize("case", ["fsu", "two_bodies_softplus", "two_bodies_rupp"])
def test_compiled_residual_and_jacobian_equal_the_reference(charset, case):
    m = (build_fsu(symmetric_fsu(), charset).model if case == "fsu"
         else _two_level_model(charset, case.rsplit("_", 1)[1]))
    x, R, loads = perturbed_state(m, 5, 3)
    params, fm, cm = _rich_params(m, 5, np.random.default_rng(1))
    Qc, Jc, Qr, Jr = both(m, x, R, loads, fm, cm, params=params)
    assert m.contact_forces(x, R).max() > 0 and np.abs(Jr).max() > 0
    assert_same(Qc, Qr)
    assert_same(Jc, Jr)
    Qn, Jn = m.evaluate(x, R, loads, fm, cm, jacobian=False, params=params)
    assert Jn is None
    assert_same(Qn, Qr)


def _spring_chain(charset, point=False):
    """The two-body chain of test_model with paper 2's 6-DOF springs (the cubic_deg torque law, a lateral shear
    stiffness of its own, tension) in place of its two discs, beside its fibres and facets; ``point``: the springs at
    the upper bodies' centroids in frames along the project axes (the paper's code's points)."""
    from lumbar.muscles.springs import add_spring_level, paper2_spring_law  # noqa: PLC0415
    m = _two_level_model(charset)
    m.discs.clear()
    law = paper2_spring_law()
    assert law.k_lateral != law.k_anterior_posterior        # the lateral shear is exercised apart
    geo = symmetric_fsu()
    lev = geo.levels["L4-L5"]
    up = copy.deepcopy(lev)
    up.name, up.upper, up.lower, up.disc_centre = "L3-L4", "L3", "L4", lev.disc_centre + [0.0, 0.0, 0.038]
    for level in (up, lev):
        add_spring_level(m, level, law, m.c[m.body_index(level.upper)] if point else None)
    m.nd = len(m.discs)
    return m


@needs_numba
@pytest.mark.parametrize("point", [False, True])
def test_compiled_springs_of_paper2_equal_the_reference(charset, point):
    """Paper 2's 6-DOF springs (cubic_deg torque law, anisotropic shear) on the compiled core: residual and Jacobian
    equal the numpy reference's, with every ``params`` extension; the Jacobian matches finite differences; and a
    spring read as an Eq. 3 disc (the law code ignored) or with isotropic shear gives another residual (control)."""
    m = _spring_chain(charset, point)
    assert m.kernel_supported() and all(d.law == "cubic_deg" for d in m.discs)
    x, R, loads = perturbed_state(m, 5, 3)
    params, fm, cm = _rich_params(m, 5, np.random.default_rng(1))
    Qc, Jc, Qr, Jr = both(m, x, R, loads, fm, cm, params=params)
    assert_same(Qc, Qr)
    assert_same(Jc, Jr)
    with kernel.use("compiled"):
        Jfd = fd_jacobian(m, x, R, loads, fmask=fm, cmask=cm, params=params)
    assert np.abs(Jc - Jfd).max() < 1e-6 * np.abs(Jc).max()
    for change in ("law", "shear"):
        d0 = m.discs[1]
        if change == "law":
            d0.law = "eq3"
        else:
            d0.k_shear_lateral = None
        with kernel.use("compiled"):
            Qx, _ = m.evaluate(x, R, loads, fm, cm, params=params)
        Qxr, _ = m.evaluate_reference(x, R, loads, fm, cm, params=params)
        assert_same(Qx, Qxr)                        # the changed spring is seen by the compiled core too
        assert np.abs(Qx - Qc).max() > 1e-3 * np.abs(Qc).max()
        m.discs[1] = _spring_chain(charset, point).discs[1]


def _place_contact_point(m, x, R, n, gap):
    """State (x, R) with body k_a[n] translated so that contact point n has the given gap to its surface (the
    translation runs along the surface's w axis: the point's u and v stay, its w moves by the same length)."""
    a, b, surf = int(m.k_a[n]), int(m.k_b[n]), m.surfaces[int(m.k_surf[n])]
    p, _ = m._attach(x, R, m.k_a[n:n + 1], m.k_s[n:n + 1])
    g0 = surf.gap(m._to_body(x, R, m.k_b[n:n + 1], p))[0][0, 0]
    Rb = R[0, b] if b >= 0 else np.eye(3)
    x = x.copy()
    x[0, a] += Rb @ surf.axes[2] * (gap - g0)
    p, _ = m._attach(x, R, m.k_a[n:n + 1], m.k_s[n:n + 1])
    assert abs(surf.gap(m._to_body(x, R, m.k_b[n:n + 1], p))[0][0, 0] - gap) < 1e-13
    return x


@needs_numba
@pytest.mark.parametrize("case", ["fsu", "two_bodies"])
@pytest.mark.parametrize("gap", [-5e-10, 5e-10, -2e-6])
def test_contact_screen_keeps_a_point_that_barely_touches(charset, case, gap):
    """The compiled contact loop skips a point whose screened gap (one affine map per surface) exceeds
    kernel.SCREEN_M: a point that penetrates by less than that margin, or by a little more, still gives the reference
    path's force and stiffness, and one that is open by less than the margin gives none (on a surface of the fixed
    body, and on a moving lower body)."""
    m = build_fsu(symmetric_fsu(), charset).model if case == "fsu" else _two_level_model(charset)
    x, R, loads = perturbed_state(m, 1, 7)
    n = int(np.flatnonzero(m.k_b >= 0)[0]) if case == "two_bodies" else m.nc // 2
    x = _place_contact_point(m, x, R, n, gap)
    m.k_stiff[n] = 1e14      # N/m: a penetration of 0.5 nm gives a force (0.25 N) far above the other sums' round-off
    one, none = np.zeros((1, m.nc)), np.zeros((1, m.nc))
    one[0, n] = 1.0
    fm = np.zeros((1, m.nf))
    d = {}
    for mode in ("compiled", "reference"):
        with kernel.use(mode):
            Q1, J1 = m.evaluate(x, R, loads, fm, one)
            Q0, J0 = m.evaluate(x, R, loads, fm, none)
        # the point's share, beside the round-off of the other elements' sums in another order
        d[mode] = (Q1 - Q0, J1 - J0, 64 * np.finfo(float).eps * np.abs(Q0).max(), 64 * np.finfo(float).eps * np.abs(J0).max())
    (dQc, dJc, eq, ej), (dQr, dJr, _, _) = d["compiled"], d["reference"]
    if gap > 0:
        assert np.abs(dQr).max() <= eq and np.abs(dQc).max() <= eq
        return
    assert np.abs(dQr).max() > 100 * eq and np.abs(dJr).max() > 100 * ej     # a skipped point would fail below
    assert np.abs(dQc - dQr).max() <= 1e-6 * np.abs(dQr).max() + eq
    assert np.abs(dJc - dJr).max() <= 1e-6 * np.abs(dJr).max() + ej


@needs_numba
@pytest.mark.parametrize("case", ["fsu", "two_bodies_rupp"])
def test_compiled_jacobian_matches_finite_differences(charset, case):
    """The compiled path's analytic Jacobian (with every params extension and weighted masks) against central
    differences of the compiled residual."""
    m = (build_fsu(symmetric_fsu(), charset).model if case == "fsu" else _two_level_model(charset, "rupp"))
    x, R, loads = perturbed_state(m, 3, 5)
    params, fm, cm = _rich_params(m, 3, np.random.default_rng(2))
    kw = dict(fmask=fm, cmask=cm, params=params)
    with kernel.use("compiled"):
        assert kernel.active()
        _, J = m.evaluate(x, R, loads, **kw)
        Jfd = fd_jacobian(m, x, R, loads, **kw)
    assert np.abs(J - Jfd).max() < 1e-8 * np.abs(J).max() + 1e-4


@needs_numba
def test_model_arrays_changed_in_place_are_read_at_every_call(charset):
    """The calibration writes f_par rows, f_scale, f_l0, k_stiff and a disc's k_shear between calls: the compiled
    path follows each change (equals the reference after it and differs from the result before it), also an array
    replaced by a new one and a disc's centre moved in place (the kernel keeps the model's data between calls)."""
    m = build_fsu(symmetric_fsu(), charset).model
    x, R, loads = perturbed_state(m, 2, 7)
    T = m.fibre_state(x, R)[2]
    sel = m.f_group == m.f_group[np.argmax(T.min(0))]          # a group taut in both states
    assert T[:, sel].min() > 0
    changes = [lambda: m.f_par.__setitem__((sel, 1), m.f_par[sel, 1] + 2.0),
               lambda: m.f_scale.__setitem__(sel, m.f_scale[sel] * 3.0),
               lambda: m.f_l0.__setitem__(slice(None), m.f_l0 * 0.99),
               lambda: m.k_stiff.__setitem__(slice(None), m.k_stiff * 5.0),
               lambda: setattr(m.discs[0], "k_shear", m.discs[0].k_shear * 4.0),
               lambda: m.discs[0].torque.__setitem__("flexion", (1.0, 0.01, 50.0)),
               lambda: setattr(m, "f_scale", m.f_scale * 2.0),
               lambda: m.discs[0].centre.__setitem__(2, m.discs[0].centre[2] + 2e-3)]
    for change in changes:
        before = m.evaluate(x, R, loads)[1]
        change()
        Qc, Jc, Qr, Jr = both(m, x, R, loads)
        assert_same(Qc, Qr)
        assert_same(Jc, Jr)
        assert np.abs(Jc - before).max() > 1e-6 * np.abs(before).max()


def _rom_tables(fsu, **kw):
    out = {}
    for mode in kernel.MODES:
        with kernel.use(mode):
            out[mode] = range_of_motion(fsu, **kw)
    return out["compiled"], out["reference"]


@needs_numba
def test_same_equilibria_on_the_visible_human_unit_all_stages_all_directions(charset):
    geo = load_geometry("visible_human", levels=["L4-L5"])
    fsu = build_fsu(geo, charset)
    c, r = _rom_tables(fsu, moments_nm=(1, 5, 10), directions=tuple(DIRECTIONS), stages=STAGES)
    assert len(c) == len(STAGES) * len(DIRECTIONS) * 3 and c["converged"].all()
    assert (c["iterations"] == r["iterations"]).all()
    assert (c["converged"] == r["converged"]).all() and (c["valid"] == r["valid"]).all()
    for col in ("rom_deg", "rot_x_deg", "rot_y_deg", "rot_z_deg", "trans_x_mm", "trans_y_mm", "trans_z_mm",
                "disc_compression_mm"):
        assert_same(c[col], r[col])


@needs_numba
def test_same_equilibria_on_the_l2s1_model_with_cables():
    geo = load_geometry("default", levels=list(l2s1.LEVELS))
    spine = l2s1.build_l2s1(geo, make_charset("calibrated"), l2s1.derive_cables())
    sols = {}
    for mode in kernel.MODES:
        with kernel.use(mode):
            sols[mode] = l2s1.solve_scenarios(spine, tol_force=1e-7, tol_moment=1e-7)
    c, r = sols["compiled"], sols["reference"]
    assert spine.model.nb == 4 and c.converged.all() and (c.converged == r.converged).all()
    assert_same(c.x, r.x)
    assert_same(so3.log(c.R), so3.log(r.R))


@needs_numba
def test_compiled_rotation_log_equals_scipys_bit_for_bit():
    """so3.log on the compiled core (kernel.log_batch) gives scipy's rotation vectors exactly: random rotations,
    angles near 0, at the series' switch (1e-3 rad) and near and at pi; a matrix 1e-9 off orthogonal and a
    left-handed one go to scipy's reference (orthogonalised, or refused); in reference mode the reference runs."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(4)
    w = rng.normal(size=(300, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    mats = [Rotation.random(500, random_state=5).as_matrix()]
    mats += [so3.exp(w * a) for a in (1e-9, 1e-4, 1e-3, 1.0001e-3, 2.0, np.pi - 1e-7, np.pi)]
    assert kernel.active()
    for m in mats:
        assert np.array_equal(so3.log(m), so3.log_reference(m))
    assert so3.log(mats[0][:6].reshape(2, 3, 3, 3)).shape == (2, 3, 3)
    assert so3.log(np.zeros((0, 3, 3))).shape == (0, 3)
    flat = np.ascontiguousarray(mats[0][:4])
    assert kernel.log_batch(flat, np.empty((4, 3)))
    skew = flat * (1.0 + 1e-9)                 # not orthogonal to 1e-12: the compiled path declines
    assert not kernel.log_batch(skew, np.empty((4, 3)))
    assert np.array_equal(so3.log(skew), so3.log_reference(skew))
    with pytest.raises(ValueError, match="determinant"):
        so3.log(np.diag([1.0, 1.0, -1.0]))
    with kernel.use("reference"):
        assert np.array_equal(so3.log(mats[0]), so3.log_reference(mats[0]))


def test_lowest_eigenvalue_of_the_newton_shift_equals_numpys():
    """The compiled Newton step's shift uses the lowest eigenvalue of the scaled symmetric tangent (numpy's eigvalsh
    on the reference path; Jacobi rotations in the compiled core, which runs without allocating): the same to
    round-off on indefinite, definite and degenerate matrices of one and four bodies. Control: the lowest diagonal
    entry, what a test of the diagonal alone would give, is not the answer."""
    rng = np.random.default_rng(7)
    for n in (6, 24):
        for kind in ("indefinite", "definite", "repeated"):
            A = rng.normal(size=(n, n)) * np.logspace(0, 4, n)[None]
            A = A @ A.T if kind == "definite" else 0.5 * (A + A.T)
            if kind == "repeated":
                Qm = np.linalg.qr(rng.normal(size=(n, n)))[0]
                A = Qm @ np.diag(np.r_[[-3.0] * 3, np.linspace(1, 5, n - 3)]) @ Qm.T
            lam = np.linalg.eigvalsh(A)[0]
            got = kernel.lowest_eigenvalue(A)
            assert abs(got - lam) <= 1e-12 * np.abs(A).max(), (n, kind, got, lam)
            assert abs(np.diag(A).min() - lam) > 1e-6 * np.abs(A).max()      # control


@needs_numba
def test_the_newton_shift_where_the_tangent_is_indefinite_matches_the_reference():
    """From a saddle (the disc-only stage's reference state: the disc's flexion law has a negative stiffness about
    zero, docs/validity.md) the modified Newton step shifts the tangent by its lowest eigenvalue: the compiled core
    (Jacobi rotations) and the reference path (numpy) give the same equilibria and iterations. Control: the start
    state is indefinite, so the shift is used."""
    from lumbar.experiments.fsu import moment_loads
    from lumbar.inputs.characteristics import load_characteristic_set
    from lumbar.mechanics.solve import stable_rest_states
    fsu = build_fsu(load_geometry("visible_human", levels=["L4-L5"]), load_characteristic_set("calibrated"))
    m = fsu.model
    fm, cm = fsu.masks(["wo_all"])
    x, R = m.reference_state(1)
    assert not stable_rest_states(m, x, R, fm, cm)[0]                           # control: a saddle
    dirs = ["flexion", "extension", "lateral_bending", "axial_rotation"] * 2
    loads = moment_loads(dirs, [1.0] * 4 + [5.0] * 4, m.nb)
    out = {}
    for mode in kernel.MODES:
        with kernel.use(mode):
            out[mode] = solve(m, loads, x0=np.repeat(x, 8, 0), R0=np.repeat(R, 8, 0), fmask=fm, cmask=cm)
    c, r = out["compiled"], out["reference"]
    assert c.converged.all() and (c.iterations == r.iterations).all()
    assert_same(c.x, r.x)
    assert_same(so3.log(c.R), so3.log(r.R))


@needs_numba
def test_a_start_state_shared_by_a_batch_gives_what_each_scenario_gives_alone(charset):
    """Consecutive scenarios from the same start state with the same element data share the start's internal forces
    and Jacobian; a batch must give, bit for bit, what each scenario gives solved alone, also where the start
    states or the per-scenario masks and parameters change inside the batch (where nothing may be shared)."""
    m = _two_level_model(charset, "rupp")
    rng = np.random.default_rng(3)
    B = 12
    loads = np.zeros((B, m.nb, 6))
    loads[:, 0, 3:] = rng.uniform(-4.0, 4.0, (B, 3))
    x0, R0 = m.reference_state(B)
    x0[6:, 1, 2] += 2e-4                                   # scenarios 6-11 start elsewhere
    fmask = np.ones((B, m.nf))
    fmask[9:, -3:] = 0.0                                   # scenarios 9-11 from there without the cable
    params = {"k_tension": np.where(np.arange(B) == 4, 1e6, 0.0)}   # scenario 4 with a disc in tension
    with kernel.use("compiled"):
        batch = kernel.newton(m, x0, R0, loads, fmask, 1.0, params, 50, 1e-8, 1e-8, 1e-3, 0.05,
                              np.tile([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6], m.nb), np.ones(6 * m.nb), 0.05)
        for s in range(B):
            one = kernel.newton(m, x0[s:s + 1], R0[s:s + 1], loads[s:s + 1], fmask[s:s + 1], 1.0,
                                {"k_tension": params["k_tension"][s:s + 1]}, 50, 1e-8, 1e-8, 1e-3, 0.05,
                                np.tile([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6], m.nb), np.ones(6 * m.nb), 0.05)
            for a, b in zip(batch, one):
                assert np.array_equal(a[s], b[0]), s
    assert batch[2].all() and len({round(float(v), 12) for v in batch[0][:, 0, 0]}) == B


@needs_numba
def test_same_residual_and_jacobian_in_the_muscle_model(model):
    """The muscle model (L1-S1, several free bodies) sums SpineModel.evaluate of its levels and cables with its
    own terms: the same numbers on both paths."""
    rng = np.random.default_rng(4)
    x, R = model.reference_state(2)
    x = x + rng.normal(0, 2e-4, x.shape)
    R = so3.exp(rng.normal(0, 0.03, (2, model.nb, 3))) @ R
    F, P = model.load_arrays(["upright_standing", "crate_close"])
    params = {"activation": rng.uniform(0, 0.2, (2, model.ms.n)), "force_vec": F, "force_pt": P}
    out = {}
    for mode in kernel.MODES:
        with kernel.use(mode):
            out[mode] = model.evaluate(x, R, params=params, levels=True)
    for a, b in zip(out["compiled"], out["reference"]):
        assert_same(a, b)


@needs_numba
def test_reference_mode_runs_the_numpy_path(charset, monkeypatch):
    m = build_fsu(symmetric_fsu(), charset).model
    calls = []
    real = type(m).evaluate_reference
    monkeypatch.setattr(type(m), "evaluate_reference", lambda self, *a, **k: calls.append(1) or real(self, *a, **k))
    with kernel.use("reference"):
        r = solve(m, np.zeros((1, 1, 6)))
    assert r.converged.all() and calls
    calls.clear()
    with kernel.use("compiled"):
        solve(m, np.zeros((1, 1, 6)))
    assert not calls
    with pytest.raises(ValueError, match="reference"):
        kernel.set_mode("fast")


def test_without_numba_the_reference_path_runs_and_says_so(charset, monkeypatch, caplog):
    """Without numba, the default (compiled) mode solves on the numpy reference path: a loaded unit is solved by
    evaluate_reference and newton_reference only (the compiled core is never entered), to the same equilibrium as
    the reference mode gives, and one warning says so."""
    from lumbar.mechanics import solve as solve_module
    m = build_fsu(symmetric_fsu(), charset).model
    loads = np.zeros((2, m.nb, 6))
    loads[0, 0, 4], loads[1, 0, 5] = 5.0, 3.0                  # 5 N*m flexion, 3 N*m axial rotation
    with kernel.use("reference"):
        ref = solve(m, loads)
    assert ref.converged.all()

    def compiled_entered(*a, **k):
        raise AssertionError("the compiled core ran without numba")

    monkeypatch.setattr(kernel, "HAVE_NUMBA", False)
    monkeypatch.setitem(kernel._state, "warned", False)
    monkeypatch.setattr(kernel, "newton", compiled_entered)
    monkeypatch.setattr(kernel, "evaluate", compiled_entered)
    calls = {"evaluate": 0, "newton": 0}
    real_eval, real_newton = type(m).evaluate_reference, solve_module.newton_reference
    monkeypatch.setattr(type(m), "evaluate_reference",
                        lambda self, *a, **k: calls.__setitem__("evaluate", calls["evaluate"] + 1) or real_eval(self, *a, **k))
    monkeypatch.setattr(solve_module, "newton_reference",
                        lambda *a, **k: calls.__setitem__("newton", calls["newton"] + 1) or real_newton(*a, **k))
    with kernel.use("compiled"):
        assert not kernel.active()
        r = solve(m, loads)
        assert not kernel.active()
    assert caplog.text.count("numba is not installed") == 1
    assert calls["evaluate"] > 0 and calls["newton"] > 0, calls
    assert r.converged.all()
    np.testing.assert_array_equal(r.x, ref.x)                  # the same path: the same numbers
    np.testing.assert_array_equal(r.R, ref.R)
    assert np.abs(so3.log(r.R[:, 0])).max() > np.radians(0.5)  # a loaded equilibrium, not the start


@needs_numba
def test_a_fresh_process_loads_the_compiled_kernels_from_the_cache(charset):
    """After one use here (compiling or loading), a new interpreter finds both kernels in the on-disk cache and
    compiles nothing; ``kernel.warm_up`` (what the test session runs before its Snakemake jobs) loads the one
    signature that the model's calls use."""
    m = build_fsu(symmetric_fsu(), charset).model
    with kernel.use("compiled"):
        solve(m, np.zeros((1, 1, 6)))
        m.evaluate(*m.reference_state(1))
    code = ("import numpy as np; from lumbar.mechanics import kernel; from lumbar.mechanics.solve import solve; "
            "from lumbar.experiments.fsu import build_fsu; from lumbar.geometry.synthetic import symmetric_fsu; "
            "from lumbar.inputs.characteristics import load_characteristic_set as L; "
            "m = build_fsu(symmetric_fsu(), L('calibrated')).model; kernel.warm_up(); solve(m, np.zeros((1, 1, 6))); "
            "m.evaluate(*m.reference_state(1)); "
            "print([(sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()), len(f.signatures)) "
            "for f in (kernel.newton_batch, kernel.evaluate_batch)])")
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, "LUMBAR_KERNEL": "compiled"},
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip() == "[(1, 0, 1), (1, 0, 1)]", r.stdout     # warm_up has the callers' signature


_TRY_LOCK = ("import fcntl, sys\nf = open(sys.argv[1], 'a+')\ntry:\n    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)\n"
             "    print('free')\nexcept BlockingIOError:\n    print('busy')")


def _lock_state(path):
    r = subprocess.run([sys.executable, "-c", _TRY_LOCK, str(path)], capture_output=True, text=True, timeout=60)
    return r.stdout.strip()


@needs_numba
@pytest.mark.skipif(sys.platform == "win32", reason="flock")
def test_first_use_of_the_compiled_core_holds_a_lock_other_processes_wait_for(charset, tmp_path, monkeypatch):
    """Jobs that start together on a fresh clone would each compile the same kernels: the first use of the compiled
    core in a process runs warm_up (compile or load) holding a file lock that the machine's other processes of the
    same cache wait for; once, not at every call. Control: released after it, another process takes it."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))          # a lock of its own (numba read its cache at import)
    path = kernel.lock_path()
    assert str(tmp_path) not in str(path) and path.parent == Path(tempfile.gettempdir())
    seen = []
    monkeypatch.setattr(kernel, "_warm_up", lambda: seen.append(_lock_state(path)))
    monkeypatch.setitem(kernel._state, "ready", False)
    m = build_fsu(symmetric_fsu(), charset).model
    with kernel.use("compiled"):
        m.evaluate(*m.reference_state(1))
        solve(m, np.zeros((1, 1, 6)))
    assert seen == ["busy"]                   # warm_up ran once, under the lock
    assert _lock_state(path) == "free"        # control
    kernel.warm_up()                          # the public warm-up (a test session's first process) takes it too
    assert seen == ["busy", "busy"]


def test_newton_cache_pins_the_residual_module():
    """numba keys a function's cached machine code on its own source file only: newton_batch (kernel.py) holds the
    residual of kernel_residual.py, so kernel.RESIDUAL_SHA256 pins that file (a mismatch compiles newton_batch without
    the cache). Control: another digest is not the file's."""
    import hashlib
    from lumbar.mechanics import kernel_residual
    digest = hashlib.sha256(Path(kernel_residual.__file__).read_bytes()).hexdigest()
    assert kernel.residual_pinned(), (f"kernel_residual.py changed: set RESIDUAL_SHA256 = {digest!r} in "
                                      f"lumbar/mechanics/kernel.py (that edit retires newton_batch's cached code)")
    assert not kernel.residual_pinned("0" * 64)


def test_numba_is_pinned_in_environment_conda_env_and_pyproject():
    """environment.txt and workflow/envs/lumbar.yaml pin the same numba (and its llvmlite; the equality of the two
    files is test_workflow's), pyproject requires at least that major.minor, and the installed numba is the pin
    (the other tests of this file skip without numba; this one fails)."""
    pins = dict(ln.strip().split("==") for ln in (ROOT / "environment.txt").read_text().splitlines()
                if ln.strip() and not ln.startswith("#"))
    assert "numba" in pins and "llvmlite" in pins
    env = (ROOT / "workflow" / "envs" / "lumbar.yaml").read_text()
    assert f"numba=={pins['numba']}" in env and f"llvmlite=={pins['llvmlite']}" in env
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (low,) = [re.fullmatch(r"numba>=([0-9.]+)", d).group(1) for d in deps if d.startswith("numba")]
    assert low == ".".join(pins["numba"].split(".")[:2])
    assert kernel.HAVE_NUMBA, "numba is not installed: pip install -r environment.txt"
    import numba
    assert numba.__version__ == pins["numba"]
