"""Paper 2 reproduced claim by claim (rule paper2_reproduction): every stated result of its Results, Discussion and
abstract (data/paper2/paper2_claims_original_text.csv, with its quote) against the reproduction model and, where it is
run, the calibrated passive chain: results/tables/paper2_reproduction.csv (claim, paper, ours, reached, certified,
verdict, reason) and the verdict counts per variant and claim class (lumbar.muscles.reproduction).

By hand: python workflow/scripts/paper2_reproduction.py paper2_reproduction --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import reproduction as rp  # noqa: E402


def main(snakemake, log):
    i = snakemake.input
    claims = rp.read_claims(i.claims)
    variants = {"reproduction": rp.results_from_files(i.validation, i.metrics, i.segment_loads, i.flexion_relaxation,
                                                      i.sensitivity)}
    adm = [rp.chain_admissibility("reproduction", pd.read_csv(i.facet_contact), pd.read_csv(i.rotations))]
    cal = _common.as_list(i.calibrated)
    if cal:
        val, met, seg, fr, fc, rot = cal
        variants["calibrated_chain"] = rp.results_from_files(val, met, seg, fr)
        adm.append(rp.chain_admissibility("calibrated_chain", pd.read_csv(fc), pd.read_csv(rot)))
    table = rp.claims_table(claims, variants)
    counts = rp.counts(table)
    adm = pd.concat(adm, ignore_index=True)
    write_table_atomic(table, snakemake.output.reproduction)
    write_table_atomic(counts, snakemake.output.reproduction_counts)
    write_table_atomic(adm, snakemake.output.chain_admissibility)
    for v, d in adm.groupby("variant", sort=False):
        bad = d[~d["admissible"]]
        log.info("passive chain on the muscle model's geometry, %s: %d of %d levels admissible%s", v,
                 len(d) - len(bad), len(d), "" if bad.empty else
                 f" (facet overlap at rest: {list(bad.loc[bad['facet_overlap_at_rest'], 'level'])}; not flexing in "
                 f"36 deg flexion: {list(bad.loc[~bad['flexes_in_flexion'], 'level'])})")
    for _, r in counts[counts["claim_class"] == "all"].iterrows():
        log.info("paper 2 claims, %s: %d reproduced, %d direction only, %d not reproduced of %d comparable "
                 "(%d not comparable)", r["variant"], r["reproduced"], r["direction only"], r["not reproduced"],
                 r["comparable"], r["not comparable"])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
