"""Force laws: values from the papers, slack points, monotonicity, continuity, derivatives."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lumbar.mechanics.elements import (contact_penalty, disc_axial_force, disc_torque, fit_surface, rupp_force,
                             softplus_force, torque_angle)
from lumbar.mechanics.elements.ligament import rupp_shape

from conftest import TABLE1


def fd(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_torque_angle_inverts_to_published_disc_only_rom():
    """Inverting Eq. 3 with Table 1 gives the disc-only ROM stated in shared/NOTES.md."""
    from scipy.optimize import brentq
    expect = {"flexion": [4.93, 6.60, 8.43, 10.11, 13.41], "extension": [2.25, 4.93, 7.95, 10.29, 12.82],
              "lateral_bending": [2.17, 3.68, 5.19, 6.51, 9.09], "axial_rotation": [1.29, 2.78, 4.45, 5.82, 7.73]}
    for d, roms in expect.items():
        for M, rom in zip([1, 2.5, 5, 7.5, 10], roms):
            lo, hi = (np.radians(1.8), np.radians(15.6)) if d == "flexion" else (1e-9, np.radians(40))
            phi = brentq(lambda p: torque_angle(p, *TABLE1[d])[0] - M, lo, hi)
            assert np.degrees(phi) == pytest.approx(rom, abs=0.01)


def test_flexion_law_peaks_near_15_6_deg():
    phi = np.radians(np.linspace(5, 30, 20001))
    T, _ = torque_angle(phi, *TABLE1["flexion"])
    assert T.max() == pytest.approx(10.19, abs=0.01)
    assert np.degrees(phi[T.argmax()]) == pytest.approx(15.6, abs=0.2)


def test_disc_torque_derivative_and_direction_split():
    phi = np.array([[0.01, 0.05, -0.02], [-0.03, -0.07, 0.04]])
    T, D = disc_torque(phi, TABLE1)
    for k in range(3):
        def f(v, k=k):
            p = phi.copy()
            p[:, k] = v
            return disc_torque(p, TABLE1)[0][:, k]
        np.testing.assert_allclose(D[:, k], fd(f, phi[:, k]), rtol=1e-6)
    assert T[0, 1] == pytest.approx(torque_angle(0.05, *TABLE1["flexion"])[0])
    assert T[1, 1] == pytest.approx(torque_angle(-0.07, *TABLE1["extension"])[0])
    # lateral bending and axial rotation are odd (left = right)
    assert disc_torque(-phi, TABLE1)[0][0, 0] == pytest.approx(-T[0, 0])


def test_disc_axial_force_compression_only_by_default():
    F, dF = disc_axial_force(np.array([-1e-3, 0.0, 1e-3]), 690234060.0, 659748.0)
    assert F[0] == pytest.approx(690234060.0 * 1e-6 + 659748.0 * 1e-3)
    assert F[1] == 0 and F[2] == 0
    Ft, _ = disc_axial_force(1e-3, 690234060.0, 659748.0, k_tension=1e5)
    assert Ft == pytest.approx(-100.0)  # traction pulls the upper vertebra back down


def eq7_by_hand(eps, a, b, c, d):
    """Paper 1, Eq. 7 as printed above Table 3: F = a ln(exp((eps + b) / d) + 1) + c, tension only (F >= 0)."""
    import math
    return max(a * math.log(math.exp((eps + b) / d) + 1.0) + c, 0.0)


@pytest.mark.parametrize("law,eps", [
    ((173.5, -10.06, -26.82, 5.625), 3.0), ((173.5, -10.06, -26.82, 5.625), 8.0),     # ALL (Table 3)
    ((48.12, -43.97, -2.5, 15.0), 10.0), ((98.94, 18.97, -82.2, 73.33), 10.0),        # PLL, CL
    ((0.4517, -3.502, 0.0, 0.02414), 4.0), ((47.11, 4.21, 54.85, -11.25), 10.0),      # ISL, FL
    ((47.11, 4.21, 54.85, -11.25), 15.0), ((1.218, -22.97, 0.0, 1.369), 30.0),        # FL, SSL
])
def test_softplus_law_is_eq7_of_table3(law, eps):
    """The implemented law equals Eq. 7 computed by hand from Table 3's parameters (e.g. ALL at 8 %:
    173.5 ln(e^((8 - 10.06) / 5.625) + 1) - 26.82 = 64.6 N; FL at 10 %: 66.6 N, at 15 %: 62.7 N)."""
    F, _ = softplus_force(eps, *law, slack_width_pct=0.0)
    assert F == pytest.approx(eq7_by_hand(eps, *law), rel=1e-12, abs=1e-12)
    assert eq7_by_hand(8.0, 173.5, -10.06, -26.82, 5.625) == pytest.approx(64.6, abs=0.05)


def test_softplus_slack_and_tension_only():
    eps = np.linspace(-20, 0, 50)
    for law in [(173.5, -10.06, -26.82, 5.625), (47.11, 4.21, 54.85, -11.25), (-50.49, -36.0, -0.02453, 4.718)]:
        F, _ = softplus_force(eps, *law)
        assert np.all(F == 0.0)                      # slack fibre carries nothing
        F2, _ = softplus_force(np.linspace(0, 60, 200), *law)
        assert np.all(F2 >= 0.0)                     # never pushes


def test_softplus_continuous_across_slack_point_for_flaval_ligament():
    """The published FL fit is 79.5 N at 0 % strain; the slack ramp keeps the force continuous."""
    eps = np.linspace(-0.01, 1.0, 20001)
    F, dF = softplus_force(eps, 47.11, 4.21, 54.85, -11.25, slack_width_pct=0.5)
    assert np.abs(np.diff(F)).max() < 0.02
    np.testing.assert_allclose(dF[1:-1], np.gradient(F, eps)[1:-1], rtol=2e-2, atol=0.5)


def test_softplus_monotone_for_positive_d_laws():
    eps = np.linspace(0.6, 40, 500)
    for law in [(173.5, -10.06, -26.82, 5.625), (48.12, -43.97, -2.5, 15.0), (98.94, 18.97, -82.2, 73.33),
                (0.4517, -3.502, 0.0, 0.02414), (1.218, -22.97, 0.0, 1.369)]:
        F, dF = softplus_force(eps, *law)
        assert np.all(np.diff(F) >= -1e-12) and np.all(dF >= 0)


def test_rupp_law_is_c1_and_reproduces_paper_shape():
    sh = rupp_shape(1.52e-3, 4.98e-3, 55.0, 456.0, 3)
    l_a, dF0, nu, K_nl, K_l = sh
    assert nu == pytest.approx(3.20294, rel=1e-4) and K_l == pytest.approx(38632, rel=1e-4)
    assert K_nl == pytest.approx(1.94821e10, rel=1e-4)
    dl = np.array([l_a - 1e-9, l_a + 1e-9])
    F, dF = rupp_force(dl, *sh)
    assert F[0] == pytest.approx(F[1], abs=1e-3) and dF[0] == pytest.approx(dF[1], rel=1e-4)
    assert rupp_force(-1e-4, *sh)[0] == 0.0
    x = np.linspace(1e-5, 6e-3, 50)
    np.testing.assert_allclose(rupp_force(x, *sh)[1], fd(lambda v: rupp_force(v, *sh)[0], x, 1e-9), rtol=1e-4)


def test_contact_penalty_zero_when_open_and_linear_when_closed():
    F, dF = contact_penalty(np.array([-1e-3, 0.0, 1e-3]), 12000.0, 5e-5)
    assert F[0] == 0 and F[1] == 0
    assert F[2] == pytest.approx(12000.0 * (1e-3 - 2.5e-5))
    assert dF[2] == 12000.0


def _facet_sets(coef, rot_seed=1, gap=0.001):
    rng = np.random.default_rng(rot_seed)
    U, V = [a.ravel() for a in np.meshgrid(np.linspace(-0.005, 0.005, 3), np.linspace(-0.003, 0.003, 3))]
    W = coef[0] * U**3 + coef[1] * V**3 + coef[2] * U**2 + coef[3] * V**2
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    base = np.column_stack([U, V, W])
    off = np.array([0.01, 0.02, 0.03])
    return (base - [0, 0, gap / 2]) @ R.T + off, (base + [0, 0, gap / 2]) @ R.T + off


def test_facet_surface_recovers_generating_quadric_exactly():
    sup, inf = _facet_sets([0.0, 0.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    assert s.rms_m < 1e-9
    np.testing.assert_allclose(s.gap(inf)[0], 0.0005, atol=1e-9)    # inferior set on the upper side
    np.testing.assert_allclose(s.gap(sup)[0], -0.0005, atol=1e-9)
    np.testing.assert_allclose(np.sort(np.abs(s.coef[2:4])), [5.0, 8.0], rtol=1e-6)


def test_facet_surface_fits_cubic_within_landmark_precision():
    sup, inf = _facet_sets([200.0, -300.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    assert s.rms_m < 5e-5                          # 0.05 mm: well below the 1 mm joint gap
    assert np.all(s.gap(inf)[0] > 0) and np.all(s.gap(sup)[0] < 0)


def test_facet_gap_gradient_matches_finite_differences():
    sup, inf = _facet_sets([200.0, -300.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    P = inf[:3]
    _, grad, hess = s.gap(P)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-7
        np.testing.assert_allclose(grad[:, k], (s.gap(P + e)[0] - s.gap(P - e)[0]) / 2e-7, rtol=1e-5, atol=1e-8)
        np.testing.assert_allclose(hess[:, :, k], (s.gap(P + e)[1] - s.gap(P - e)[1]) / 2e-7, rtol=1e-4, atol=1e-4)


def test_facet_beyond_extent_is_outside_the_landmarks_uv_extent_only():
    sup, inf = _facet_sets([200.0, -300.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    assert not s.beyond_extent(np.vstack([sup, inf])).any()           # every landmark inside its own extent
    (u0, u1), (v0, v1) = s.u_range, s.v_range
    q = np.array([[0.5 * (u0 + u1), 0.5 * (v0 + v1), 0.0], [u0 - 1e-4, 0.0, 0.0], [0.0, v1 + 1e-4, 0.0],
                  [u1 + 1e-3, 0.0, 0.0]])
    P = s.origin + q @ s.axes                                           # local (u, v, w) back to the reference frame
    np.testing.assert_array_equal(s.beyond_extent(P), [False, True, True, True])
    np.testing.assert_array_equal(s.beyond_extent(P, margin=5e-4), [False, False, False, True])


def test_contact_force_beyond_extent_splits_the_total_by_where_the_points_touch():
    from lumbar.mechanics.model import SpineModel
    sup, inf = _facet_sets([0.0, 0.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    (u0, u1), (v0, v1) = s.u_range, s.v_range
    pen = -2e-4                                                        # 0.2 mm into the surface
    forces = []
    for u, v in ((0.5 * (u0 + u1), 0.5 * (v0 + v1)), (u1 + 1e-3, 0.0)):
        point = s.origin + np.array([u, v, s.surface(u, v)[0] + pen]) @ s.axes
        m = SpineModel()
        low = m.add_body("low", np.zeros(3), fixed=True)
        up = m.add_body("up", np.array([0.0, 0.0, 0.03]))
        m.add_facet(up, low, s, point[None], 12000.0)
        m.finalize()
        x, R = m.reference_state(1)
        forces.append((m.contact_forces(x, R)[0, 0], m.contact_forces(x, R, beyond_extent=True)[0, 0]))
    (t_in, b_in), (t_out, b_out) = forces
    assert t_in > 0 and b_in == 0.0                                    # pressed inside: nothing beyond
    assert t_out > 0 and b_out == t_out                                # pressed beyond the extent: all of it


@settings(max_examples=60, deadline=None)
@given(a=st.floats(0.1, 500), b=st.floats(-40, 20), c=st.floats(-100, 100), d=st.floats(0.05, 80),
       eps=st.floats(-30, 60))
def test_property_softplus_tension_only_and_continuous(a, b, c, d, eps):
    F, dF = softplus_force(eps, a, b, c, d)
    assert F >= 0.0 and np.isfinite(F) and np.isfinite(dF)
    F2, _ = softplus_force(eps + 1e-7, a, b, c, d)
    assert abs(F2 - F) <= abs(dF) * 1e-7 + 1e-3 * max(1.0, a / d) * 1e-3


@pytest.mark.parametrize("n_points", [1, 4])
def test_joint_stiffness_is_shared_by_its_points_and_set_by_one_setter(n_points):
    """A facet joint pressed evenly 0.2 mm deep carries the same total force with 1 or 4 contact points (each point
    gets 1/n of the joint's stiffness; a builder that gave every point the whole stiffness would carry 4x with 4);
    ``set_facet_stiffness`` scales it as a rebuild with the new stiffness would, and ``facet_stiffness`` reads back
    the joint's value."""
    from lumbar.mechanics.model import SpineModel
    sup, inf = _facet_sets([0.0, 0.0, 8.0, 5.0])
    s = fit_surface(sup, inf)
    (u0, u1), (v0, v1) = s.u_range, s.v_range
    uc, vc = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    du, dv = 0.1 * (u1 - u0), 0.1 * (v1 - v0)
    uv = [(uc, vc)] if n_points == 1 else [(uc - du, vc - dv), (uc + du, vc - dv), (uc - du, vc + dv), (uc + du, vc + dv)]
    pts = np.array([s.origin + np.array([u, v, s.surface(u, v)[0] - 2e-4]) @ s.axes for u, v in uv])

    def total(k_build, k_set=None):
        m = SpineModel()
        low = m.add_body("low", np.zeros(3), fixed=True)
        up = m.add_body("up", np.array([0.0, 0.0, 0.03]))
        m.add_facet(up, low, s, pts, k_build)
        m.finalize()
        if k_set is not None:
            m.set_facet_stiffness(k_set)
        x, R = m.reference_state(1)
        return float(m.contact_forces(x, R)[0].sum()), m.facet_stiffness()

    f1, k1 = total(12000.0)
    # the joint's penalty law at 0.2 mm (the model's default smoothing), whatever n (the surface is curved a little)
    f_joint = float(contact_penalty(np.array([2e-4]), 12000.0, 5e-5)[0][0])
    assert f1 == pytest.approx(f_joint, rel=0.02)
    f2, k2 = total(12000.0, 24000.0)
    f3, _ = total(24000.0)
    assert f2 == pytest.approx(f3, rel=1e-12) and f2 == pytest.approx(2 * f1, rel=0.05)
    np.testing.assert_allclose(k1, [12000.0]) and np.testing.assert_allclose(k2, [24000.0])
    with pytest.raises(ValueError, match="facet_stiffness_n_per_m"):
        total(12000.0, -1.0)
