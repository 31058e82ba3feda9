"""The phases of lumbar.discovery.fit.discover, each on its own, on the L2-S1 IDP problem of the fixture model
(conftest.idp_model_fixture: a closed-form forward model, milliseconds per batch). Datasets with a planted effect are
TEST FIXTURES (lumbar.discovery.make_hidden_effect_dataset), never data.

Every test has a control that fails for the wrong mechanism: the grid's zero row is the nominal model but its other
rows move; the refined estimate follows the planted effect and not the grid; the null tests give a small p-value to
a planted effect and not to a null; the nuisance refit finds a planted uniform scale and not in an unscaled table; the
decision names the effect only when every criterion passes and says which one fails otherwise."""
import numpy as np
import pytest

from lumbar import discovery as D
from lumbar.discovery import fit as F
from lumbar.experiments import effects as fx

SMALL = {"stages": ["intact", "wo_cl"], "moments_nm": [5.0], "n_specimens": 8, "noise_sd_deg": 0.3,
         "noise_sd_mpa": 0.02, "generator": "batch"}


def config(**disc):
    return {"seed": 7, "discovery": {"grid_points": 7, "null_specimens": 0, "benchmark": dict(SMALL), **disc}}


def settings(**disc):
    s = D.default_settings()
    s.update(D.discovery_settings(config(**disc)))
    return s


def problem(idp_model, effect="none", value=0.0, seed=5, scale=1.0, **disc):
    df = D.make_hidden_effect_dataset(config(**disc), "idp_invitro", effect, value, seed=seed, idp_model=idp_model)
    df["idp_mean_mpa"] *= scale
    df["idp_sd_mpa"] *= scale
    return D.build_problem("idp_invitro", df, config(**disc), idp_model=idp_model)


def phases_to_observation(prob, s):
    """The phases up to the observed statistics, as discover runs them."""
    cands = list(prob.candidates)
    grids = F.fit_grids(prob, cands, s)
    null = F.null_prediction(prob, grids.base)
    ref = F.refine(prob, cands, grids, null, s)
    score = F.scorer(prob, cands, ref, null, s)
    return cands, grids, null, ref, score, score(prob.y[None, :])


# ------------------------------------------------------------------ phase 1: the coarse grid
def test_coarse_grid_is_denser_near_zero_and_holds_zero_and_the_bounds():
    g = F.coarse_grid(-1.0, 2.0, 8)                    # an even count: 0 is added, not a grid point of u
    assert g[0] == -1.0 and g[-1] == 2.0 and 0.0 in g and len(g) == 9 and np.all(np.diff(g) > 0)
    steps = np.diff(g)
    assert steps[len(steps) // 2] < steps[-1]          # near 0 finer than at the bound
    # control: power 1 is the uniform grid on either side of 0 (the density comes from the power)
    u = F.coarse_grid(0.0, 1.0, 5, power=1.0)
    assert np.allclose(np.diff(u), 0.25)


def test_grid_phase_zero_row_is_the_nominal_model_and_the_cache_saves_the_batch(idp_model_fixture):
    prob, s = problem(idp_model_fixture), settings()
    cands = list(prob.candidates)
    cache = {}
    g = F.fit_grids(prob, cands, s, cache)
    assert g.batches == 1 and set(g.coarse) == set(cands)
    assert np.allclose(g.base, prob.forward({})[0], equal_nan=True)
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        assert g.grids[c][0] == lo and g.grids[c][-1] == hi and len(g.grids[c]) >= s["grid_points"]
        P = g.coarse[c]
        assert P.shape == (len(g.grids[c]), len(prob.y))
        assert np.allclose(P[np.flatnonzero(g.grids[c] == 0.0)[0]], g.base)      # no effect at 0
        # control: away from 0 the effect moves the prediction (the rows are not copies of the base)
        assert np.nanmax(np.abs(P[-1] - g.base)) > 1e-6, c
    again = F.fit_grids(prob, cands, s, cache)
    assert again.batches == 0 and again.coarse is g.coarse
    # control: another grid is another cache key, solved again
    assert F.fit_grids(prob, cands, settings(grid_points=5), cache).batches == 1


# ------------------------------------------------------------------ phase 2: refinement
def test_refinement_recovers_the_planted_value_and_refines_only_the_leaders(idp_model_fixture):
    true = fx.EFFECTS["idp_moment_term"].magnitudes[0]
    s = settings(fine_candidates=1)
    prob = problem(idp_model_fixture, "idp_moment_term", true)
    cands, grids, null, ref, _, _ = phases_to_observation(prob, s)
    assert abs(ref.est["idp_moment_term"] - true) <= 0.2 * true
    assert list(ref.fine) == ["idp_moment_term"] and ref.batches == 1          # one fine batch, the leader only
    th, P = ref.curves_raw["idp_moment_term"]
    assert np.all(np.diff(th) > 0) and len(th) > len(grids.grids["idp_moment_term"])
    # control: the same phase on a null table puts the candidate's estimate near 0, not at the planted value
    null_prob = problem(idp_model_fixture, "none", 0.0)
    _, _, _, ref0, _, _ = phases_to_observation(null_prob, s)
    assert abs(ref0.est["idp_moment_term"]) < 0.5 * true
    # control: without fine candidates no fine batch is solved
    _, _, _, ref_nf, _, _ = phases_to_observation(prob, settings(fine_candidates=0))
    assert ref_nf.fine == {} and ref_nf.batches == 0


# ------------------------------------------------------------------ phase 3: null tests
def test_null_tests_give_bootstrap_counts_small_for_a_planted_effect_not_for_a_null(idp_model_fixture):
    s = settings(n_bootstrap=99)
    true = fx.EFFECTS["idp_moment_term"].magnitudes[0]
    prob = problem(idp_model_fixture, "idp_moment_term", true)
    cands, _, null, _, score, obs = phases_to_observation(prob, s)
    t = F.null_tests(prob, cands, null, score, obs, s)
    assert t.B == 99 and len(t.Tmax_null) == 99 and t.boot is not None
    for c in cands:
        k = t.p_adj[c] * (t.B + 1) - 1                        # (1 + k) / (B + 1), k a count in 0..B
        assert abs(k - round(k)) < 1e-9 and 0 <= round(k) <= t.B
        assert t.p_raw[c] <= t.p_adj[c] + 1e-12               # max-T is never below the candidate's own p
    assert t.p_adj["idp_moment_term"] < 0.02
    assert np.array_equal(t.Tmax_null, np.max([t.boot["T_c"][c] for c in cands], axis=0))
    again = F.null_tests(prob, cands, null, score, obs, s)    # seeded: the same null tables
    assert np.array_equal(again.Tmax_null, t.Tmax_null)
    # control: on a null table the best candidate's p-value is not small
    prob0 = problem(idp_model_fixture, "none", 0.0, seed=23)
    cands0, _, null0, _, score0, obs0 = phases_to_observation(prob0, s)
    t0 = F.null_tests(prob0, cands0, null0, score0, obs0, s)
    assert max(t0.p_adj.values()) > 0.05 and min(t0.p_adj.values()) > 0.02
    # the adjusted p-value counts the null tables' largest statistic over the candidates (max-T), and that
    # correction for the number of candidates is larger than a candidate's own p-value for some candidate
    T0 = {c: float(obs0["T_c"][c][0]) for c in cands0}
    for c in cands0:
        assert np.isclose(t0.p_adj[c], (1 + np.sum(t0.Tmax_null >= T0[c] - 1e-12)) / (t0.B + 1))
    assert any(t0.p_adj[c] > t0.p_raw[c] for c in cands0)
    # control: no null tables asked for, none drawn
    none = F.null_tests(prob, cands, null, score, obs, settings(n_bootstrap=0))
    assert none.boot is None and none.p_adj == {} and len(none.Tmax_null) == 0 and none.p_fit == {}


# ------------------------------------------------------------------ phase 4: nuisance comparison
def test_nuisance_refit_finds_a_planted_uniform_scale_and_not_in_an_unscaled_table(idp_model_fixture):
    s = settings(n_bootstrap=49)
    prob = problem(idp_model_fixture, "none", 0.0, seed=21, scale=0.8)
    cands, _, null, _, score, obs = phases_to_observation(prob, s)
    tests = F.null_tests(prob, cands, null, score, obs, s)
    refits = F.nuisance_refits(prob, cands, null, score, obs, tests, s)
    assert refits.best_nuisance == "uniform scale"
    assert abs(refits.nres["uniform scale"]["parameters"]["all"] - 0.8) < 0.03
    assert refits.aic["uniform scale"] < refits.aic[null.none_label]
    # control: the same table unscaled is best explained by the null model itself
    prob1 = problem(idp_model_fixture, "none", 0.0, seed=21)
    c1, _, n1, _, sc1, o1 = phases_to_observation(prob1, s)
    r1 = F.nuisance_refits(prob1, c1, n1, sc1, o1, F.null_tests(prob1, c1, n1, sc1, o1, s), s)
    assert r1.best_nuisance == n1.none_label


def test_candidate_is_compared_with_the_best_nuisance_it_is_not_equivalent_to(idp_model_fixture):
    """An axial preload adds the same IDP to every row of this experiment: it is equivalent to the uniform offset,
    which is then not its opponent in the comparison."""
    s = settings(n_bootstrap=49)
    true = fx.EFFECTS["axial_preload"].magnitudes[0]
    prob = problem(idp_model_fixture, "axial_preload", true)
    cands, _, null, ref, score, obs = phases_to_observation(prob, s)
    best = max(cands, key=lambda c: obs["T_c"][c][0])
    _, exact, _ = F.refit(prob, cands, best, ref, null, score, obs)
    tests = F.null_tests(prob, cands, null, score, obs, s)
    refits = F.nuisance_refits(prob, cands, null, score, obs, tests, s)
    assert "uniform offset" in refits.equiv["axial_preload"]
    cmp_ = F.compare_nuisance(cands, "axial_preload", exact, null, score, obs, tests, refits)
    assert cmp_.versus not in refits.equiv["axial_preload"] and cmp_.p_vs is not None
    assert set(cmp_.p_fit) >= {"specimen_mean", "best_candidate", "best_nuisance"}
    assert "best_candidate" not in tests.p_fit                 # the null tests' own record is left as it was
    # control: a candidate equivalent to no family is compared with the lowest AIC among all of them
    refits.equiv["axial_preload"] = []
    cmp2 = F.compare_nuisance(cands, "axial_preload", exact, null, score, obs, tests, refits)
    assert cmp2.versus == min(refits.aic, key=lambda k: (refits.aic[k], k != null.none_label))


def test_explained_share_is_the_chi2_drop_over_the_excess_above_the_null():
    tests = F.NullTests(B=3, c_hat0=1.0, boot={"chi_r": np.array([9.0, 10.0, 11.0])})
    share, after, expected = F.explained_share(np.sqrt(2.0), 10, 30.0, tests)   # chi2 after = 2 * 10 = 20
    assert expected == 10.0 and np.isclose(after, 20.0) and np.isclose(share, (30 - 20) / (30 - 10))
    # control: no excess above the null tables: the share only says whether the refit fits no worse
    assert F.explained_share(np.sqrt(0.5), 10, 8.0, tests)[0] == 1.0
    assert F.explained_share(np.sqrt(0.9), 10, 8.0, tests)[0] == 0.0
    assert F.explained_share(float("nan"), 10, 30.0, tests)[0] == 0.0


# ------------------------------------------------------------------ phase 5: decision
def passing(**kw):
    """Evidence on which every naming criterion passes (the settings' defaults: alpha 0.01, min_gap 1.5,
    min_gap_reduction 0.3)."""
    ev = dict(best="itl", n_rows=20, n_candidates=3, gap_before=3.0, p_adj={"itl": 0.001}, B=199,
              versus="uniform scale", p_vs=0.001, p_fit={"specimen_mean": 0.001, "best_candidate": 0.4},
              explained=0.9, chi_null_obs=180.0, chi_after_obs=30.0, chi_null_expected=20.0)
    ev.update(kw)
    return F.Evidence(**ev)


@pytest.mark.parametrize("field, value, reason", [
    ("gap_before", 1.0, "gap_before 1.00 <= min_gap"),
    ("p_adj", {"itl": 0.2}, "p = 0.2 for itl"),
    ("p_vs", 0.3, "does not beat the nuisance explanation 'uniform scale'"),
    ("p_fit", {"specimen_mean": 0.001, "best_candidate": 0.004}, "leaves a misfit"),
    ("explained", 0.2, "the refit explains 20%"),
])
def test_decision_names_the_effect_only_when_every_criterion_passes(field, value, reason):
    s = settings()
    d = F.decide(passing(), s)
    assert d.named == "itl" and d.decision == "named: itl" and d.reasons == []
    # control: the one failing criterion blocks the name and is the reason given
    bad = F.decide(passing(**{field: value}), s)
    assert bad.named is None and not bad.decision.startswith("named")
    assert any(reason in r for r in bad.reasons), bad.reasons


def test_decision_says_what_the_table_is_when_nothing_is_named():
    s = settings()
    few = F.decide(passing(n_rows=2, too_few=True), s)
    assert few.named is None and few.decision.startswith("nothing named: too few rows: 2 scenario(s)")
    assert F.decide(passing(best=None), s).decision == "nothing named: no candidate effect acts on this experiment"
    # consistent with the null (its goodness of fit passes): nothing named, or the specimen-mean shift with specimens
    calm = dict(p_adj={"itl": 0.5}, p_fit={"specimen_mean": 0.5})
    assert F.decide(passing(**calm), s).decision == "nothing named"
    assert F.decide(passing(with_specimens=True, **calm), s).decision == "nuisance: specimen-mean shift"
    # the null fails, a nuisance explains it and its refit is adequate: the nuisance
    nres = {"uniform scale": {"description": "uniform scale 0.8"}}
    nuis = dict(p_adj={"itl": 0.5}, best_nuisance="uniform scale", p_nuis={"uniform scale": 0.001}, nres=nres,
                p_fit={"specimen_mean": 0.001, "best_nuisance": 0.5})
    assert F.decide(passing(**nuis), s).decision == "nuisance: uniform scale 0.8"
    # control: the same with an inadequate nuisance refit is unexplained
    nuis["p_fit"] = {"specimen_mean": 0.001, "best_nuisance": 0.001}
    assert F.decide(passing(**nuis), s).decision == "unexplained"
