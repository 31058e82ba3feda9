"""The admissibility criteria as the admissible fit's one-sided penalties (zero inside a margin within each criterion's
limit), computed from the probe's metrics (:meth:`lumbar.experiments.calibration.probe.Probe.metrics`)."""
from __future__ import annotations

import math

from .. import admissibility as ADM
from .probe import PROBE_DIRECTIONS, PROBE_MOMENTS

#: the compliance of the probe's [2, 3] N*m window is the reference of the "no compliance rise" penalty (the
#: criterion takes the tangent at 2.5 N*m); later windows may not exceed it by more than FIT_MARGIN["compliance_rise"]
COMPLIANCE_REFERENCE_WINDOW = (2.0, 3.0)
#: margins of the fit's penalties inside the admissibility limits (so that the 0.25 N*m check passes with room)
FIT_MARGIN = {"rest_facet_n": 15.0, "pretension_fraction": 0.9, "nz_fraction": 0.8, "compression_share": 0.2,
              "functional_n": 2.0, "isl_ssl_share": 0.12, "compliance_rise": 0.05, "first_step_deg": 0.4,
              "rom_rel": 0.2, "disc_compression_mm": 0.01, "remus_factor": 1.25,
              "scale_factor": 1.1}


def fit_penalties(mt, limit, nz):
    """(name, value) of every one-sided penalty term of :func:`.admissible.fit_admissible` (0 inside its margin)."""
    p = []
    for side, f in zip(("left", "right"), mt["rest_facet"]):
        p.append((f"unloaded facet {side}", max(0.0, f - FIT_MARGIN["rest_facet_n"]) / 5.0))
    for k, lim in limit.items():
        v = mt["rest_tension"].get(k, 0.0)
        p.append((f"unloaded {k} tension", max(0.0, v - FIT_MARGIN["pretension_fraction"] * lim -
                                               0.5 * ADM.REST_TENSION_TOL_N) / max(0.25, 0.2 * lim)))
    for plane, (dp, dn) in ADM.NZ_PLANES.items():
        if plane in nz:
            ref = nz[plane][0]
            v = mt["rot"][(dp, 1.0)] + mt["rot"][(dn, 1.0)]
            p.append((f"neutral zone {plane}", max(0.0, FIT_MARGIN["nz_fraction"] * ref - v) / (0.25 * ref)))
    for k in ADM.FUNCTIONAL_KINDS:
        if k in mt["flex_tension"]:
            p.append((f"{k} in tension in flexion", max(0.0, FIT_MARGIN["functional_n"] - mt["flex_tension"][k])))
    fm_ = mt["flex_moment"]
    share = (fm_.get("ISL", 0.0) + fm_.get("SSL", 0.0)) / PROBE_MOMENTS[-1]
    p.append(("ISL+SSL share", max(0.0, FIT_MARGIN["isl_ssl_share"] - share) / 0.02))
    if "ISL" in mt["flex_tension"] and "SSL" in mt["flex_tension"]:
        p.append(("ISL above SSL", max(0.0, mt["flex_tension"]["SSL"] - 0.9 * mt["flex_tension"]["ISL"]) / 5.0))
    if "CL" in fm_ and "FL" in fm_:
        p.append(("CL above FL", max(0.0, fm_["FL"] - 0.9 * fm_["CL"]) / 0.2))
    Ms = (0.0,) + PROBE_MOMENTS
    for d in PROBE_DIRECTIONS:
        th = [0.0] + [mt["rot"][(d, M)] for M in PROBE_MOMENTS]
        p.append((f"first step {d}", max(0.0, th[1] - FIT_MARGIN["first_step_deg"]) / 0.05))
        c = [(th[i + 1] - th[i]) / (Ms[i + 1] - Ms[i]) for i in range(len(th) - 1)]
        i0 = Ms.index(COMPLIANCE_REFERENCE_WINDOW[0])
        ref = max(c[i0], 1e-6)
        p.append((f"compliance {d}", max(0.0, max(c[i0 + 1:]) / ref - 1.0 - FIT_MARGIN["compliance_rise"]) / 0.05))
    p.append(("compression facet share", max(0.0, mt["compression_facet_share"] - FIT_MARGIN["compression_share"]) / 0.05))
    # the paper's disc transmits no traction: where a pure moment lifts the upper vertebra off it, the unit's stiffness
    # drops (a compliance rise; measured in extension, where the facets' contact pushes the vertebra up): keep the
    # disc compressed by the ligaments' pre-tension at every probe moment
    p.append(("disc stays compressed", max(0.0, FIT_MARGIN["disc_compression_mm"] - mt["min_disc_compression_mm"]) /
              FIT_MARGIN["disc_compression_mm"]))
    return p


def scale_penalties(names, q, mt):
    """(name, value) of the force-scale criterion inside :func:`.admissible.fit_admissible`: a ligament's force scale outside
    [``ADM.SCALE_MIN``, ``ADM.SCALE_MAX``] x its source law must keep its tension within ``ADM.REMUS_FACTOR`` (less a
    margin) of the Remus et al. (2021) law of the same fibres where that law loads it most (metrics ``remus``), when
    it carries more than 1 N there (the criterion's own exception); elsewhere the scale itself is pulled back inside. Zero
    inside the range narrowed by ``FIT_MARGIN["scale_factor"]`` (a fit that trades the pull against the data ends
    inside the criterion's limit, not on it); continuous in the fit vector (the pull fades in over 0.05 decade)."""
    p = []
    remus = mt.get("remus") or {}
    margin = math.log10(FIT_MARGIN["scale_factor"])
    lo, hi = math.log10(ADM.SCALE_MIN) + margin, math.log10(ADM.SCALE_MAX) - margin
    allowed = math.log(ADM.REMUS_FACTOR / FIT_MARGIN["remus_factor"])
    for j, n in enumerate(names):
        if not n.endswith(":scale"):
            continue
        k = n.split(":")[0]
        out = max(0.0, lo - q[j]) + max(0.0, q[j] - hi)
        if out == 0.0:
            p.append((f"force scale {k}", 0.0))
            continue
        t_model, t_remus = remus.get(k, (0.0, 0.0))
        if t_remus > 1.0:
            log_ratio = math.log(max(t_model, 1e-9) / t_remus)
            miss = max(0.0, -allowed - log_ratio) if q[j] < lo else max(0.0, log_ratio - allowed)
            p.append((f"force scale {k}", min(1.0, out / 0.05) * miss / 0.1))
        else:
            p.append((f"force scale {k}", out / 0.05))
    return p
