"""The calibration's prior: the ligament laws on elongation it starts from (paper 1 Table 3 and the Rupp et al. 2015
laws of its Appendix 1, or the Remus et al. 2021 laws of the same fibres) with their spreads, and the prior set as the
calibration recorded it (role calibration.prior of the stage manifests)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from ...inputs.characteristics import SoftplusLaw, load_characteristic_set, load_shape_check
from .disc import c_zero, softplus_zero_law

#: the law each calibrated ligament starts from (its prior), on elongation in percent of the paper's own fibre:
#: paper 1 Table 3, except the FL (Table 3's law is concave: its force falls with stretch, which the paper attributes
#: to the vertebral-arch artefact, Sect. 4.2) and the ITL (no Table 3 row: the paper's model has an ITL with a
#: "non-validated characteristic", Sects. 2.2.4 and 4.3): for both the prior is the paper's elongation-based
#: characteristic, the Rupp et al. 2015 law of Appendix 1, refitted with Eq. 7
PRIOR_SOURCE = {"ALL": ("calibrated", "Table 3"), "PLL": ("calibrated", "Table 3"), "CL": ("calibrated", "Table 3"),
                "ISL": ("calibrated", "Table 3"), "SSL": ("calibrated", "Table 3"),
                "FL": ("rupp2015", "Appendix 1 Rupp et al. 2015 law, refitted with Eq. 7 (F(0) = 0)"),
                "ITL": ("rupp2015", "Appendix 1 Rupp et al. 2015 law, refitted with Eq. 7 (F(0) = 0)")}
ELONGATION_LIGAMENTS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")


def paper_fibre_slack_length(kind, prestrain_pct, data_dir=None) -> float:
    """The paper model's slack length [m] of a ligament kind at the paper's prestrain: the mean in-situ length of its
    strands, l_set = l_lig,0 * (1 + eps_Rupp) (Appendix 1, calculated shape parameters and Rupp inputs), divided
    by (1 + prestrain). The length on which the paper's percent strains are defined (derived_from_published_fit)."""
    sc = load_shape_check(data_dir)
    rupp = load_characteristic_set("rupp2015", data_dir=data_dir).ligaments
    sel = sc[sc["ligament"] == kind]
    if sel.empty or kind not in rupp:
        raise ValueError(f"no Appendix 1 fibre lengths for ligament {kind!r} (rupp2015_shape_check.csv)")
    l_set = float(sel["l0"].mean()) * (1.0 + rupp[kind].prestrain)
    return l_set / (1.0 + prestrain_pct / 100.0)


def rupp_as_softplus(law, law_length_m, max_elongation_m=5e-3, n=201):
    """Eq. 7 (a, b, c, d) with F(0) = 0, d > 0, least-squares fitted on elongation 0..``max_elongation_m`` in percent of
    ``law_length_m`` to a Rupp et al. (2015) law of the whole ligament (toe F_A (dl/l_A)^nu, linear beyond)."""
    from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
    e = np.linspace(0.0, max_elongation_m, n)
    K = (law.f_b_n - law.f_a_n) / (law.l_b_m - law.l_a_m)
    nu = law.l_a_m * K / law.f_a_n
    F = np.where(e < law.l_a_m, law.f_a_n * (np.clip(e, 0, None) / law.l_a_m) ** nu, law.f_a_n + K * (e - law.l_a_m))
    eps = 100.0 * e / law_length_m
    sol = least_squares(lambda q: softplus_zero_law(eps, q[0], q[1], q[2]) - F, [50.0, -10.0, 3.0],
                        bounds=([0.01, -60.0, 0.05], [5000.0, 40.0, 50.0]), xtol=1e-12, ftol=1e-12)
    a, b, d = (float(v) for v in sol.x)
    return a, b, c_zero(a, b, d), d, float(np.abs(sol.fun).max())


def elongation_prior(published=None, data_dir=None):
    """The calibration's prior: every ligament kind of :data:`ELONGATION_LIGAMENTS` with the law of
    :data:`PRIOR_SOURCE` defined on elongation (``SoftplusLaw.law_length_m`` = the paper's fibre slack length,
    :func:`paper_fibre_slack_length`) at the paper's prestrain (Sect. 2.2.4). Returns (CharacteristicSet named
    "calibrated", provenance table: ligament, a, b, c, d, prestrain_pct, law_length_mm, source, note)."""
    pub = published if published is not None else load_characteristic_set("calibrated", data_dir=data_dir)
    ligs, rows = {}, []
    for kind in ELONGATION_LIGAMENTS:
        set_name, what = PRIOR_SOURCE[kind]
        pre = pub.ligaments[kind].prestrain_pct if kind in pub.ligaments else \
            load_characteristic_set("shirazi_adl1986", data_dir=data_dir).ligaments[kind].prestrain_pct
        L = paper_fibre_slack_length(kind, pre, data_dir)
        note = ""
        if set_name == "calibrated":
            src = pub.ligaments[kind]
            a, b, c, d = src.a, src.b, src.c, src.d
        elif set_name == "rupp2015":
            a, b, c, d, err = rupp_as_softplus(load_characteristic_set("rupp2015", data_dir=data_dir).ligaments[kind], L)
            note = f"Eq. 7 fit to the Rupp law over 0-5 mm elongation, largest deviation {err:.2g} N"
        else:
            src = load_characteristic_set(set_name, data_dir=data_dir).ligaments[kind]
            a, b, c, d = src.a, src.b, src.c, src.d
        ligs[kind] = SoftplusLaw(a, b, c, d, pre, source=f"prior: paper 1 {what} on elongation", law_length_m=L)
        rows.append({"ligament": kind, "a_n": a, "b_pct": b, "c_n": c, "d_pct": d, "prestrain_pct": pre,
                     "law_length_mm": L * 1e3, "pre_elongation_mm": pre / 100.0 * L * 1e3,
                     "source": f"paper 1 {what}", "note": note})
    cs = dataclasses.replace(pub, name="calibrated", ligaments=ligs, absent={}, alternatives={},
                             source="elongation prior (lumbar.experiments.calibration.elongation_prior)")
    return cs, pd.DataFrame(rows)


def calibration_prior(published=None, geometry=None, level="L4-L5", geometry_path=None, prior="remus2021",
                      data_dir=None):
    """The admissible fit's prior: (prior characteristic set on elongation, provenance table, {fit parameter: prior
    spread in fit units}).

    ``prior``: "remus2021" (default): every ligament law is the Remus et al. (2021) law of the same fibres
    (:func:`lumbar.experiments.priors.remus_prior`; needs the Visible Human folder ``geometry_path`` with its
    ``*_UWMat.lig`` files); "table3": paper 1 Table 3 on elongation (:func:`elongation_prior`). The ligament spreads
    are how much the two sources disagree on this level's fibres, per kind (:func:`priors.ligament_spreads`); without
    the Remus files (another geometry) the prior is Table 3 with the default spreads, and the provenance says so."""
    from ...geometry.visible_human import read_uw_materials  # noqa: PLC0415 - only with a Visible Human folder
    from .. import priors as PR  # noqa: PLC0415 - calibration-only helper module

    if prior not in PR.PRIORS:
        raise ValueError(f"ligament prior {prior!r}; expected one of {PR.PRIORS}")
    table3, prov = elongation_prior(published, data_dir)
    if geometry_path is None or geometry is None or level not in getattr(geometry, "levels", {}):
        prov = prov.assign(spread_source="default spreads (no Remus et al. 2021 laws for this geometry)")
        return table3, prov, {}
    remus, rprov = PR.remus_prior(table3, geometry.levels[level], read_uw_materials(geometry_path, level),
                                  ELONGATION_LIGAMENTS)
    spreads = PR.ligament_spreads(PR.source_disagreement(remus.ligaments, table3.ligaments))
    chosen, cprov = (remus, rprov) if prior == "remus2021" else (table3, prov)
    cprov = cprov.assign(scale_spread_log10=[spreads.get(f"{k}:scale") for k in cprov["ligament"]],
                         pre_elongation_spread_mm=[spreads.get(f"{k}:pre_elongation") for k in cprov["ligament"]],
                         prior=prior)
    return chosen, cprov, spreads


def read_prior_set(path, published):
    """The prior characteristic set the calibration used, rebuilt from its provenance table
    (role calibration.prior: ligament, a_n, b_pct, c_n, d_pct, prestrain_pct, law_length_mm) on
    ``published`` (disc and facet): the one record of the prior, read by the admissibility and the other levels (the
    force-scale criterion is relative to it)."""
    df = pd.read_csv(path)
    need = {"ligament", "a_n", "b_pct", "c_n", "d_pct", "prestrain_pct", "law_length_mm"}
    if not need <= set(df.columns):
        raise ValueError(f"{path}: the prior table needs the columns {sorted(need)}; has {sorted(df.columns)}")
    ligs = dict(published.ligaments)
    for r in df.itertuples():
        ligs[r.ligament] = SoftplusLaw(float(r.a_n), float(r.b_pct), float(r.c_n), float(r.d_pct),
                                       float(r.prestrain_pct), source=f"prior ({path})",
                                       law_length_m=float(r.law_length_mm) * 1e-3)
    return dataclasses.replace(published, name="calibrated", ligaments=ligs, absent={}, alternatives={},
                               source=f"calibration prior ({path})")
