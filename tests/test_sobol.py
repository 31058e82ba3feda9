"""Sobol indices from a Legendre polynomial chaos expansion (lumbar.muscles.pce) on functions with known
indices, and the Sobol table of the muscle study (lumbar.muscles.muscle_model.sobol_indices) on a synthetic sample."""
from math import comb

import numpy as np
import pandas as pd
import pytest

from lumbar.muscles import pce


def _design(n, dim, seed=3):
    return 2 * pce.qmc_points(n, dim, seed) - 1          # uniform on [-1, 1]^dim


def test_qmc_points_seeded_power_of_two():
    a, b = pce.qmc_points(64, 5, 7), pce.qmc_points(64, 5, 7)
    assert a.shape == (64, 5) and np.array_equal(a, b)
    assert not np.array_equal(a, pce.qmc_points(64, 5, 8))
    assert a.min() >= 0 and a.max() < 1
    # balance of a Sobol net: each half of each axis holds exactly half the points
    assert np.all((a < 0.5).sum(axis=0) == 32)
    with pytest.raises(ValueError, match="power of two"):
        pce.qmc_points(48, 5, 7)


def test_multi_indices_count_and_order():
    for dim, p in ((1, 4), (3, 2), (5, 3), (5, 4)):
        a = pce.multi_indices(dim, p)
        assert len(a) == comb(dim + p, p) == len({tuple(r) for r in a})
        assert a.sum(axis=1).max() == p and np.all(np.diff(a.sum(axis=1)) >= 0) and not a[0].any()


def test_legendre_basis_is_orthonormal():
    U = _design(2 ** 14, 2)
    A = pce.legendre_basis(U, pce.multi_indices(2, 4))
    assert np.allclose(A.T @ A / len(U), np.eye(A.shape[1]), atol=2e-3)


def test_additive_linear_function_exact():
    """y = sum c_i u_i (u_i uniform on [-1, 1]): S1_i = ST_i = c_i^2 / sum c_j^2, variance sum c_j^2 / 3."""
    c = np.array([3.0, -2.0, 1.0, 0.0, 0.5])
    U = _design(64, 5)
    y = 1.5 + U @ c
    f = pce.fit(U, y, 3)
    expect = c ** 2 / np.sum(c ** 2)
    assert np.allclose(f.S1, expect, atol=1e-10) and np.allclose(f.ST, expect, atol=1e-10)
    assert f.variance == pytest.approx(np.sum(c ** 2) / 3, rel=1e-10)
    assert f.mean == pytest.approx(1.5, abs=1e-10)
    assert f.q2_loo == pytest.approx(1.0, abs=1e-10)


def test_pure_interaction_has_no_first_order_part():
    """y = u1 * u2 on [-1, 1]^2 (plus an inert u3): S1 = 0 and ST = 1 for u1 and u2, all zero for u3."""
    U = _design(32, 3)
    f = pce.fit(U, U[:, 0] * U[:, 1], 2)
    assert np.allclose(f.S1, 0, atol=1e-10)
    assert np.allclose(f.ST, [1, 1, 0], atol=1e-10)
    r = pce.sobol_analysis(U, U[:, 0] * U[:, 1], 2, n_bootstrap=50, seed=1)
    assert np.allclose(r["S1_hi"], 0, atol=1e-8) and np.allclose(r["ST_lo"][:2], 1, atol=1e-8)


def test_polynomial_of_the_degree_is_fitted_exactly():
    """Any polynomial of total degree <= p is in the basis: reproduced to round-off, Q2_loo = 1; one of degree
    p + 1 is not (Q2 < 1)."""
    rng = np.random.default_rng(5)
    U = _design(128, 4)

    def poly(V):
        return 2 + V[:, 0] ** 3 - 0.5 * V[:, 1] * V[:, 2] + V[:, 3] ** 2 * V[:, 0] - V[:, 2]

    f = pce.fit(U, poly(U), 3)
    Ut = rng.uniform(-1, 1, (50, 4))
    assert np.allclose(f.predict(Ut), poly(Ut), atol=1e-9)
    assert f.q2_loo == pytest.approx(1.0, abs=1e-10)
    g = pce.fit(U, poly(U) + U[:, 1] ** 4, 3)
    assert g.q2_loo < 1 - 1e-4


def test_q2_loo_equals_explicit_leave_one_out():
    """The hat-matrix Q2 equals refitting without each point in turn; on pure noise it is below zero (an
    in-sample R2 would be positive)."""
    rng = np.random.default_rng(8)
    U = _design(32, 3)
    y = np.sin(2 * U[:, 0]) + U[:, 1] * U[:, 2] + rng.normal(0, 0.2, 32)
    alphas = pce.multi_indices(3, 2)
    A = pce.legendre_basis(U, alphas)
    pred = [A[i] @ np.linalg.lstsq(np.delete(A, i, 0), np.delete(y, i), rcond=None)[0] for i in range(32)]
    assert pce.fit(U, y, 2).q2_loo == pytest.approx(1 - np.mean((y - pred) ** 2) / np.var(y), rel=1e-9)
    assert pce.fit(U, rng.normal(size=32), 2).q2_loo < 0


def test_ishigami_indices():
    """Ishigami function (a = 7, b = 0.1, inputs uniform on [-pi, pi]^3): the known indices S1 = (0.314, 0.442,
    0), ST = (0.558, 0.442, 0.244) within 0.02 from a degree-8 PCE on 512 Sobol points."""
    X = np.pi * _design(512, 3, seed=11)
    y = np.sin(X[:, 0]) + 7 * np.sin(X[:, 1]) ** 2 + 0.1 * X[:, 2] ** 4 * np.sin(X[:, 0])
    f = pce.fit(pce.to_unit(X, [[-np.pi, np.pi]] * 3), y, 8)
    assert np.allclose(f.S1, [0.314, 0.442, 0.0], atol=0.02)
    assert np.allclose(f.ST, [0.558, 0.442, 0.244], atol=0.02)
    assert f.q2_loo > 0.98


def test_bootstrap_interval_covers_and_shrinks():
    """Noisy additive function: the 95 % bootstrap interval covers the exact index and narrows with n."""
    c = np.array([2.0, 1.0, 0.5])
    exact = c ** 2 / np.sum(c ** 2)
    widths = []
    for n in (32, 256):
        U = _design(n, 3, seed=2)
        y = U @ c + np.random.default_rng(n).normal(0, 0.3, n)
        r = pce.sobol_analysis(U, y, 2, n_bootstrap=300, seed=4)
        assert np.all(r["S1_lo"] <= r["S1"] + 1e-12) and np.all(r["S1"] <= r["S1_hi"] + 1e-12)
        assert r["S1_lo"][0] - 0.02 <= exact[0] <= r["S1_hi"][0] + 0.02
        widths.append(r["S1_hi"][0] - r["S1_lo"][0])
    assert widths[1] < widths[0] / 2


def test_to_unit_rejects_bad_bounds():
    with pytest.raises(ValueError, match="bounds"):
        pce.to_unit(np.zeros((2, 2)), [[0, 1], [1, 1]])
    assert np.allclose(pce.to_unit([[10.0, 1000.0]], [[10, 1000], [10, 1000]]), [[-1, 1]])


# ---------------------------------------------------------------------- the muscle study's Sobol functions
def test_sobol_samples_and_chunks():
    from lumbar.muscles.muscle_model import PARAMETERS
    from lumbar.muscles.muscle_sensitivity import SOBOL_BOUNDS, sobol_chunk_rows, sobol_samples
    X = sobol_samples(16, 1)
    assert X.shape == (16, len(PARAMETERS)) and np.array_equal(X, sobol_samples(16, 1))
    for k, name in enumerate(PARAMETERS):
        lo, hi = SOBOL_BOUNDS[name]
        assert lo <= X[:, k].min() and X[:, k].max() <= hi
    rows = np.concatenate([sobol_chunk_rows(len(X), 3, k) for k in range(3)])
    assert rows.tolist() == list(range(16))
    with pytest.raises(ValueError, match="power of two"):
        sobol_samples(12, 1)
    with pytest.raises(ValueError, match="chunk"):
        sobol_chunk_rows(16, 3, 3)


def _synthetic_samples(n, posture="standing", fail=()):
    """A sample table as sobol_evaluate writes it, with an additive IDP in (scaled) SSL and SpT."""
    from lumbar.muscles.muscle_model import PARAMETERS
    from lumbar.muscles.muscle_sensitivity import sobol_samples
    X = sobol_samples(n, 9)
    d = pd.DataFrame(X, columns=list(PARAMETERS))
    d.insert(0, "posture", posture)
    d.insert(1, "sample", np.arange(n))
    d.insert(2, "scope", "ALL")
    d["idp_mpa"] = 0.5 + 0.2 * (d["ssl_um"] - 2.8) / 0.8 + 0.1 * (d["spt_n_per_cm2"] - 77.5) / 72.5
    d["converged"] = True
    d["reached"] = ~d["sample"].isin(fail)
    d["certified"] = d["reached"] & (d["sample"] != 3)
    d["kkt_residual"] = np.where(d["sample"] == 3, 1e-3, 1e-8)
    return d


def test_sobol_indices_table():
    from lumbar.muscles.muscle_model import PARAMETERS
    from lumbar.muscles.muscle_sensitivity import sobol_indices
    s = pd.concat([_synthetic_samples(64), _synthetic_samples(64, "flexion", fail=(5, 6))], ignore_index=True)
    df = sobol_indices(s, 64, 2, seed=1, n_bootstrap=100)
    assert len(df) == 2 * len(PARAMETERS)
    st = df[df["posture"] == "standing"].set_index("parameter")
    assert st.loc["ssl_um", "S1"] == pytest.approx(0.8, abs=1e-8)
    assert st.loc["spt_n_per_cm2", "ST"] == pytest.approx(0.2, abs=1e-8)
    assert st.loc["pennation_deg", "ST"] == pytest.approx(0.0, abs=1e-8)
    assert (st["top_parameter"] == "ssl_um").all() and st["stable"].all() and st["fit_ok"].all()
    assert st["q2_loo"].iloc[0] == pytest.approx(1.0, abs=1e-8)
    # the uncertified sample (3) is counted and left out of the fit: certified optima only
    assert (st["n_uncertified"] == 1).all() and (st["n_fit"] == 63).all() and (st["kkt_residual_max"] == 1e-8).all()
    fl = df[df["posture"] == "flexion"]
    assert (fl["n_failed"] == 2).all() and (fl["n_fit"] == 61).all() and (fl["degree"] == 2).all()
    wild = s.copy()
    wild.loc[wild["sample"] == 3, "idp_mpa"] = 100.0          # control: an uncertified value cannot move the indices
    dw = sobol_indices(wild, 64, 2, seed=1, n_bootstrap=100)
    np.testing.assert_allclose(dw["S1"], df["S1"], atol=1e-12)
    assert (df["idp_mean_mpa"] - 0.5).abs().max() < 1e-8


def test_sobol_indices_lowers_the_degree_and_checks_rows():
    from lumbar.muscles.muscle_sensitivity import sobol_indices
    s = _synthetic_samples(16, fail=(0, 1))          # 14 reached < 21 terms of degree 2: degree 1 (6 terms)
    df = sobol_indices(s, 16, 2, seed=1, n_bootstrap=20)
    assert (df["degree"] == 1).all() and (df["n_terms"] == 6).all() and df["S1"].notna().all()
    with pytest.raises(ValueError, match="expected rows"):
        sobol_indices(s.iloc[1:], 16, 2, seed=1)
