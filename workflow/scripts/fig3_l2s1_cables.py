"""L2-S1 IDP stage, rule fig3_l2s1_cables: Fig. 3 analog, the L2-S1 spine with its wire cables
(lumbar.plots.render_spine).

By hand: python workflow/scripts/fig3_l2s1_cables.py fig3_l2s1_cables --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.plots.render_spine import render_spine  # noqa: E402


def main(snakemake, log):
    g = snakemake.params.geometry
    geo = load_configured(g, levels=list(l2s1.LEVELS))
    cab = l2s1.build_l2s1(geo, load_characteristic_set("rupp2015"), l2s1.derive_cables(snakemake.input.cables)).cables
    used = render_spine(geo, l2s1.LEVELS, snakemake.output[0], cables=cab, backend=snakemake.params.render["backend"])
    log.info("rendered %s with %s", snakemake.output[0], used)
    log.info("done: %s", ", ".join(map(str, snakemake.output)))

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
