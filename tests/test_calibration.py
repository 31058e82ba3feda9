"""Backward calibration (lumbar.calibration): round trip on a noise-free surrogate, the disc-only stage,
the written characteristic directory and its loader."""
import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from lumbar import calibration as cal
from lumbar.characteristics import SoftplusLaw, load_characteristic_set
from lumbar.elements.ligament import softplus_force
from lumbar.fsu import build_fsu
from lumbar.stepwise_reduction import (EXPERIMENT_SCHEMA, read_experiment_table, reference_table,
                                       simulate_stepwise_reduction)
from lumbar.virtual_experiment import SpecimenVariation, stepwise_reduction_table

from conftest import ROOT

DERIVED = ROOT / "data" / "experiments" / "heuer2007_disc_only_derived_from_published_fit.csv"
ZERO = SpecimenVariation(**{f.name: 0.0 for f in dataclasses.fields(SpecimenVariation)})
# generating ligament laws of the round trip, inside the fitted family (c such that F(0) = 0, d > 0)
TRUTH = {"ALL": (120.0, -9.0, 3.0), "PLL": (40.0, -10.0, 2.5), "CL": (60.0, -11.0, 3.0),
         "FL": (30.0, -10.0, 2.0), "ISL": (15.0, -4.0, 1.5), "SSL": (8.0, 2.0, 2.0)}


@pytest.fixture(scope="module")
def geometry():
    from lumbar.geometry import load_geometry
    return load_geometry("default", levels=["L4-L5"])


@pytest.fixture(scope="module")
def truth_set():
    base = load_characteristic_set("calibrated")
    ligs = {k: SoftplusLaw(a, b, cal.c_zero(a, b, d), d, base.ligaments[k].prestrain_pct)
            for k, (a, b, d) in TRUTH.items()}
    return dataclasses.replace(base, ligaments=ligs)


@pytest.fixture(scope="module")
def round_trip(geometry, truth_set):
    table = stepwise_reduction_table(geometry, truth_set, seed=1, n_specimens=1, variation=ZERO, noise_sd_deg=0.0)
    res = cal.calibrate(geometry, reference_table(table), initial=truth_set)
    return table, res


def test_round_trip_rom_residual_below_0_01_deg(geometry, round_trip):
    table, res = round_trip
    sim = simulate_stepwise_reduction(build_fsu(geometry, res.charset))
    m = sim.merge(table, on=["stage", "direction", "moment_nm"])
    assert len(m) == 160 and m["converged"].all()
    err = (m["rom_deg"] - m["rom_mean_deg"]).abs()
    assert err.max() < 0.01, m.loc[err.idxmax()]


def test_round_trip_recovers_disc_and_facet(truth_set, round_trip):
    _, res = round_trip
    for d, p in truth_set.disc.torque.items():
        np.testing.assert_allclose(res.disc[d], p, rtol=1e-3, err_msg=d)
    assert res.facet_stiffness == pytest.approx(truth_set.facet.stiffness, rel=0.05)


def test_round_trip_recovers_ligament_laws(truth_set, round_trip):
    """Parameters where identifiable; everywhere: the force over the strains the fit stage visits."""
    _, res = round_trip
    pts = res.ligament_points
    for k, (a, b, d) in TRUTH.items():
        eps = pts.loc[pts["ligament"] == k, "strain_pct"].to_numpy()
        law = truth_set.ligaments[k]
        f_true = softplus_force(eps, law.a, law.b, law.c, law.d)[0]
        f_fit = softplus_force(eps, *res.ligaments[k])[0]
        assert np.all(np.abs(f_fit - f_true) <= 0.02 * np.abs(f_true).max() + 0.2), k
        if np.abs(f_true).max() > 5.0:                      # engaged: parameters identifiable
            np.testing.assert_allclose(res.ligaments[k][:2], (a, b), rtol=0.05, atol=0.3, err_msg=k)


def test_disc_only_stage_reproduces_derived_rows(geometry):
    derived = read_experiment_table(DERIVED)
    ref = reference_table(derived)
    torque = {}
    for d in ("flexion", "extension", "lateral_bending", "axial_rotation"):
        r = ref[ref["direction"] == d]
        torque[d] = cal.fit_disc_direction(np.radians(r["rom_mean_deg"]), r["moment_nm"])
    base = load_characteristic_set("calibrated")
    cs = dataclasses.replace(base, disc=dataclasses.replace(base.disc, torque=torque))
    sim = simulate_stepwise_reduction(build_fsu(geometry, cs), stages=["wo_all"])
    m = sim.merge(derived, on=["stage", "direction", "moment_nm"])
    assert len(m) == 20 and m["converged"].all()
    assert (m["rom_deg"] - m["rom_mean_deg"]).abs().max() < 0.1


def test_write_characteristics_loadable(tmp_path, round_trip):
    _, res = round_trip
    out = cal.write_characteristics(res, ROOT / "data" / "characteristics", tmp_path / "chars", "test table")
    cs = load_characteristic_set("calibrated", data_dir=out)
    for k in cal.CALIBRATED_LIGAMENTS:
        assert (cs.ligaments[k].a, cs.ligaments[k].d) == pytest.approx((res.ligaments[k][0], res.ligaments[k][3]))
    assert "ITL" not in cs.ligaments
    assert cs.disc.torque["extension"] == pytest.approx(res.disc["extension"])
    sp = pd.read_csv(out / "ligaments_softplus.csv")
    assert set(sp.loc[sp["set"] == "calibrated", "kind"]) == {"calibrated_on_surrogate"}
    t1 = cal.table1(res, load_characteristic_set("calibrated"))
    assert {"p1_nm", "paper_p1_nm", "data_kind", "fit_not_converged"} <= set(t1.columns)
    t3 = cal.table3(res, load_characteristic_set("calibrated"))
    n_nc = {r.structure: int(float(r.n_not_converged)) for r in res.summary.itertuples()}
    assert t3.set_index("ligament")["fit_not_converged"].to_dict() == {k: n_nc[k] for k in t3["ligament"]}
    assert t1["fit_not_converged"].tolist() == [n_nc[f"disc:{d}"] for d in t1["direction"]]


def test_bad_disc_fit_too_few_points():
    with pytest.raises(ValueError, match=">= 3"):
        cal.fit_disc_direction([0.01, 0.02], [1.0, 2.0])


def test_reject_reference_without_disc_stage(geometry):
    derived = read_experiment_table(DERIVED)
    with pytest.raises(ValueError, match="wo_pll"):
        cal.calibrate(geometry, derived)


def test_c_zero_gives_zero_force_at_zero_strain():
    for a, b, d in TRUTH.values():
        assert cal.softplus_zero_law(0.0, a, b, d) == pytest.approx(0.0, abs=1e-12)
        assert a * math.log1p(math.exp(b / d)) + cal.c_zero(a, b, d) == pytest.approx(0.0, abs=1e-9)
    assert EXPERIMENT_SCHEMA.required[:3] == ["stage", "direction", "moment_nm"]
