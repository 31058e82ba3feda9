"""Failing controls of the admissibility criteria (lumbar.experiments.admissibility.criteria_table).

Every criterion must be able to fail. Each test builds by hand the small tables ``criteria_table`` consumes (the
columns of what ``assess`` returns for a unit: moment-rotation curves with the internal loads per step, and the axial
compression curve), a baseline that passes every criterion, and perturbs exactly the quantity one criterion judges:
that criterion's row must turn to ``passed == False`` and no other row may change. Where a criterion could be
mis-wired (the wrong column, the wrong side, the wrong sign, a reversed inequality), the matching passing input is
built so that the mis-wired criterion would fail it.

No unit is solved here: the tests run in well under a second."""
import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import admissibility as ADM

LEVEL = "L4-L5"
MOMENTS = np.round(np.arange(0.0, 10.0 + 1e-9, ADM.JUMP_STEP_NM), 2)
DIRECTIONS = ("flexion", "extension", "lateral_bending_right", "lateral_bending_left", "axial_rotation_left",
              "axial_rotation_right")
KINDS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL")
#: the plane of every direction in the neutral-zone reference
PLANE_OF = {d: p for p, ds in ADM.NZ_PLANES.items() for d in ds}
#: the rotation exponent of the baseline curves (theta = c * M**P: a stiffening curve, compliance falling with M)
P = 0.6
#: baseline ligament tensions [N] at rest and at 10 N*m flexion, and the y moments [N*m] they produce at 10 N*m
#: (negative = resisting flexion). The tension order of the CL and FL is opposite to their moment order (the flavum
#: lies near the centre of rotation), so a criterion comparing the wrong column fails the baseline.
REST_T = {"ALL": 20.0, "PLL": 1.0, "FL": 30.0, "CL": 5.0, "ISL": 0.0, "SSL": 0.0}
FLEX10_T = {"ALL": 5.0, "PLL": 2.0, "FL": 60.0, "CL": 40.0, "ISL": 60.0, "SSL": 20.0}
FLEX10_MY = {"ALL": 0.5, "PLL": -0.05, "FL": -0.8, "CL": -2.5, "ISL": -2.0, "SSL": -0.8}
REST_FACET_N = 10.0


@pytest.fixture(scope="module")
def nz():
    z = ADM.neutral_zones(LEVEL)
    assert set(z) == set(ADM.NZ_PLANES)         # the measured zone of every plane: every plane is judged
    return z


@pytest.fixture(scope="module")
def literature():
    return ADM.read_literature()


@pytest.fixture(scope="module")
def limits():
    """Pre-tension limits well above the baseline's rest tensions (the unloaded criterion is not under test here)."""
    return pd.DataFrame({"ligament": list(KINDS), "paper_pretension_n": 100.0, "remus2021_pretension_n": np.nan,
                         "limit_n": 100.0, "limit_source": "paper", "paper_source": "test", "remus_source": ""})


def _nz_amplitude(nz, direction, fraction=0.55):
    """Rotation [deg] at 1 N*m of one side: ``fraction`` of its plane's measured neutral zone (both sides together:
    2 x fraction, well above NZ_FRACTION)."""
    return fraction * nz[PLANE_OF[direction]][0]


def _curves(nz) -> pd.DataFrame:
    """A unit that passes every criterion: stiffening curves theta = c * M**P (c: rotation at 1 N*m), facets loading
    in extension and (the contralateral one) in axial rotation, the posterior ligaments loading in flexion."""
    rows = []
    for d in DIRECTIONS:
        c = _nz_amplitude(nz, d)
        for M in MOMENTS:
            s = M / MOMENTS[-1]
            row = {"stage": "intact", "direction": d, "moment_nm": float(M), "rotation_deg": c * M ** P,
                   "converged": True, "jump": False,
                   "facet_left_contact_n": REST_FACET_N, "facet_right_contact_n": REST_FACET_N}
            if d == "flexion":                                  # the facets open, the posterior ligaments load
                row["facet_left_contact_n"] = row["facet_right_contact_n"] = REST_FACET_N * max(0.0, 1.0 - M)
            elif d == "extension":                              # both facets load
                row["facet_left_contact_n"] = row["facet_right_contact_n"] = REST_FACET_N + 8.0 * M
            elif d == "axial_rotation_left":
                # the contralateral (right) facet loads, slowly; the ipsilateral one opens fast: their sum falls
                # (a criterion summing both facets, or judging the left one, fails this baseline)
                row["facet_right_contact_n"] = REST_FACET_N + 0.5 * M
                row["facet_left_contact_n"] = REST_FACET_N * max(0.0, 1.0 - M)
            elif d == "axial_rotation_right":
                row["facet_left_contact_n"] = REST_FACET_N + 0.5 * M
                row["facet_right_contact_n"] = REST_FACET_N * max(0.0, 1.0 - M)
            for k in KINDS:
                t10, my10 = (FLEX10_T[k], FLEX10_MY[k]) if d == "flexion" else (REST_T[k], 0.0)
                row[f"{k}_tension_n"] = REST_T[k] + s * (t10 - REST_T[k])
                row[f"{k}_moment_y_nm"] = s * my10
            rows.append(row)
    return pd.DataFrame(rows)


def _compression(facet_share_at_max=0.10, converged=True) -> pd.DataFrame:
    """An axial (follower) compression curve 0-1000 N: the facets' share rising linearly to ``facet_share_at_max``
    at the largest force, the disc carrying the rest."""
    F = np.arange(0.0, ADM.COMPRESSION_N + 1e-9, 50.0)
    share = facet_share_at_max * F / F[-1]
    conv = np.ones(len(F), bool)
    conv[-1] = converged
    return pd.DataFrame({"force_n": F, "converged": conv, "facet_share": share, "disc_share": 1.0 - share,
                         "facet_left_contact_n": 0.5 * share * F, "facet_right_contact_n": 0.5 * share * F,
                         "disc_axial_n": (1.0 - share) * F})


def _table(curves, compression, limits, nz, literature):
    return ADM.criteria_table(curves, compression, limits, LEVEL, nz, literature)


def _passed(t) -> pd.Series:
    return t.set_index(["criterion", "direction"])["passed"]


def _assert_only_changed(base, pert, criterion, directions):
    """``pert`` fails exactly the rows of ``criterion`` in ``directions``; every other row is as in ``base``."""
    b, p = _passed(base), _passed(pert)
    assert b.index.equals(p.index)                               # no row appeared or vanished
    changed = {key for key in b.index if b[key] != p[key]}
    assert changed == {(criterion, d) for d in directions}, pert[~pert["passed"]]
    assert not p[[(criterion, d) for d in directions]].any()


def _row(t, criterion, direction):
    r = t[(t["criterion"] == criterion) & (t["direction"] == direction)]
    assert len(r) == 1, (criterion, direction, t[["criterion", "direction"]])
    return r.iloc[0]


def _rows(t, prefix):
    return t[t["criterion"].str.startswith(prefix)]


@pytest.fixture(scope="module")
def baseline(nz, literature, limits):
    """The passing unit, its compression curve and its criteria table (each control compares its own criterion's
    rows with this table, so a criterion that fails the baseline fails its own controls, not all of them)."""
    curves, comp = _curves(nz), _compression()
    return curves, comp, _table(curves, comp, limits, nz, literature)


def test_baseline_unit_passes_every_criterion(baseline):
    """The matching passing input: every row passes, and every criterion under test here has its rows."""
    _, _, t = baseline
    assert t["passed"].all(), t[~t["passed"]][["criterion", "direction", "value", "limit"]]
    judged = set(zip(t["criterion"], t["direction"]))
    assert {(NZ, p) for p in ADM.NZ_PLANES} <= judged
    assert {(ISL_SSL, "flexion"), (CL_FL, "flexion"), (COMP, "compression")} <= judged
    assert {(FACET, d) for d in ("extension", "axial_rotation_left", "axial_rotation_right")} <= judged


# ------------------------------------------------------------------ 1. the neutral-zone proxy
NZ = "neutral-zone proxy: rotation at +1 plus -1 N*m"


def _stiff_near_neutral(curves, directions, nz, fraction=0.3):
    """The same range of motion at 10 N*m, but stiff around the neutral position: theta = R10 * (M/10)**q with q
    chosen so that the rotation at 1 N*m is ``fraction`` of the plane's measured zone (q <= 1: still stiffening)."""
    out = curves.copy()
    for d in directions:
        sel = out["direction"] == d
        M = out.loc[sel, "moment_nm"].to_numpy(float)
        R10 = float(out.loc[sel & (out["moment_nm"] == MOMENTS[-1]), "rotation_deg"].iloc[0])
        q = np.log10(R10 / (fraction * nz[PLANE_OF[d]][0]))
        assert 0.0 < q <= 1.0
        out.loc[sel, "rotation_deg"] = R10 * (M / MOMENTS[-1]) ** q
    return out


def test_neutral_zone_fails_a_unit_stiff_around_neutral(baseline, nz, literature, limits):
    """Flexion and extension reach the baseline's rotation at 10 N*m but rotate little at +-1 N*m: the rotations at
    +1 and -1 N*m add up to less than NZ_FRACTION of the measured zone and the flexion-extension row fails; the curve
    shape (no snap, stiffening) and the other planes are untouched."""
    curves, comp, base = baseline
    stiff = _stiff_near_neutral(curves, ("flexion", "extension"), nz)
    for d in ("flexion", "extension"):              # the perturbation: only near neutral, not at the full moment
        b, s = (c[c["direction"] == d].set_index("moment_nm")["rotation_deg"] for c in (curves, stiff))
        assert s[10.0] == pytest.approx(b[10.0]) and s[1.0] < 0.6 * b[1.0]
    t = _table(stiff, comp, limits, nz, literature)
    _assert_only_changed(base, t, NZ, ["flexion_extension"])
    r = _row(t, NZ, "flexion_extension")
    assert r["value"] < r["limit"] == pytest.approx(ADM.NZ_FRACTION * nz["flexion_extension"][0])
    assert _row(base, NZ, "flexion_extension")["value"] >= r["limit"]


def test_neutral_zone_needs_both_sides_of_the_plane(baseline, nz, literature, limits):
    """A unit stiff near neutral on one side only (axial rotation to the right) is still judged on the sum of both
    sides: it passes while the other side makes up for it, and fails when both sides are stiff."""
    curves, comp, base = baseline
    one = _stiff_near_neutral(curves, ("axial_rotation_right",), nz, fraction=0.25)
    t1 = _table(one, comp, limits, nz, literature)
    assert _row(t1, NZ, "axial_rotation_right_left")["passed"]         # 0.55 + 0.25 of the zone >= 0.75
    both = _stiff_near_neutral(curves, ("axial_rotation_right", "axial_rotation_left"), nz, fraction=0.25)
    t2 = _table(both, comp, limits, nz, literature)
    _assert_only_changed(base, t2, NZ, ["axial_rotation_right_left"])


def test_neutral_zone_limit_follows_the_measured_zone(baseline, nz, literature, limits):
    """The same unit fails when the measured zone of its plane is larger: the criterion reads the reference."""
    curves, comp, base = baseline
    wider = {**nz, "lateral_bending_right_left": (3.0 * nz["lateral_bending_right_left"][0], "test: a wider zone")}
    t = _table(curves, comp, limits, wider, literature)
    _assert_only_changed(base, t, NZ, ["lateral_bending_right_left"])


# ------------------------------------------------------------------ 2. the ISL above the SSL
ISL_SSL = "ISL carries more than the SSL at 10 N*m flexion"


def _flexion_end(curves, **cols):
    """``curves`` with columns of the flexion row at the largest moment set to the given values."""
    out = curves.copy()
    sel = (out["direction"] == "flexion") & (out["moment_nm"] == out["moment_nm"].max())
    assert sel.sum() == 1
    for c, v in cols.items():
        out.loc[sel, c] = v
    return out


def test_isl_over_ssl_fails_when_the_ssl_carries_more(baseline, nz, literature, limits):
    """Swapping the ISL and SSL tensions at 10 N*m flexion (their sum, their moments, both in tension: unchanged)
    makes the SSL carry more than the ISL, against Hindle et al. (ISL about 75 %): only that row fails. The moments
    still put the ISL first, so a criterion comparing moments instead of tensions would not see it."""
    curves, comp, base = baseline
    swapped = _flexion_end(curves, ISL_tension_n=FLEX10_T["SSL"], SSL_tension_n=FLEX10_T["ISL"])
    t = _table(swapped, comp, limits, nz, literature)
    _assert_only_changed(base, t, ISL_SSL, ["flexion"])
    r, b = _row(t, ISL_SSL, "flexion"), _row(base, ISL_SSL, "flexion")
    assert r["value"] < r["limit"] < b["value"]                 # the ISL's fraction of the ISL+SSL force, vs 1/2


def test_isl_over_ssl_fails_when_both_are_slack(baseline, nz, literature, limits):
    """Neither ligament loaded at 10 N*m (ISL == SSL == 0): the ISL does not carry more, the row fails (beside the
    'in tension' and share rows, which fail for the same reason)."""
    curves, comp, _ = baseline
    slack = _flexion_end(curves, ISL_tension_n=0.0, SSL_tension_n=0.0, ISL_moment_y_nm=0.0, SSL_moment_y_nm=0.0)
    t = _table(slack, comp, limits, nz, literature)
    assert not _row(t, ISL_SSL, "flexion")["passed"]


# ------------------------------------------------------------------ 3. the CL above the FL
CL_FL = "CL moment above FL moment at 10 N*m flexion"


def test_cl_over_fl_fails_when_the_flavum_resists_more(baseline, nz, literature, limits):
    """The flavum resisting more of the flexion moment than the capsular ligaments (moments swapped, tensions kept:
    the CL still carries less tension than the FL in both cases) fails the Adams, Hutton & Stott ordering; the
    baseline, where the tension order is the opposite of the moment order, passes: the criterion judges moments."""
    curves, comp, base = baseline
    swapped = _flexion_end(curves, CL_moment_y_nm=FLEX10_MY["FL"], FL_moment_y_nm=FLEX10_MY["CL"])
    t = _table(swapped, comp, limits, nz, literature)
    _assert_only_changed(base, t, CL_FL, ["flexion"])
    assert _row(t, CL_FL, "flexion")["value"] < 0.0 < _row(base, CL_FL, "flexion")["value"]


def test_cl_over_fl_counts_only_a_moment_resisting_flexion(baseline, nz, literature, limits):
    """A capsular moment as large as the baseline's but of the other sign (positive y: driving the flexion, not
    resisting it) must fail although its magnitude exceeds the flavum's: the sign convention is part of the check."""
    curves, comp, base = baseline
    driving = _flexion_end(curves, CL_moment_y_nm=-FLEX10_MY["CL"])
    t = _table(driving, comp, limits, nz, literature)
    _assert_only_changed(base, t, CL_FL, ["flexion"])


# ------------------------------------------------------------------ 4. the facets loading with the moment
FACET = "facet contact non-decreasing with the moment"


def _set_facets(curves, direction, left=None, right=None):
    """``curves`` with the facet contact forces of ``direction`` replaced by functions of the moment."""
    out = curves.copy()
    sel = out["direction"] == direction
    M = out.loc[sel, "moment_nm"].to_numpy(float)
    for side, f in (("left", left), ("right", right)):
        if f is not None:
            out.loc[sel, f"facet_{side}_contact_n"] = f(M)
    return out


def test_facets_fail_when_contact_falls_in_extension(baseline, nz, literature, limits):
    """Both facets load up to 5 N*m of extension, then unload while still in contact (still above their rest force
    at 10 N*m): the largest drop exceeds CONTACT_TOL_N and the extension row fails."""
    curves, comp, base = baseline

    def rise_then_fall(M):
        return REST_FACET_N + np.where(M <= 5.0, 8.0 * M, 40.0 - 5.0 * (M - 5.0))
    falling = _set_facets(curves, "extension", rise_then_fall, rise_then_fall)
    t = _table(falling, comp, limits, nz, literature)
    _assert_only_changed(base, t, FACET, ["extension"])
    r = _row(t, FACET, "extension")
    assert r["value"] > r["limit"]


def test_facets_fail_when_they_never_load_in_extension(baseline, nz, literature, limits):
    """Facets that keep their rest force through extension (never stop it) fail: no drop, but no loading either."""
    curves, comp, base = baseline

    def flat(M):
        return np.full_like(M, REST_FACET_N)
    t = _table(_set_facets(curves, "extension", flat, flat), comp, limits, nz, literature)
    _assert_only_changed(base, t, FACET, ["extension"])
    assert _row(t, FACET, "extension")["value"] <= ADM.CONTACT_TOL_N    # it is the missing load that fails


def test_facets_tolerate_a_small_drop(baseline, nz, literature, limits):
    """A dip smaller than CONTACT_TOL_N (contact-point switching) in loading facets passes: each facet drops by a
    quarter of the tolerance at 5 N*m, both together (what extension judges) by half of it."""
    curves, comp, _ = baseline

    def dip(M):
        return REST_FACET_N + 8.0 * M - np.where(np.isclose(M, 5.0), 0.25 * ADM.CONTACT_TOL_N + 8.0 * 0.25, 0.0)
    t = _table(_set_facets(curves, "extension", dip, dip), comp, limits, nz, literature)
    r = _row(t, FACET, "extension")
    assert r["passed"] and r["value"] == pytest.approx(0.5 * ADM.CONTACT_TOL_N)


def test_facets_in_axial_rotation_judge_the_contralateral_joint(baseline, nz, literature, limits):
    """In axial rotation to the left the right (contralateral) facet is the one that must load. Mirroring the facets
    (the left one loading, the right one opening) fails that direction only; the baseline, where the ipsilateral
    facet opens and the two together unload, passes."""
    curves, comp, base = baseline

    def loads(M):
        return REST_FACET_N + 8.0 * M

    def opens(M):
        return REST_FACET_N * np.maximum(0.0, 1.0 - M)
    mirrored = _set_facets(curves, "axial_rotation_left", left=loads, right=opens)
    t = _table(mirrored, comp, limits, nz, literature)
    _assert_only_changed(base, t, FACET, ["axial_rotation_left"])


# ------------------------------------------------------------------ 5. the facet share of axial compression
COMP = "facet share of a pure axial (follower) load"


def test_compression_fails_when_the_facets_carry_the_axial_load(baseline, nz, literature, limits):
    """Facets carrying 40 % of a 1000 N follower load (the disc 60 %: more than the 16 % of erect standing, towards
    the 70 % of a narrow degenerate disc) fail; the baseline's 10 % (disc 90 %) passes, so a criterion reading the
    disc's share would fail the baseline."""
    curves, _, base = baseline
    t = _table(curves, _compression(0.40), limits, nz, literature)
    _assert_only_changed(base, t, COMP, ["compression"])
    r = _row(t, COMP, "compression")
    assert r["value"] == pytest.approx(0.40) and r["value"] > r["limit"]


def test_compression_is_judged_at_the_largest_force(baseline, nz, literature, limits):
    """The facet share at the largest force counts, whatever the row order: the same curve listed from 1000 N down
    to 0 N (its last row a 0 N state with no facet share) still fails."""
    curves, _, base = baseline
    reversed_rows = _compression(0.40).iloc[::-1].reset_index(drop=True)
    t = _table(curves, reversed_rows, limits, nz, literature)
    _assert_only_changed(base, t, COMP, ["compression"])


def test_compression_fails_when_the_largest_force_did_not_converge(baseline, nz, literature, limits):
    """A small facet share is no pass when the solve at the largest force did not converge."""
    curves, _, base = baseline
    t = _table(curves, _compression(0.10, converged=False), limits, nz, literature)
    _assert_only_changed(base, t, COMP, ["compression"])


def test_facets_fail_when_they_open_within_one_step(baseline, nz, literature, limits):
    """Both facets lose all contact within one 0.25 N*m step of extension and re-engage after it: a drop from
    contact to none is a drop (counting only the steps that end in contact missed it)."""
    curves, comp, base = baseline

    def open_once(M):
        F = REST_FACET_N + 8.0 * M
        return np.where(np.isclose(M, 5.25), 0.0, F)
    opening = _set_facets(curves, "extension", open_once, open_once)
    t = _table(opening, comp, limits, nz, literature)
    _assert_only_changed(base, t, FACET, ["extension"])
    assert _row(t, FACET, "extension")["value"] > 40.0


def test_neutral_zone_is_judged_on_a_grid_without_one_newton_metre(baseline, nz, literature, limits):
    """The rotation at 1 N*m is read on each curve (interpolated): moving the grid off 1.0 keeps every plane's row,
    with nearly the same value, instead of dropping the rows (and with them the criterion)."""
    curves, comp, base = baseline
    shifted = curves.copy()
    shifted["moment_nm"] = shifted["moment_nm"] + np.where(np.isclose(shifted["moment_nm"], 1.0), 1e-6, 0.0)
    t = _table(shifted, comp, limits, nz, literature)
    r0, r1 = _rows(base, "neutral-zone"), _rows(t, "neutral-zone")
    assert len(r1) == len(r0) == len(ADM.NZ_PLANES)
    np.testing.assert_allclose(r1["value"].to_numpy(float), r0["value"].to_numpy(float), rtol=1e-3)
