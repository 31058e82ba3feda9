"""The report's builder and its registry of sections: :class:`ReportBuilder` reads the result files and the
configuration and writes the document (:mod:`lumbar.report.document`): the first page (title, abstract, validation
scoreboard figure), then every registered section (:data:`SECTIONS`, :func:`report_section`). The sections live in
modules of their own, which register themselves: :mod:`.front_sections` (validation, flags, summary, methods),
:mod:`.paper_sections` (models, calibration, forward simulation, IDP, muscles), :mod:`.load_sharing_section`,
:mod:`.posterior`, :mod:`.discrepancy_section`, :mod:`.appendix_sections` (further figures, provenance, appendix).

A section finds a result file by its role in the stage manifests (:mod:`lumbar.inputs.manifests`):
``b.out("stepwise_reduction", "counts")`` is that file under the run's results root (config ``run.name``).
Every number comes from a result or data file; nothing is typed in."""
from __future__ import annotations

import json
import logging
import math
import os
import re
from pathlib import Path
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
import pandas as pd

from lumbar import __version__
from lumbar.inputs import manifests

from lumbar.experiments import validation as V

from .document import Contents, Doc, Figure, Heading, Para, Table, plain

log = logging.getLogger(__name__)

NOT_BUILT = "not built in this configuration"
TITLE = "Lumbar spine multibody model: stepwise-reduction ligament characteristics, L2-S1 intradiscal pressure, " \
        "paraspinal muscles and model-experiment discrepancies"
PAPERS = (
    "Lumbar spinal ligament characteristics extracted from stepwise reduction experiments allow for preciser "
    "modeling than literature data (paper 1)",
    "Biomechanical properties of paraspinal muscles influence spinal loading - a musculoskeletal simulation study "
    "(paper 2)",
)
SET_LABELS = {"calibrated": "calibrated (this model)", "chazal1985": "Chazal et al. (1985)",
              "shirazi_adl1986": "Shirazi-Adl et al. (1986)", "white_panjabi1990": "White and Panjabi (1990)",
              "nolte1990": "Nolte et al. (1990)", "rupp2015": "Rupp et al. (2015)"}
DIRECTION_ABBR = {"flexion": "F", "extension": "E", "lateral_bending": "L", "axial_rotation": "A"}
#: the sources of a simulated value that are this workflow's own models (the first page names only the others)
OWN_SETS = ("calibrated", "muscle model", "geometry")
MAX_ROWS = 60          # generic CSV tables: at most this many rows are drawn, the rest is referenced
MAX_WARNINGS = 40      # the Flags section lists at most this many warnings (all are in logs/)



# ----------------------------------------------------------------------------------------------- small helpers
def norm_path(p) -> str:
    return Path(os.path.normpath(str(p))).as_posix()


def fmt(v, digits: int = 3) -> str:
    """A value as a short string: floats to ``digits`` significant digits (a value of ``digits`` or more integer
    digits keeps them: 1706.7 -> "1707", not "1.71e+03"), NaN/None as empty."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int,)) and not isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        if v == int(v) and abs(v) < 1e6:
            return str(int(v))
        if 10 ** digits <= abs(v) < 1e6:
            return str(int(round(v)))
        return f"{v:.{digits}g}"
    if isinstance(v, np.bool_):
        return "yes" if bool(v) else "no"
    if isinstance(v, np.integer):
        return str(int(v))
    if isinstance(v, np.floating):
        return fmt(float(v), digits)
    if isinstance(v, Mapping):
        return ", ".join(f"{k}={fmt(x, digits)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        items = [fmt(x, digits) for x in v[:8]]
        return "[" + ", ".join(items) + (f", ... ({len(v)} items)" if len(v) > 8 else "") + "]"
    return str(v)


#: unit suffixes of the project's column names (README "Frame and units"), longest first
_UNIT_SUFFIXES = (
    ("_n_per_cm2", "N/cm\u00b2"), ("_nm_per_rad", "N\u00b7m/rad"), ("_nm_per_deg", "N\u00b7m/deg"),
    ("_n_per_mm", "N/mm"), ("_n_per_m", "N/m"), ("_mm2", "mm\u00b2"), ("_cm2", "cm\u00b2"), ("_m2", "m\u00b2"),
    ("_rad3", "rad\u00b3"), ("_mpa", "MPa"), ("_kpa", "kPa"), ("_deg", "deg"), ("_rad", "rad"),
    ("_nm", "N\u00b7m"), ("_mm", "mm"), ("_um", "\u00b5m"), ("_kg", "kg"), ("_pct", "%"), ("_n", "N"),
    ("_m", "m"), ("_s", "s"))
#: words of column names and identifiers as a reader writes them
_WORDS = {"sim": "simulated", "idp": "IDP", "rom": "ROM", "rms": "RMS", "csa": "CSA", "kkt": "KKT",
          "ipopt": "IPOPT", "sqp": "SQP", "pce": "PCE", "loo": "LOO", "lo": "low", "hi": "high", "n": "n",
          "nlp": "NLP", "ssl": "SSL", "isl": "ISL", "all": "ALL", "pll": "PLL", "fl": "FL", "cl": "CL",
          "va": "VA", "com": "COM", "sd": "SD", "ci": "CI", "std": "SD", "num": "number", "max": "max",
          "min": "min", "csv": "CSV", "json": "JSON", "q2": "Q2", "r2": "R2", "rmse": "RMSE", "mpa": "MPa",
          "vs": "vs", "id": "id"}


def human_header(col: str) -> str:
    """A column name of a result table as a table header: words instead of identifiers, the unit in brackets
    (``disc_moment_sagittal_nm`` -> "disc moment sagittal [N·m]", ``p3_nm_per_rad`` -> "p3 [N·m/rad]",
    ``n_outliers`` -> "n outliers"). A name with no unit suffix keeps its words."""
    c = str(col)
    unit = ""
    low = c.lower()
    for suf, u in _UNIT_SUFFIXES:
        if low.endswith(suf) and len(low) > len(suf):
            c, unit = c[: -len(suf)], u
            break
    words = [w for w in re.split(r"[_\s]+", c) if w]
    words = [_WORDS.get(w, w) if w.islower() or w.isdigit() else w for w in words]
    text = " ".join(words).replace("wo ", "w/o ") if words[:1] == ["wo"] else " ".join(words)
    return f"{text} [{unit}]" if unit else text


_IDENT = re.compile(r"^[a-z][a-z0-9]*(?:_[a-z0-9]+)+$")


def human_value(v: str) -> str:
    """An identifier-like cell (``lateral_bending``, ``wo_all``, ``crate_far``) as words; anything else as is
    (file paths, sentences, numbers)."""
    s = str(v)
    if not _IDENT.match(s):
        return s
    return re.sub(r"\bwo ([a-z]+)", lambda m: "w/o " + m.group(1).upper(), s.replace("_", " "))


#: the claim classes of paper 2 as the report names them (lumbar.muscles.reproduction counts them apart)
CLAIM_CLASSES = {"validation": "validation", "table1": "Table 1 loads", "flexion_relaxation": "flexion-relaxation",
                 "sensitivity_headline": "headline sensitivity changes",
                 "sensitivity_bound": "effects the paper calls small or negligible",
                 "sensitivity_direction": "sensitivity directions", "reachability": "postures not reached",
                 "rotations": "intervertebral rotations"}
VARIANT_NAMES = {"reproduction": "reproduction model (paper 2's springs)",
                 "calibrated_chain": "calibrated passive chain"}
SHORT_VARIANT_NAMES = {"reproduction": "its model", "calibrated_chain": "on the calibrated chain"}


def paper2_claims_sentence(b, short=False):
    """Paper 2's stated results claim by claim (the counts table of rule paper2_reproduction): the reproduced share
    of the comparable claims per variant, the headline changes and flexion-relaxation apart from the effects the
    paper calls negligible; None when the table is not among the inputs."""
    rel = b.out("muscle_model", "reproduction_counts")
    if not b.has(rel):
        return None
    c = read_csv(b.path(rel))
    b.shown.add(norm_path(rel))

    def part(v, cls):
        r = c[(c["variant"] == v) & (c["claim_class"] == cls)]
        if r.empty:
            return None
        r = r.iloc[0]
        return int(r["reproduced"]), int(r["comparable"])

    out = []
    for v in sorted(dict.fromkeys(c["variant"]), key=lambda v: (v != "reproduction", v)):   # the paper's model first
        tot = part(v, "all")
        if tot is None:
            continue
        s = f"{(SHORT_VARIANT_NAMES if short else VARIANT_NAMES).get(v, v)} {tot[0]} of {tot[1]}"
        bits = []
        if short and v != "reproduction":
            out.append(s)
            continue
        for cls in (("sensitivity_headline", "flexion_relaxation") if short else
                    ("validation", "sensitivity_headline", "flexion_relaxation", "table1", "sensitivity_bound")):
            p = part(v, cls)
            if p is not None and p[1]:
                bits.append(f"{CLAIM_CLASSES[cls]} {p[0]} of {p[1]}")
        if bits:
            s += " (" + ", ".join(bits) + ")"
        out.append(s)
    lead = ("Paper 2 claim by claim, reproduced of comparable: " if short else
            "Paper 2 claim by claim, comparable claims reproduced (within x1.5 or the stated bound): ")
    return lead + "; ".join(out) + "."



def reference_text(section: dict, noise: str) -> str:
    """What a stage is compared with, from its config section: the measured table it names, or the SURROGATE
    of virtual specimens (count, generator set and ``noise``, e.g. "noise SD 0.5 deg")."""
    if section.get("measured_table"):
        return f"the measured table {section.get('measured_table')}"
    return (f"a SURROGATE of {fmt(section.get('n_specimens'))} virtual specimens of the "
            f"'{fmt(section.get('generator_set'))}' set ({noise})")


def flatten(d, prefix="") -> list[tuple[str, Any]]:
    out = []
    for k in d:
        v = d[k]
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping) and v:
            out += flatten(v, key)
        else:
            out.append((key, v))
    return out


def read_csv(path) -> pd.DataFrame:
    return pd.read_csv(path)


def mentions_surrogate(path) -> bool:
    try:
        return "surrogate" in Path(path).read_text(errors="ignore").lower()
    except OSError:
        return False


def _render_caption(text: str, config: Mapping) -> str:
    """An .rst caption of workflow/report as plain text: config placeholders filled, RST markup removed."""
    def sub(m):
        v = config
        for k in re.findall(r'\["([^"]+)"\]', m.group(1)):
            v = v.get(k, "") if isinstance(v, Mapping) else ""
        return fmt(v)
    text = re.sub(r"\{\{\s*snakemake\.config((?:\[\"[^\"]+\"\])+)\s*\}\}", sub, text)
    text = text.replace("``", "").replace("**", "")
    return " ".join(text.split())


# ----------------------------------------------------------------------------------------------- the builder
def null_models_sentence(t: pd.DataFrame) -> str:
    """The null-model table (role validation.null_models) in words, one clause per scoreboard quantity: the model's
    count beside every trivial model's on the same rows, and which of them it does not beat (the validation section;
    the first page: :func:`null_models_brief`)."""
    parts = []
    for q, g in t.groupby("quantity", sort=False):
        r0 = g.iloc[0]
        nulls = [f"{int(r.null_within)} ({r.description})" for r in g.itertuples(index=False)]
        s = (f"{V.condition_label(q)}, the model {int(r0.model_within)} of {int(r0.n_rows)} within against "
             + " and ".join(nulls))
        lost = ~g["model_beats_null"].astype(bool).to_numpy()
        if lost.all():
            s += ", which it does not beat" if len(g) == 1 else ", none of which it beats"
        elif lost.any():
            at = [str(int(v)) for v in g["null_within"][lost]]
            s += (", and does not beat the trivial model at " + at[0] if len(at) == 1 else
                  ", and does not beat the trivial models at " + " and ".join(at))
        parts.append(s)
    return ("Beside trivial models on the same rows: " + "; ".join(parts) + ".") if parts else ""


def above_one_sd(rows: pd.DataFrame) -> list:
    """The rows judged within mean +- 2 SD whose simulated value is above the mean + 1 SD (the SD read back from the
    row's high end), per quantity: inside the tolerance, but in the upper tail of the measured spread. One entry per
    quantity, its conditions (without their parenthesised detail, which the table keeps) with value and mean."""
    out = {}
    for r in rows.itertuples():
        if not str(r.tolerance_rule).startswith("mean +- 2 SD") or not r.within:
            continue
        sd = (float(r.measured_high) - float(r.measured)) / 2.0
        if sd > 0 and float(r.sim) > float(r.measured) + sd:
            cond = re.sub(r" \([^)]*\)", "", V.condition_label(r.condition)).replace(",", "")
            out.setdefault(r.quantity, []).append(f"{cond} {fmt(float(r.sim))} {r.unit} against {fmt(float(r.measured))}")
    return [f"{q}, {' and '.join(v)}" for q, v in out.items()]


def trivial_counts(t: pd.DataFrame | None, quantity: str) -> str:
    """The trivial models' counts on the model's rows of one scoreboard quantity, as the first page puts them beside
    the model's (" (trivial models: 9, 13)"); empty without such a model."""
    if t is None or t.empty:
        return ""
    g = t[t["quantity"] == quantity]
    if g.empty:
        return ""
    return f" (trivial model{'s' if len(g) > 1 else ''}: {', '.join(str(int(v)) for v in g['null_within'])})"


def null_models_brief(t: pd.DataFrame) -> str:
    """How many of the trivial models (role validation.null_models) the model beats on the same rows, as the first
    page says it after their counts (:func:`trivial_counts`)."""
    if t.empty:
        return ""
    beats = int(t["model_beats_null"].astype(bool).sum())
    return f"It beats {beats} of {len(t)} trivial models on the same rows."


class ReportBuilder:
    """Reads the result files and writes the report's sections into a :class:`~lumbar.report.document.Doc`
    (prose from the configuration and the files, figure and table numbering, what was not built)."""

    def __init__(self, inputs, config, html_path, captions_dir=None, published=None, logs_dir=None, logs_exclude=()):
        self.config = config
        #: the run's results root (config run.name, manifests.results_root): where :meth:`out` finds a role's file
        self.root = manifests.results_root(config)
        self.logs_dir = Path(logs_dir) if logs_dir else None
        self.logs_exclude = set(logs_exclude)      # sub-folders of logs_dir holding other runs' logs
        self.html_dir = Path(html_path).resolve().parent
        self.inputs = {}
        for p in inputs:
            self.inputs[norm_path(p)] = Path(p)
        self.captions_dir = Path(captions_dir) if captions_dir else None
        self.published = self._published(published)
        self.shown: set[str] = set()
        self.n_fig = 0
        self.n_tab = 0
        self.doc = Doc()
        sr = config.get("stepwise_reduction", {}) or {}
        l2 = config.get("l2s1", {}) or {}
        self.sr_surrogate = not sr.get("measured_table") or self.file_surrogate(self.out("stepwise_reduction",
                                                                                         "counts"))
        self.idp_surrogate = not l2.get("measured_table") or self.file_surrogate(self.out("l2s1", "counts"))

    # -- inputs
    def out(self, stage: str, role: str, **fill) -> str:
        """The file of an output role of a stage (:mod:`lumbar.inputs.manifests`) under the run's results root."""
        return manifests.path(stage, role, self.root, **fill)

    def outs(self, stage: str, role: str, **fill) -> list[str]:
        """Every file of a role declared as a list (``expand``), under the run's results root."""
        return manifests.paths(stage, role, self.root, **fill)

    def out_dir(self, stage: str, role: str) -> str:
        """The folder of a role's file(s), with a trailing ``/`` (to select the inputs inside it)."""
        return Path(self.outs(stage, role)[0]).parent.as_posix() + "/"

    def has(self, rel) -> bool:
        p = self.inputs.get(norm_path(rel))
        return p is not None and p.exists()

    def path(self, rel) -> Path:
        return self.inputs[norm_path(rel)]

    def file_surrogate(self, rel) -> bool:
        """Whether a result file compares with SURROGATE data: a table by its data-kind column (its header may name
        the word, e.g. the outlier counts' ``surrogate_comparison``), any other file by its text."""
        if not self.has(rel):
            return False
        path = self.path(rel)
        if path.suffix == ".csv":
            df = read_csv(path)
            for col in ("data_kinds", "data_kind", "kind"):
                if col in df.columns:
                    return bool(df[col].astype(str).str.contains("surrogate", case=False).any())
        return mentions_surrogate(path)

    def _published(self, published):
        if not published or not Path(published).is_file():
            return {}
        try:
            df = pd.read_csv(published)
            return {r["quantity"]: r for _, r in df.iterrows()}
        except Exception as e:  # noqa: BLE001 - an unreadable optional file only loses the paper's column
            log.warning("published results %s unreadable: %s", published, e)
            return {}

    def rel_to_html(self, rel) -> str:
        return Path(os.path.relpath(self.path(rel).resolve(), self.html_dir)).as_posix()

    def caption(self, rel, default: str, surrogate: bool = False) -> str:
        text = default
        if self.captions_dir is not None:
            rst = self.captions_dir / (Path(rel).stem + ".rst")
            if rst.is_file():
                text = _render_caption(rst.read_text(), self.config)
        if surrogate:
            text = "SURROGATE reference data (virtual specimens, not measured). " + text
        return text

    # -- blocks
    def missing(self, what: str):
        self.doc.add(Para(f"{what}: {NOT_BUILT}.", "note"))

    def figure(self, rel, default_caption, surrogate=False, label=None):
        """A figure; ``label`` "Fig. N" for the analog of the paper's Fig. N, else numbered "Fig. S<n>"."""
        if not self.has(rel) or self.path(rel).stat().st_size == 0:
            self.missing(f"{label or 'Figure'} ({Path(rel).name})")
            return False
        if label is None:
            self.n_fig += 1
            label = f"Fig. S{self.n_fig}"
        self.shown.add(norm_path(rel))
        self.doc.add(Figure(rel, self.caption(rel, default_caption, surrogate), label))
        return True

    def table_block(self, title, header, rows, source=None, note="", surrogate=False, label=None, **kw):
        """A table; ``label`` "Table N" for the analog of the paper's Table N, else numbered "Table S<n>"."""
        if label is None:
            self.n_tab += 1
            label = f"Table S{self.n_tab}"
        if surrogate and "surrogate" not in title.lower():
            title += " [SURROGATE reference data]"
        if source:
            self.shown.add(norm_path(source))
        self.doc.add(Table(f"{label}. {title}", [str(h) for h in header], rows, source, note, **kw))

    def csv_table(self, rel, title, surrogate=None, columns=None, max_rows=MAX_ROWS, label=None):
        if not self.has(rel):
            self.missing(f"{label or 'Table'}, {title} ({Path(rel).name})")
            return None
        try:
            df = read_csv(self.path(rel))
        except (ValueError, pd.errors.ParserError) as e:   # shown as a note; the rest of the report is built
            self.doc.add(Para(f"{label or 'Table'}, {title} ({rel}): not readable as CSV ({e}).", "note"))
            return None
        if surrogate is None:
            surrogate = mentions_surrogate(self.path(rel))
        shown = df[columns] if columns else df
        note = self.caption(rel, "", surrogate=False)
        # a column with one value in every row is said once, in the note, not repeated in every row
        if len(shown) >= 3 and shown.shape[1] > 3:
            const = [c for c in shown.columns if shown[c].nunique(dropna=False) == 1]
            if const and len(const) < shown.shape[1] - 1:
                said = "; ".join(f"{human_header(c)} = {self.cell(c, shown[c].iloc[0]) or '(empty)'}"
                                 for c in const)
                note = (note + " " if note else "") + f"In every row: {said}."
                shown = shown.drop(columns=const)
        if shown.shape[1] > 12 and len(shown) <= 8:      # wide and short: one row per column
            header = ["column"] + [f"row {i + 1}" for i in range(len(shown))]
            rows = [[human_header(c)] + [self.cell(c, v) for v in shown[c]] for c in shown.columns]
            self.table_block(title, header, rows, source=rel, note=note, surrogate=surrogate, label=label)
            return df
        if len(shown) > max_rows:
            note = (note + " " if note else "") + f"First {max_rows} of {len(shown)} rows; full table: {rel}."
            shown = shown.head(max_rows)
        rows = [[self.cell(c, v) for c, v in zip(shown.columns, r)] for r in shown.itertuples(index=False)]
        self.table_block(title, [human_header(c) for c in shown.columns], rows, source=rel, note=note,
                         surrogate=surrogate, label=label)
        return df

    @staticmethod
    def cell(column: str, v) -> str:
        """One cell of a result table as the reader sees it: numbers rounded (:func:`fmt`), set names spelled
        out, identifiers as words."""
        if isinstance(v, str):
            return SET_LABELS.get(v, human_value(v)) if column == "set" else human_value(v)
        return fmt(v)

    # ------------------------------------------------------------------------------------------- sections
    def build(self) -> Doc:
        """The whole report: the first page (title, abstract, validation scoreboard figure), then every
        registered section in order (:data:`SECTIONS`; :func:`report_section` adds one)."""
        self.first_page()
        numbered = [sec for sec in SECTIONS if sec.numbered]
        self.doc.add(Contents([(self._section_title(sec, numbered), sec.anchor) for sec in SECTIONS]))
        for k, sec in enumerate(SECTIONS):
            # the PDF's page 2 starts with the first section (Tables R1 and R2 together on one page)
            self.doc.add(Heading(self._section_title(sec, numbered), 1, sec.anchor, new_page=k == 0))
            sec.build(self)
        return self.doc

    @staticmethod
    def _section_title(sec, numbered) -> str:
        return f"{numbered.index(sec) + 1} {sec.title}" if sec.numbered else sec.title

    # -- helpers for sections (also for sections registered from outside this module)
    def heading(self, text: str, level: int = 2, anchor: str | None = None):
        self.doc.add(Heading(text, level, anchor))

    def para(self, text: str, style: str = "p"):
        self.doc.add(Para(text, style))

    def cfg(self, *keys, default=None):
        v = self.config
        for k in keys:
            if not isinstance(v, Mapping) or k not in v:
                return default
            v = v[k]
        return v

    # -- first page: can I trust this model, and for what?
    def first_page(self):
        """Title, the abstract read from the result files (at most :data:`FIRST_PAGE_MAX_WORDS` words with the title,
        so that the validation scoreboard figure follows on the PDF's first page and on the browser's first screen),
        the scoreboard figure, then the internal loads' figure and, for a user's specimen, its landmark QA. The
        findings behind the numbers are in their sections, linked from here."""
        self.doc.add(Heading(TITLE, 0))
        for part in self.abstract_paragraphs():
            self.doc.add(Para(part, "abstract"))
        qa = self.specimen_block()
        self.figure(self.out("validation", "scoreboard"), "Validation scoreboard: every distinct comparison with data "
                    "this model did not generate.", label="Fig. R")
        self.figure(self.out("validation", "internal_loads"), "Internal loads of the calibrated unit against "
                    "measurements: judged, never fitted (left), and those the fit also holds as constraints (right).",
                    label="Fig. R2")
        if qa:
            qa()
        self.doc.add(Para(f"Generated by lumbar {__version__} from the result files of this configuration (geometry "
                          f"'{fmt(self.cfg('geometry', 'kind'))}', seed {fmt(self.cfg('seed'))}); every number "
                          "is read from a result file. Reproduces: " + "; ".join(PAPERS) + ".", "small"))

    def specimen_block(self):
        """For a user's specimen (geometry kind meshes | label_volume): which specimen this report is about, how its
        geometry was made and what its voxels cannot support; returns the function that adds the landmark QA figure
        of the calibrated unit (None for another geometry)."""
        g = self.cfg("geometry", default={}) or {}
        if g.get("kind") not in ("meshes", "label_volume"):
            return None
        level = self.cfg("fsu", "level")
        name = Path(str(g.get("path", ""))).name or str(g.get("path"))
        what = ("vertebra surfaces" if g["kind"] == "meshes" else "a CT label volume, meshed by the workflow")
        txt = (f"Specimen: {name} ({what}, {g.get('path')}"
               + (f"; {g.get('units')}, {g.get('axes')} axes" if g["kind"] == "meshes" else "; NIfTI world, mm")
               + "). Its project frame comes from the anatomy and its landmarks are placed automatically from the "
               "Visible Human atlas (docs/specimen.md); the calibrated unit is " + f"{level}.")
        levels = self.out("specimen", "levels")
        if self.has(levels):
            lv = read_csv(self.path(levels))
            self.shown.add(norm_path(levels))
            txt += f" Units built: {', '.join(map(str, lv['level']))}"
            if "disc_height_mm" in lv:
                txt += (f" (endplate disc heights {fmt(float(lv['disc_height_mm'].min()), 2)}-"
                        f"{fmt(float(lv['disc_height_mm'].max()), 2)} mm)")
            txt += "."
            if "facet_numbers" in lv:
                off = lv[~lv["facet_numbers"].astype(str).str.startswith("measured")]
                if len(off):
                    txt += (" Facet joints: " + str(off["facet_numbers"].iloc[0]) + " The facet landmarks of "
                            "these units are placed by the atlas, not measured on the surfaces; read their facet "
                            "loads with that in mind.")
        self.doc.add(Para(txt))
        # the QA figure follows the scoreboard figure (first_page): the scoreboard stays on the first page
        return lambda: self.figure(
            self.out("specimen", "qa", unit=level), f"Landmark QA of the specimen's calibrated unit {level}: both "
            "vertebrae with every automatically placed landmark, coloured by structure (check them before reading the "
            "unit's results; the table is editable, docs/specimen.md).", label="Fig. Q")

    def distinct(self):
        """The validation scoreboard's distinct comparisons (None when the table is not among the inputs)."""
        rel = self.out("validation", "scoreboard_table")
        if not self.has(rel):
            return None
        df = read_csv(self.path(rel))
        self.shown.add(norm_path(rel))
        return V.distinct_comparisons(df) if len(df) else df

    def abstract(self) -> str:
        """The first page's summary as one text (:meth:`abstract_paragraphs` joined)."""
        return plain(" ".join(self.abstract_paragraphs()))

    def abstract_paragraphs(self) -> list[str]:
        """The first page's summary in three paragraphs: what is compared and the independent checks (beside a
        trivial model); the internal loads of the calibrated unit, with a link to where they come from; the
        calibration targets, the muscle model, what is only a method check and how many warnings need attention.
        Links: ``[text](#anchor)`` to a section (the renderers draw them)."""
        paras = []
        d = self.distinct()
        geo = human_value(fmt(self.cfg("geometry", "kind")))
        out = []
        if d is None or not len(d):
            out.append(f"This report shows the results of the lumbar workflow ({geo} geometry); the comparison with "
                       f"real data is {NOT_BUILT}.")
            out.append("Independent checks: none in this configuration.")
            out.append("Calibration targets: none in this configuration.")
        else:
            counts = V.role_counts(d)
            out.append(f"{len(d)} distinct comparisons with measurements the models did not generate (Fig. R; "
                       "[Validation on real data](#validation)).")
            w, n = counts.get(V.INDEPENDENT, (0, 0))
            ind = d[d["role"] == V.INDEPENDENT]
            rel = self.out("validation", "null_models")
            nulls = read_csv(self.path(rel)) if self.has(rel) else None
            agree, miss = [], []
            for (q, sets), g in ind.groupby(["quantity", "sets"], sort=False):
                # the model's own comparisons (calibrated unit, muscle model, geometry) name no set; another set's
                # (the paper's Table 3 set as published) does; the model's own beside the trivial models' counts
                own = sets in OWN_SETS
                name = V.condition_label(q) + ("" if own else f" ({V.sets_label(sets)})")
                beside = trivial_counts(nulls, q) if own else ""
                if g["within"].all():
                    agree.append(name + beside)
                else:
                    miss.append(f"{name} {int(g['within'].sum())} of {len(g)}{beside}")
            text = f"Independent checks: {w} of {n} within"
            if agree:
                text += "; agrees: " + ", ".join(agree)
            if miss:
                text += "; misses: " + "; ".join(miss)
            out.append(text + ".")
            if nulls is not None:
                out.append(null_models_brief(nulls))
            w, n = counts.get(V.INTERNAL, (0, 0))
            paras.append(" ".join(x for x in out if x))
            out = []
            if n:
                g = d[d["role"] == V.INTERNAL]
                miss = [f"{V.condition_label(r.condition)}" for r in g.itertuples() if not r.within]
                high = above_one_sd(g)
                wc, nc = counts.get(V.CONSTRAINT, (0, 0))
                out.append(f"Internal loads (judged, never fitted): {w} of {n} within"
                           + (f" (outside: {', '.join(miss)})" if miss else "")
                           + (f" (above the mean + 1 SD: {'; '.join(high)})" if high else "")
                           + (f"; held as fit constraints: {wc} of {nc}" if nc else "")
                           + " (Tables R3, R4; where they come from: [What the data told us](#posterior)).")
            if out:
                paras.append(" ".join(out))
                out = []
            w, n = counts.get(V.TARGET, (0, 0))
            out.append(f"Calibration targets (a fit quality, not a validation): {w} of {n} met." if n else
                       "Calibration targets: none in this configuration.")
        out.append(self._muscle_abstract())
        sur = [name for name, flag in (("4", self.sr_surrogate), ("5", self.idp_surrogate)) if flag]
        warn = self.warnings()
        tail = (f"{len(warn)} warning(s) need the user's attention ([Flags](#flags))." if warn is not None
                else "The workflow logs were not given to the report.")
        if sur:
            tables = "Tables 4 and 5 count" if len(sur) == 2 else f"Table {sur[0]} counts"
            out.append(f"{tables} outliers against SURROGATE data (this model's virtual specimens): a method check, "
                       f"not the paper's reproduction. {tail}")
        else:
            out.append(f"Tables 4 and 5 compare with the configured measured tables. {tail}")
        return [p for p in paras + [" ".join(out)] if p]

    def facet_edge_sentence(self) -> str:
        """Where the calibrated unit's extension facet force sits (inside the fitted articular surface or beyond it,
        where Eq. 4 is extrapolated), in words, from the MAP values of the load-sharing band table; empty without it."""
        rel = self.out("load_sharing", "bands")
        if not self.has(rel):
            return ""
        b = read_csv(self.path(rel))
        b = b[(b["direction"] == "extension") & np.isclose(b["moment_nm"], 7.5)].set_index("quantity")["map"]
        if "facet_left_beyond_surface_n" not in b.index:
            return ""
        side = "left" if b["facet_left_contact_n"] >= b["facet_right_contact_n"] else "right"
        total, off = float(b[f"facet_{side}_contact_n"]), float(b[f"facet_{side}_beyond_surface_n"])
        if not total > 0:
            return ""
        return (f"In extension at 7.5 N*m, {fmt(off)} of the larger joint's {fmt(total)} N "
                f"({fmt(100 * off / total, 2)} %) come from contact beyond the fitted articular surface (the geometry's "
                "cartilage grid), where Eq. 4 is extrapolated (docs/validity.md).")

    def null_sentence(self) -> str:
        """What the model adds over a trivial model on the same rows (the validation's null-model table), in words
        where it does not beat it."""
        rel = self.out("validation", "null_models")
        return null_models_sentence(read_csv(self.path(rel))) if self.has(rel) else ""

    def _muscle_abstract(self) -> str:
        claims = paper2_claims_sentence(self, short=True)
        rel = self.out("muscle_model", "metrics")
        if not self.has(rel):
            return claims or f"Muscle model, in-vivo validation: {NOT_BUILT}."
        if claims:
            return claims + " " + self._muscle_validation_text()
        return self._muscle_validation_text()

    def _muscle_validation_text(self) -> str:
        rel = self.out("muscle_model", "metrics")
        m = json.loads(self.path(rel).read_text())
        n, total = m.get("n"), m.get("n_total", m.get("n"))
        if m.get("r2") is None or m.get("rmse_mpa") is None:
            s = (f"In-vivo L4-L5 intradiscal pressure: {fmt(n)} of {fmt(total)} activities certified, too few for "
                 "R2")
        else:
            s = (f"In-vivo L4-L5 intradiscal pressure: R2 = {fmt(m['r2'])}, RMSE = {fmt(m['rmse_mpa'])} MPa over "
                 f"{fmt(n)} of {fmt(total)} activities with a certified optimum")
        pub = self.published.get("idp_validation_r2")
        paper = pub["value"] if pub is not None else m.get("paper_r2")
        if paper is not None:
            s += f" (paper: R2 = {fmt(paper)})"
        iv = self.out("muscle_model", "validation")
        if self.has(iv):
            t = read_csv(self.path(iv))
            if "reached" in t.columns:
                miss = [human_value(a) for a, r in zip(t["activity"], t["reached"]) if not bool(r)]
                if "certified" in t.columns:
                    unc = [human_value(a) for a, r, c in zip(t["activity"], t["reached"], t["certified"])
                           if bool(r) and not bool(c)]
                    if unc:
                        s += (f"; reached, but IPOPT could not certify the optimum (left out; Flags): "
                              f"{', '.join(unc)}")
                        if m.get("r2_reached") is not None and m.get("rmse_reached_mpa") is not None:
                            s += (f" (with it, over the {fmt(m.get('n_reached'))} activities reached: R2 = "
                                  f"{fmt(m['r2_reached'])}, RMSE = {fmt(m['rmse_reached_mpa'])} MPa)")
                if miss:
                    s += f"; not reached (beyond its muscles' capacity; muscle capacity table): {', '.join(miss)}"
        return s + "."

    def warnings(self) -> list[tuple[str, str]] | None:
        """(log, message) of every WARNING line in the workflow's logs (``logs_dir``), time stamps removed, in
        file order (not those under a sub-folder of ``logs_exclude``: another run's); None when no logs directory
        was given or it does not exist."""
        if self.logs_dir is None or not self.logs_dir.is_dir():
            return None
        out = []
        for p in sorted(self.logs_dir.rglob("*.log")):
            if p.name == "paper_report.log" or p.relative_to(self.logs_dir).parts[0] in self.logs_exclude:
                continue                              # this report's own log (being written), another run's
            for line in p.read_text(errors="replace").splitlines():
                m = re.match(r"^(?:\d{4}-\d\d-\d\d[ T][\d:,.]+\s+)?WARNING\s+(.*)$", line)
                if m:
                    out.append((p.relative_to(self.logs_dir).with_suffix("").as_posix(), m.group(1).strip()))
        return out


# ----------------------------------------------------------------------------------------------- the sections
@dataclass
class Section:
    """One section of the report: ``build(builder)`` adds its blocks below a level-1 heading ``title`` (numbered
    when ``numbered``), which the HTML gives the id ``anchor`` (the contents and the docs link to it)."""
    anchor: str
    title: str
    build: Callable[[ReportBuilder], None]
    numbered: bool = True


#: the report's sections in order, after the first page
SECTIONS: list[Section] = []


def report_section(anchor: str, title: str, *, after: str | None = None, before: str | None = None,
                   numbered: bool = True):
    """Register ``f(builder)`` as a section of the report (decorator), at the end or ``after``/``before`` the
    section with that anchor. ``f`` writes with the builder's ``csv_table``, ``figure``, ``table_block``,
    ``heading``, ``para`` and ``missing``; a file it shows must be among the report's inputs (in the workflow:
    an output its stage manifest marks ``final`` or ``report="optional"``, lumbar.inputs.manifests), else it is
    reported as "not built in this configuration"; it finds the file by its role, ``b.out(stage, role)``.
    Re-registering an anchor replaces that section."""
    def register(f):
        sec = Section(anchor, title, f, numbered)
        old = [i for i, x in enumerate(SECTIONS) if x.anchor == anchor]
        if old:
            SECTIONS[old[0]] = sec
            return f
        ref = after or before
        idx = next((i for i, x in enumerate(SECTIONS) if x.anchor == ref), None) if ref else None
        if ref and idx is None:
            raise ValueError(f"report_section({anchor!r}): no section {ref!r}; anchors: "
                             f"{[x.anchor for x in SECTIONS]}")
        SECTIONS.insert(len(SECTIONS) if idx is None else idx + (1 if after else 0), sec)
        return f
    return register
