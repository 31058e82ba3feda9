"""The discrepancy discovery on tables it did not make: a null hypothesis with specimens in it, nuisance explanations
beside the candidates, and the fast path (a bank of specimens resampled per null table) against the reference path
(new specimens for every null table).

The L2-S1 tables here come from a SYNTHETIC specimen population (a TEST FIXTURE, not data, not the mechanics): each
specimen scales the nominal IDP pattern of the fixture model by its own disc-load factor, has its own sensitivity to
the sagittal moment, and a term second order in its disc-load factor, so the mean of varied specimens is not the
nominal model (the specimen-mean shift of a nonlinear model) and one specimen moves all its rows together; the
fixtures add multiplicative and additive noise and vary their number of specimens. The ROM test at the end runs the
mechanics: virtual specimens of the L4-L5 unit (lumbar.experiments.virtual_experiment)."""
import numpy as np
import pandas as pd
import pytest
from scipy.stats import kstest, ks_2samp

from lumbar import discovery as D
from lumbar.discovery.specimens import SpecimenBank, null_datasets, fit_null_noise
from lumbar.experiments import effects as fx

#: Kolmogorov-Smirnov threshold for "the null p-values are uniform enough": the test of uniformity must not reject
#: at the 1 % level (over 60 null tables of the synthetic population; the benchmark applies the same threshold to
#: its nulls, lumbar.discovery.power_study.TARGETS)
KS_P_MIN = 0.01


@pytest.fixture(scope="module")
def model(idp_model_fixture):
    """The nominal L2-S1 model table (TEST FIXTURE of conftest.py)."""
    return idp_model_fixture


def population(model, K, seed):
    """K synthetic specimens (SYNTHETIC, see the module doc): IDP (K, 49) [MPa], moment (K, 49), IDP per newton.
    Independent sources like a specimen's: a disc-load factor of every row, a factor per muscle set-up (how the
    cables load this specimen), a moment sensitivity, and a term second order in the disc-load factor."""
    rng = np.random.default_rng(seed)
    base = model["idp_mpa"].to_numpy(float)
    M = model["disc_moment_sagittal_nm"].to_numpy(float)
    setups = pd.factorize(model["muscle_setup"])[0]
    f = np.exp(0.06 * rng.standard_normal((K, 1)))                            # disc-load factor
    fs = np.exp(0.05 * rng.standard_normal((K, setups.max() + 1)))[:, setups]  # per muscle set-up
    g = 0.01 * rng.standard_normal((K, 1))                                    # moment sensitivity [1/(N*m)]
    idp = base * f * fs * (1 + g * M) + 1.5 * (f - 1) ** 2 * np.abs(M)         # second order: mean shift ~ |M|
    Mk = M * np.exp(0.1 * rng.standard_normal((K, 1)))
    per_n = float(model["idp_per_newton_pa"].iat[0]) * np.exp(0.05 * rng.standard_normal(K))
    return idp, Mk, per_n


def bank_of(model, K, seed):
    idp, Mk, per_n = population(model, K, seed)
    return SpecimenBank("idp_invitro", model[["muscle_setup", "load_case"]].reset_index(drop=True), idp,
                        f"SYNTHETIC test population, seed {seed}", {"moment": Mk, "per_n": per_n})


def table(model, seed, effect=None, value=0.0, scale=1.0, noise=(0.04, 0.01)):
    """A fixture table of 6-8 synthetic specimens (TEST FIXTURE) with an optional IDP effect of the library (applied
    per specimen with its own moment and IDP per newton) or a uniform scale of the IDP (outside the library)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 9))
    idp, Mk, per_n = population(model, n, 10_000 + seed)
    if effect:
        idp = fx.idp_delta(effect, value, idp * 1e6, Mk, per_n[:, None]) / 1e6
    idp = idp * scale
    A = idp * (1 + noise[0] * rng.standard_normal(idp.shape)) + noise[1] * rng.standard_normal(idp.shape)
    return pd.DataFrame({"muscle_setup": model["muscle_setup"], "load_case": model["load_case"],
                         "idp_mean_mpa": A.mean(0), "idp_sd_mpa": A.std(0, ddof=1), "n_specimens": n,
                         "kind": "surrogate", "source": "TEST FIXTURE: synthetic specimens"})


def config(**disc):
    return {"seed": 5, "discovery": {"n_bootstrap": 199, **disc}}


@pytest.fixture(scope="module")
def bank(model):
    """The null bank: 500 synthetic specimens. A bank of K has its own sampling error (its mean about sqrt(n / K) of
    a table's standard error off the population's, its variance about sqrt(2 / K) off); the finite-size corrections
    average over banks (test_p_values_of_nulls_from_varied_specimens_are_uniform_enough gives every table its own
    bank of 48), but one bank for every table shares its error with all of them: here it is kept small."""
    return bank_of(model, 500, 1)


def run(model, df, bank, cfg=None, **meta):
    cfg = cfg or config()
    prob = D.build_problem("idp_invitro", df, cfg, idp_model=model, bank=bank)
    prob.meta.update(meta)
    return D.discover(prob, D.discovery_settings(cfg))


# ------------------------------------------------------------------ the null with specimens
def test_seeded_nulls_from_varied_specimens_name_nothing_where_a_null_without_specimens_names_effects(model, bank):
    """Varied specimens of a nonlinear model: their mean is not the nominal model. The null with specimens names
    nothing on any of eight seeded tables; the former null (nominal model + noise) names an effect on some of them
    (the mechanism of the wrong name: the specimen-mean shift and the specimens' shared deviations read as an
    effect)."""
    with_specimens, without = [], []
    for seed in range(8):
        df = table(model, seed)
        r = run(model, df, bank)["result"]
        with_specimens.append(r["named_effect"])
        assert r["null_model"]["kind"] == "virtual_specimens" and r["null_model"]["specimens"] == 500
        without.append(D.discover(D.build_problem("idp_invitro", df, config(null_specimens=0), idp_model=model),
                                  D.discovery_settings(config(null_specimens=0)))["result"]["named_effect"])
    assert with_specimens == [None] * 8
    assert sum(x is not None for x in without) >= 2, without


def test_uniform_idp_scale_names_nothing_and_reports_the_nuisance(model, bank):
    """An IDP scaled by 0.82 (a transducer calibration, outside the library): no effect named, the uniform scale
    reported with its refit, in discovery.json, the section text and the figure's column."""
    out = run(model, table(model, 3, scale=0.82), bank)
    r = out["result"]
    assert r["named_effect"] is None
    assert r["decision"].startswith("nuisance: uniform scale 0.8"), r["decision"]
    # the fitted scale also holds the mean disc-load factor of the table's own 6-8 specimens (a few per cent)
    assert abs(r["nuisance"]["uniform scale"]["parameters"]["all"] - 0.82) < 0.06
    assert r["gap_nuisance"] < 0.5 * r["gap_before"]
    md = D.section_markdown(out, "t.csv")
    assert "uniform scale 0.8" in md and "Nuisance explanations" in md
    assert np.isfinite(out["scenarios"]["z_nuisance"]).all()


@pytest.mark.parametrize("effect", ["disc_load_share", "idp_moment_term", "axial_preload"])
def test_planted_effect_at_the_benchmark_magnitude_is_still_named(model, bank, effect):
    true = fx.EFFECTS[effect].magnitudes[0]
    r = run(model, table(model, 11, effect, true), bank)["result"]
    assert r["named_effect"] == effect, (r["decision"], r["decision_reasons"])
    assert abs(r["parameter_estimate"]["value"] - true) <= 0.35 * true
    if effect == "axial_preload":          # a uniform offset of the IDP on this experiment: said so
        assert "uniform offset" in r["named_equivalent_to"]


def test_p_values_of_nulls_from_varied_specimens_are_uniform_enough(model):
    """Sixty seeded nulls of the synthetic population, each discovered with its own bank of 48 specimens (the
    corrections for the bank's finite size hold over banks): Kolmogorov-Smirnov against U(0, 1) does not reject at
    KS_P_MIN, and at most 5 % of them name an effect."""
    ps, named = [], 0
    for seed in range(100, 160):
        r = run(model, table(model, seed), bank_of(model, 48, 500 + seed), config(n_bootstrap=99))["result"]
        ps.append(r["p_value"])
        named += r["named_effect"] is not None
    assert named <= 3
    assert kstest(ps, "uniform").pvalue >= KS_P_MIN, sorted(ps)


def test_fast_path_gives_the_p_values_of_the_reference_path(model):
    """The fast path (the table's n specimens resampled from a bank, with the corrections for its size) against the
    reference path (new specimens of the population for every null table), on a bank of 240 (a bank's own sampling
    error, about sqrt(n / K) of a table's standard error, is what the corrections average over): the p-values of
    the same tables agree within the Monte-Carlo error of 400 null tables each, and so do the null distributions
    of the chi-square (two-sample KS). Without the bank-mean correction the null is too narrow (checked too)."""
    B = 400
    bank = bank_of(model, 240, 1)
    fresh = bank_of(model, B * 8, 2)
    cfg = config(n_bootstrap=B)
    pf, pr = [], []
    Tf = Tr = None
    for seed, kw in [(21, {}), (22, {}), (23, {"effect": "disc_load_share", "value": 0.03}),
                     (24, {"scale": 0.93}), (25, {"effect": "idp_moment_term", "value": 0.012e6})]:
        df = table(model, seed, **kw)
        a = run(model, df, bank, cfg)["result"]
        b = run(model, df, bank, cfg, null_fresh=fresh)["result"]
        pf.append(a["p_value"])
        pr.append(b["p_value"])
    tol = [3 * np.sqrt(max(p, 0.01) * (1 - p) / B) * np.sqrt(2) + 0.02 for p in pr]
    assert all(abs(a - b) <= t for a, b, t in zip(pf, pr, tol)), list(zip(pf, pr))
    # the null distributions themselves (one table's problem)
    prob = D.build_problem("idp_invitro", table(model, 21), cfg, idp_model=model, bank=bank)
    valid = np.isfinite(prob.y) & np.isfinite(bank.mean)
    nm = fit_null_noise(prob.meta["spec_sd"], bank, valid)
    Yf, Sf = null_datasets(prob, bank, nm, B, np.random.default_rng(1))
    Yr, Sr = null_datasets(prob, bank, nm, B, np.random.default_rng(1), fresh=fresh)
    r = bank.mean

    def chi(Y, S):
        return np.sum(((Y - r) / S)[:, valid] ** 2, 1)

    Tf, Tr = chi(Yf, Sf), chi(Yr, Sr)
    assert ks_2samp(Tf, Tr).pvalue >= 0.01
    # the correction matters: resampling the 48 specimens without it gives a visibly narrower null
    dev_f = np.var(Yf - r, axis=0)[valid].mean()
    dev_r = np.var(Yr - r, axis=0)[valid].mean()
    K, n = bank.K, int(prob.meta["n_per_row"].max())
    assert abs(dev_f / dev_r - 1) < 0.15
    assert dev_f / ((K + n) / (K - n)) < 0.92 * dev_r


def test_noise_fitted_from_the_table_spread(model):
    """A table more spread than the virtual specimens: the excess is measurement noise, additive and relative, near
    what made it (noise of 10 % + 0.03 MPa, larger than the specimens' spread; five tables, a bank of 1000); a table
    less spread: no noise, the variation of the specimens kept (a wider null), the ratio reported."""
    bank = bank_of(model, 1000, 1)
    ratios = []
    for seed in range(31, 36):
        prob = D.build_problem("idp_invitro", table(model, seed, noise=(0.10, 0.03)), config(), idp_model=model,
                               bank=bank)
        valid = np.isfinite(prob.y)
        nm = fit_null_noise(prob.meta["spec_sd"], bank, valid)
        r = bank.mean[valid]
        made = np.sqrt(0.03 ** 2 + (0.10 * r) ** 2)             # the fixture's noise per specimen
        ratios.append(np.median(np.sqrt(nm.a2 + nm.b2 * r ** 2) / made))
        assert nm.lam == 1.0
    assert 0.5 < np.median(ratios) < 2.0, ratios
    narrow = fit_null_noise(0.3 * np.sqrt(bank.var), bank, valid)
    assert narrow.lam == 1.0 and narrow.a2 == narrow.b2 == 0 and np.isclose(narrow.spread_ratio, 0.09)


def test_candidate_equivalent_to_a_nuisance_is_flagged(model, bank):
    r = run(model, table(model, 41), bank)["result"]
    nc = r["identifiability"]["nuisance_correlation"]
    assert nc["axial_preload"]["uniform offset"] > 0.999                  # IDP += per_n P: an offset
    assert "axial_preload" in r["nuisance"]["uniform offset"]["equivalent_candidates"]
    assert nc["disc_load_share"]["uniform offset"] < 0.9


# ------------------------------------------------------------------ the mechanics: virtual specimens of L4-L5
ROM_CFG = {"stages": ["intact", "wo_cl", "wo_va", "wo_pll"], "moments_nm": [2.5, 7.5], "fixture_specimens": 16,
           "effects": ["ligament_prestrain"], "out_of_library": ["disc_scale"], "n_seeds": 1, "n_magnitudes": 2,
           "near_threshold_factors": [], "n_null": 1, "n_ool_seeds": 1, "experiments": ["stepwise_rom"]}


@pytest.mark.slow
def test_rom_from_virtual_specimens_null_unnamed_planted_prestrain_named_softer_disc_unnamed(tmp_path):
    """Virtual specimens of the L4-L5 unit for both the null bank (24) and the fixtures (16, another stream): the null
    table names nothing, the larger benchmark prestrain is named, a disc softer by 0.7 (outside the library) is
    not."""
    cfg = {"seed": 3, "discovery": {"grid_points": 9, "n_bootstrap": 199, "null_specimens": 24,
                                    "effects": ["ligament_prestrain", "va_neutral_offset", "itl", "passive_muscle"],
                                    "benchmark": dict(ROM_CFG)}}
    cases = D.benchmark_cases(cfg)
    cases = cases[cases["magnitude_label"].isin(["m2", "none", "x0.7"])]
    bench = D.run_benchmark_cases(cfg, cases, tmp_path, worked_cases=1)
    got = dict(zip(bench["hidden_effect"], bench["named_effect"]))
    assert got == {"ligament_prestrain": "ligament_prestrain", "none": "none", "disc_scale": "none"}, bench[
        ["case", "named_effect", "decision", "p_value"]]
    assert (tmp_path / bench["case"].iat[0] / "section.md").is_file()        # the worked example
    assert bench["correct"].all()


def test_bank_file_is_parsed_once_and_reread_when_it_changes(tmp_path):
    """A benchmark job runs one discovery per fixture on the same bank file: it is parsed once per process, and a
    changed file (size or modification time) is read again, never answered from the old parse."""
    import os

    from lumbar.discovery import specimens as SP

    def table(offset):
        rows = [{"specimen": k, "stage": "intact", "direction": d, "moment_nm": 10.0, "rom_deg": 5.0 + k + offset,
                 "source": "TEST FIXTURE (not data)"} for k in range(3) for d in ("flexion", "extension")]
        return pd.DataFrame(rows)

    p = tmp_path / "bank.csv"
    SP.write_bank(table(0.0), p)
    a = SP.read_bank(p, "stepwise_rom")
    assert SP.read_bank(p, "stepwise_rom") is a                       # the same parse
    SP.write_bank(table(0.25), p)
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))     # a new version even within the clock's step
    b = SP.read_bank(p, "stepwise_rom")
    assert b is not a
    np.testing.assert_allclose(b.values - a.values, 0.25)
