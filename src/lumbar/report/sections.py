"""The report's sections: :class:`ReportBuilder` reads the result files and the configuration and writes the
document (:mod:`lumbar.report.document`): summary, methods, results per stage, discrepancy workflow, provenance and
the configuration appendix. Every number comes from a result or data file; nothing is typed in."""
from __future__ import annotations

import hashlib
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
from lumbar.inputs.tables import OUTLIER_COUNT_NAMES

from lumbar.experiments import validation as V

from .document import CHECK, CROSS, NC, Bullets, Contents, Doc, Figure, Heading, Para, Table

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
MAX_ROWS = 60          # generic CSV tables: at most this many rows are drawn, the rest is referenced
MAX_WARNINGS = 40      # the Flags section lists at most this many warnings (all are in logs/)

T = "results/tables/"
F = "results/figures/"
MM = "results/muscle_model/"
D = "results/discrepancy/"
DISCOVERY_CASES = (("default", "stepwise reduction (default case)"), ("in_vivo", "in-vivo intradiscal pressure"),
                   ("va_artefact", "vertebral-arch removal artefact"),
                   ("intact_rom", "intact L4-L5 range of motion (Yamamoto et al. 1989)"))


# ----------------------------------------------------------------------------------------------- small helpers
def _norm(p) -> str:
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


def _reference_text(section: dict, noise: str) -> str:
    """What a stage is compared with, from its config section: the measured table it names, or the SURROGATE
    of virtual specimens (count, generator set and ``noise``, e.g. "noise SD 0.5 deg")."""
    if section.get("measured_table"):
        return f"the measured table {section.get('measured_table')}"
    return (f"a SURROGATE of {fmt(section.get('n_specimens'))} virtual specimens of the "
            f"'{fmt(section.get('generator_set'))}' set ({noise})")


def _flatten(d, prefix="") -> list[tuple[str, Any]]:
    out = []
    for k in d:
        v = d[k]
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping) and v:
            out += _flatten(v, key)
        else:
            out.append((key, v))
    return out


def _read_csv(path) -> pd.DataFrame:
    return pd.read_csv(path)


def _mentions_surrogate(path) -> bool:
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
class ReportBuilder:
    """Reads the result files and writes the report's sections into a :class:`~lumbar.report.document.Doc`
    (prose from the configuration and the files, figure and table numbering, what was not built)."""

    def __init__(self, inputs, config, html_path, captions_dir=None, published=None, logs_dir=None):
        self.config = config
        self.logs_dir = Path(logs_dir) if logs_dir else None
        self.html_dir = Path(html_path).resolve().parent
        self.inputs = {}
        for p in inputs:
            self.inputs[_norm(p)] = Path(p)
        self.captions_dir = Path(captions_dir) if captions_dir else None
        self.published = self._published(published)
        self.shown: set[str] = set()
        self.n_fig = 0
        self.n_tab = 0
        self.doc = Doc()
        sr = config.get("stepwise_reduction", {}) or {}
        l2 = config.get("l2s1", {}) or {}
        self.sr_surrogate = not sr.get("measured_table") or self._file_surrogate(T + "table4_outlier_counts.csv")
        self.idp_surrogate = not l2.get("measured_table") or self._file_surrogate(T + "table5_outlier_counts.csv")

    # -- inputs
    def has(self, rel) -> bool:
        p = self.inputs.get(_norm(rel))
        return p is not None and p.exists()

    def path(self, rel) -> Path:
        return self.inputs[_norm(rel)]

    def _file_surrogate(self, rel) -> bool:
        """Whether a result file compares with SURROGATE data: a table by its data-kind column (its header may name
        the word, e.g. the outlier counts' ``surrogate_comparison``), any other file by its text."""
        if not self.has(rel):
            return False
        path = self.path(rel)
        if path.suffix == ".csv":
            df = _read_csv(path)
            for col in ("data_kinds", "data_kind", "kind"):
                if col in df.columns:
                    return bool(df[col].astype(str).str.contains("surrogate", case=False).any())
        return _mentions_surrogate(path)

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
        self.shown.add(_norm(rel))
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
            self.shown.add(_norm(source))
        self.doc.add(Table(f"{label}. {title}", [str(h) for h in header], rows, source, note, **kw))

    def csv_table(self, rel, title, surrogate=None, columns=None, max_rows=MAX_ROWS, label=None):
        if not self.has(rel):
            self.missing(f"{label or 'Table'}, {title} ({Path(rel).name})")
            return None
        try:
            df = _read_csv(self.path(rel))
        except (ValueError, pd.errors.ParserError) as e:   # shown as a note; the rest of the report is built
            self.doc.add(Para(f"{label or 'Table'}, {title} ({rel}): not readable as CSV ({e}).", "note"))
            return None
        if surrogate is None:
            surrogate = _mentions_surrogate(self.path(rel))
        shown = df[columns] if columns else df
        note = self.caption(rel, "", surrogate=False)
        # a column with one value in every row is said once, in the note, not repeated in every row
        if len(shown) >= 3 and shown.shape[1] > 3:
            const = [c for c in shown.columns if shown[c].nunique(dropna=False) == 1]
            if const and len(const) < shown.shape[1] - 1:
                said = "; ".join(f"{human_header(c)} = {self._cell(c, shown[c].iloc[0]) or '(empty)'}"
                                 for c in const)
                note = (note + " " if note else "") + f"In every row: {said}."
                shown = shown.drop(columns=const)
        if shown.shape[1] > 12 and len(shown) <= 8:      # wide and short: one row per column
            header = ["column"] + [f"row {i + 1}" for i in range(len(shown))]
            rows = [[human_header(c)] + [self._cell(c, v) for v in shown[c]] for c in shown.columns]
            self.table_block(title, header, rows, source=rel, note=note, surrogate=surrogate, label=label)
            return df
        if len(shown) > max_rows:
            note = (note + " " if note else "") + f"First {max_rows} of {len(shown)} rows; full table: {rel}."
            shown = shown.head(max_rows)
        rows = [[self._cell(c, v) for c, v in zip(shown.columns, r)] for r in shown.itertuples(index=False)]
        self.table_block(title, [human_header(c) for c in shown.columns], rows, source=rel, note=note,
                         surrogate=surrogate, label=label)
        return df

    @staticmethod
    def _cell(column: str, v) -> str:
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

    def _cfg(self, *keys, default=None):
        v = self.config
        for k in keys:
            if not isinstance(v, Mapping) or k not in v:
                return default
            v = v[k]
        return v

    # -- summary
    def _counts_sentence(self, rel_vs, rel_counts, what, surrogate):
        rel = rel_vs if self.has(rel_vs) else rel_counts if self.has(rel_counts) else None
        if rel is None:
            return f"{what}: {NOT_BUILT}."
        # the vocabulary of lumbar.inputs.tables.VS_PAPER_COLUMNS; an outlier-count table (no vs-paper table built)
        # has no paper columns, Table 5's names its counts outliers / scenarios (lumbar.experiments.l2s1.outlier_counts)
        df = _read_csv(self.path(rel)).rename(columns=OUTLIER_COUNT_NAMES)
        ours, scen = "n_outliers", ("n_scenarios" if "n_scenarios" in df.columns else None)
        paper = "paper_n_outliers" if "paper_n_outliers" in df.columns else None
        paper_scen = "paper_n_scenarios" if "paper_n_scenarios" in df.columns else None
        parts = []
        for _, r in df.iterrows():
            s = f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[ours])} of {fmt(r[scen])}" if scen else \
                f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[ours])}"
            if paper and fmt(r[paper]) != "":
                ps = f" of {fmt(r[paper_scen])}" if paper_scen and fmt(r[paper_scen]) else ""
                s += f" (paper: {fmt(r[paper])}{ps})"
            parts.append(s)
        ref = ("SURROGATE reference (virtual specimens; a method check, i.e. a round trip, not a reproduction of "
               "the paper's counts)") if surrogate else "the measured reference table"
        real_o, real_n = (c if c in df.columns else None for c in ("n_outliers_real", "n_scenarios_real"))
        if real_o and real_n and surrogate:
            parts_real = [f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[real_o])} of {fmt(r[real_n])}"
                          for _, r in df.iterrows() if fmt(r[real_n]) not in ("", "0")]
            if parts_real:
                ref += "; outliers among the rows with a real (measured or published-fit) reference: " + \
                    "; ".join(parts_real)
        paper_note = " The paper's counts are against the measured experiment, ours against the " + \
            ("surrogate, so they are not a reproduction of the paper's numbers." if surrogate else "given table.") \
            if paper and df[paper].notna().any() else \
            " The paper's counts are not available in this run (paths.published_model_results not found)."
        return f"{what}, outliers against {ref}: " + "; ".join(parts) + "." + paper_note

    # -- first page: can I trust this model, and for what?
    def first_page(self):
        """Title, a five-sentence abstract read from the result files, and the validation scoreboard figure."""
        self.doc.add(Heading(TITLE, 0))
        self.doc.add(Para(self.abstract(), "abstract"))
        self.figure(F + "validation_scoreboard.png", "Validation scoreboard: every distinct comparison with data "
                    "this model did not generate.", label="Fig. R")
        self.figure(F + "validation_internal_loads.png", "Internal loads of the calibrated unit against measurements: "
                    "judged, never fitted (left), and those the fit also holds as constraints (right).",
                    label="Fig. R2")
        self.doc.add(Para(f"Generated by lumbar {__version__} from the result files of this configuration (geometry "
                          f"'{fmt(self._cfg('geometry', 'kind'))}', seed {fmt(self._cfg('seed'))}); every number "
                          "is read from a result file. Reproduces: " + "; ".join(PAPERS) + ".", "small"))

    def _distinct(self):
        rel = T + "validation_real_data.csv"
        if not self.has(rel):
            return None
        df = _read_csv(self.path(rel))
        self.shown.add(_norm(rel))
        return V.distinct_comparisons(df) if len(df) else df

    def abstract(self) -> str:
        """Five sentences: what is compared, the independent checks, the calibration targets, the muscle model,
        what is only a method check and how many warnings need attention."""
        d = self._distinct()
        geo = human_value(fmt(self._cfg("geometry", "kind")))
        out = []
        if d is None or not len(d):
            out.append(f"This report shows the results of the lumbar workflow ({geo} geometry); the comparison with "
                       f"real data is {NOT_BUILT}.")
            out.append("Independent checks: none in this configuration.")
            out.append("Calibration targets: none in this configuration.")
        else:
            counts = V.role_counts(d)
            out.append(f"This report compares the lumbar workflow's models ({geo} geometry) with measurements they did "
                       f"not generate, in {len(d)} distinct comparisons (Fig. R, Tables R1 and R2).")
            w, n = counts.get(V.INDEPENDENT, (0, 0))
            ind = d[d["role"] == V.INDEPENDENT]
            agree, miss = [], []
            for (q, sets), g in ind.groupby(["quantity", "sets"], sort=False):
                name = f"{V.condition_label(q)} ({V.sets_label(sets)})"
                if g["within"].all():
                    agree.append(name)
                else:
                    miss.append(f"{name}, {int(g['within'].sum())} of {len(g)} within")
            text = f"Independent checks: {w} of {n} within their acceptance interval"
            if agree:
                text += "; the model agrees with " + ", ".join(agree)
            if miss:
                text += "; it misses " + "; ".join(miss)
            out.append(text + ".")
            nulls = self._null_sentence()
            if nulls:
                out.append(nulls)
            w, n = counts.get(V.INTERNAL, (0, 0))
            if n:
                g = d[d["role"] == V.INTERNAL]
                miss = [f"{V.condition_label(r.condition)}" for r in g.itertuples() if not r.within]
                wc, nc = counts.get(V.CONSTRAINT, (0, 0))
                out.append(f"Internal loads of the calibrated unit (facet contact forces against in-vitro "
                           f"measurements; judged, never fitted): {w} of {n} within"
                           + (f" (outside: {', '.join(miss)})" if miss else "")
                           + (f"; the ligament roles and the facet share of compression, which the fit also holds "
                              f"as constraints, {wc} of {nc}" if nc else "") + " (Tables R3 and R4).")
            w, n = counts.get(V.TARGET, (0, 0))
            out.append(f"Calibration targets (a fit quality, not a validation): {w} of {n} met." if n else
                       "Calibration targets: none in this configuration.")
        out.append(self._muscle_abstract())
        sur = [name for name, flag in (("Table 4", self.sr_surrogate), ("Table 5", self.idp_surrogate)) if flag]
        warn = self.warnings()
        tail = (f"{len(warn)} warning(s) need the user's attention (Flags)." if warn is not None
                else "the workflow logs were not given to the report.")
        if sur:
            out.append(f"The outlier counts of {' and '.join(sur)} compare with SURROGATE data (virtual specimens of "
                       f"this model), a method check, not a reproduction of the paper; {tail}")
        else:
            out.append(f"Tables 4 and 5 compare with the configured measured tables; {tail}")
        return " ".join(out)

    def _null_sentence(self) -> str:
        """What the model adds over a trivial model on the same rows (results/tables/validation_null_models.csv),
        in words where it does not beat it."""
        rel = T + "validation_null_models.csv"
        if not self.has(rel):
            return ""
        t = _read_csv(self.path(rel))
        parts = []
        for r in t.itertuples(index=False):
            s = (f"{V.condition_label(r.quantity)}: the model {r.model_within} of {r.n_rows} within, a trivial model "
                 f"({r.description}) {r.null_within}")
            if not bool(r.model_beats_null):
                s += " - the model does not beat it"
            parts.append(s)
        return ("Beside a trivial model on the same rows: " + "; ".join(parts) + ".") if parts else ""

    def _muscle_abstract(self) -> str:
        rel = MM + "in_vivo_metrics.json"
        if not self.has(rel):
            return f"Muscle model, in-vivo validation: {NOT_BUILT}."
        m = json.loads(self.path(rel).read_text())
        n, total = m.get("n"), m.get("n_total", m.get("n"))
        if m.get("r2") is None or m.get("rmse_mpa") is None:
            s = (f"The muscle-driven model reaches {fmt(n)} of {fmt(total)} in-vivo activities, too few for R2 and "
                 "RMSE of the L4-L5 intradiscal pressure")
        else:
            s = (f"The muscle-driven model predicts the in-vivo L4-L5 intradiscal pressure with R2 = {fmt(m['r2'])} "
                 f"and RMSE = {fmt(m['rmse_mpa'])} MPa over the {fmt(n)} of {fmt(total)} activities it reaches")
        pub = self.published.get("idp_validation_r2")
        paper = pub["value"] if pub is not None else m.get("paper_r2")
        if paper is not None:
            s += f" (paper: R2 = {fmt(paper)})"
        iv = T + "in_vivo_validation.csv"
        if self.has(iv):
            t = _read_csv(self.path(iv))
            if "reached" in t.columns:
                miss = [human_value(a) for a, r in zip(t["activity"], t["reached"]) if not bool(r)]
                if miss:
                    s += f"; not reached (beyond its muscles' capacity; muscle capacity table): {', '.join(miss)}"
        return s + "."

    def scoreboard_section(self):
        """Tables R1 and R2: one row per distinct comparison, independent checks apart from calibration targets."""
        rel = T + "validation_real_data.csv"
        d = self._distinct()
        if d is None:
            self.missing("Validation on real data (validation_real_data.csv)")
            return
        self.doc.add(Para("One row per distinct comparison: rows that several characteristic sets share (the "
                          "disc-only stage, for which every set uses the paper's disc) are shown once, with the "
                          "number of sets. Acceptance interval: the published range, else the tolerance named in "
                          f"the CSV's tolerance_rule. Every row, with its source: {rel}. Agreement with the "
                          "SURROGATE tables further below is a method check, not a validation."))
        titles = {V.INDEPENDENT: ("R1", "Independent checks (validation)"),
                  V.TARGET: ("R2", "Calibration targets (fit quality, not validation)"),
                  V.INTERNAL: ("R3", "Internal loads, independent checks (judged, never fitted)"),
                  V.CONSTRAINT: ("R4", "Internal loads the fit also holds as constraints (not independent)")}
        for role, (w, n) in V.role_counts(d).items():
            g = d[d["role"] == role]
            label, title = titles.get(role, (None, role))
            rows, last = [], None
            for r in g.itertuples(index=False):
                q = f"{V.condition_label(r.quantity)} [{V.unit_label(r.unit)}]"
                band = (f"{fmt(r.band_low)} to {fmt(r.band_high)}" if np.isfinite(r.band_low) else "")
                sim = fmt(r.sim) if np.isfinite(r.sim) else "no value"
                blo = getattr(r, "sim_band_low", np.nan)
                post = f"{fmt(blo)}-{fmt(r.sim_band_high)}" if np.isfinite(blo) else ""
                rows.append([q if q != last else "", V.condition_label(r.condition), sim, post, fmt(r.measured), band,
                             CHECK if r.within else CROSS, V.sets_label(r.sets)])
                last = q
            self.table_block(f"{title}: {w} of {n} distinct comparisons within", ["quantity [unit]", "condition",
                             "simulated", "90 % band", "measured", "acceptance interval", "within",
                             "simulated by"], rows,
                             source=rel, label=f"Table {label}" if label else None, marks=True, key_cols=2)

    def warnings(self) -> list[tuple[str, str]] | None:
        """(log, message) of every WARNING line in the workflow's logs (``logs_dir``), time stamps removed, in
        file order; None when no logs directory was given or it does not exist."""
        if self.logs_dir is None or not self.logs_dir.is_dir():
            return None
        out = []
        for p in sorted(self.logs_dir.rglob("*.log")):
            if p.name == "paper_report.log":          # this report's own log, being written
                continue
            for line in p.read_text(errors="replace").splitlines():
                m = re.match(r"^(?:\d{4}-\d\d-\d\d[ T][\d:,.]+\s+)?WARNING\s+(.*)$", line)
                if m:
                    out.append((p.relative_to(self.logs_dir).with_suffix("").as_posix(), m.group(1).strip()))
        return out

    def flags_section(self):
        """Every WARNING of the workflow's logs: what a user must act on. Expected outcomes are results in their
        tables (and one summary line in the rule's log), not warnings."""
        warn = self.warnings()
        self.doc.add(Para(
            "A warning in a rule's log is something to act on. Expected outcomes are results in their tables, each "
            "rule's log has one summary line for them: postures the muscles cannot hold (columns reached and "
            "converged of the muscle tables; red stars in the figures), scenarios without equilibrium (converged, "
            "n.c. in the grids), ROM measured from an unstable rest state (rest_state_stable of the stepwise-reduction "
            "tables: the disc-only stage, whose flexion law has negative stiffness about zero), calibration parameters that are not identifiable or end at a bound (columns "
            "identifiable and at_bound of calibration_summary.csv), comparisons outside their acceptance interval "
            "(Tables R1 and R2)."))
        if warn is None:
            self.doc.add(Para(f"Workflow logs: {NOT_BUILT} (no logs directory given to the report).", "note"))
        elif not warn:
            self.doc.add(Para("No warning in the workflow's logs.", "p"))
        else:
            note = (f"First {MAX_WARNINGS} of {len(warn)}; every one is in its rule's log under logs/."
                    if len(warn) > MAX_WARNINGS else "")
            self.table_block(f"Warnings in the workflow's logs ({len(warn)})", ["rule log", "warning"],
                             [[name, msg] for name, msg in warn[:MAX_WARNINGS]], note=note, key_cols=0)

    def summary(self):
        paras = [
            self._counts_sentence(T + "table4_vs_paper.csv", T + "table4_outlier_counts.csv",
                                  "Stepwise reduction, forward simulation (Table 4 analog)", self.sr_surrogate),
            self._counts_sentence(T + "table5_vs_paper.csv", T + "table5_outlier_counts.csv",
                                  "L2-S1 intradiscal pressure (Table 5 analog)", self.idp_surrogate),
            self._calibration_sentence(),
            self._muscle_sentence(),
            self._discrepancy_sentence(),
        ]
        for p in paras:
            self.doc.add(Para(p, "abstract"))

    def _calibration_sentence(self):
        rel = "results/calibration/calibration_summary.csv"
        if not self.has(rel):
            return f"Calibration residuals: {NOT_BUILT}."
        df = _read_csv(self.path(rel))
        res, unit = "rms_residual", "residual_unit"        # lumbar.experiments.calibration's summary columns
        parts = []
        for u, g in df.groupby(unit, sort=False) if unit else [("", df)]:
            names = ", ".join(str(x) for x in g.get("structure", g.index))
            parts.append(f"{fmt(g[res].min())} to {fmt(g[res].max())} {u} ({names})")
        nc = int(df["n_not_converged"].sum()) if "n_not_converged" in df else 0
        kind = " on SURROGATE data" if _mentions_surrogate(self.path(rel)) else ""
        return (f"Calibration{kind} in {df['step'].nunique() if 'step' in df else len(df)} steps, RMS residuals: "
                + "; ".join(parts) + f"; {nc} non-converged scenario(s) during the fits.")

    def _muscle_sentence(self):
        rel = MM + "in_vivo_metrics.json"
        if not self.has(rel):
            return f"Muscle model, in-vivo validation: {NOT_BUILT}."
        m = json.loads(self.path(rel).read_text())
        n_tot = m.get("n_total", m.get("n"))
        s = (f"Muscle model (paper 2): predicted vs in-vivo L4-L5 intradiscal pressure over {fmt(m.get('n'))} "
             f"converged of {fmt(n_tot)} activities, ")
        if m.get("r2") is None or m.get("rmse_mpa") is None:
            s += "R2 and RMSE not computed (too few converged activities)"
        else:
            s += f"R2 = {fmt(m.get('r2'), 3)}, RMSE = {fmt(m.get('rmse_mpa'), 3)} MPa"
        pub = self.published.get("idp_validation_r2")
        if pub is not None:
            s += f" (paper: R2 = {fmt(pub['value'])}, {pub['source']})"
        if m.get("r2_all") is not None and m.get("n", n_tot) != n_tot:
            s += (f"; with the IDP of the {fmt(n_tot - m.get('n'))} posture(s) flagged as not converged included, "
                  f"R2 = {fmt(m['r2_all'], 3)}, RMSE = {fmt(m['rmse_all_mpa'], 3)} MPa (the muscle capacity table "
                  "says where the muscles fall short)")
        if _mentions_surrogate(self.path(rel)):
            s += " [SURROGATE data involved]"
        return s + "."

    def _discrepancy_sentence(self):
        out = []
        rel = D + "default/discovery.json"
        if self.has(rel):
            d = json.loads(self.path(rel).read_text())
            sur = " (against SURROGATE reference data)" if self.sr_surrogate else ""
            if d.get("named_effect"):
                out.append(f"Discrepancy workflow{sur}: the missing effect that best explains the model-experiment "
                           f"gap is '{fmt(d.get('named_effect'))}' (estimate {fmt(d.get('parameter_estimate'))}, "
                           f"confidence {fmt(d.get('confidence'))}); gap {fmt(d.get('gap_before'))} before, "
                           f"{fmt(d.get('gap_after'))} after adding it.")
            else:
                out.append(f"Discrepancy workflow{sur}: no missing effect is named (gap {fmt(d.get('gap_before'))}; "
                           f"{fmt(d.get('decision')) or 'no candidate passed the naming rule'}).")
        rel = D + "benchmark_summary.json"
        if self.has(rel):
            d = json.loads(self.path(rel).read_text())
            scal = [(k, v) for k, v in _flatten(d) if isinstance(v, (int, float, bool))][:8]
            out.append("Discrepancy benchmark on SURROGATE data with planted effects: "
                       + ", ".join(f"{k} = {fmt(v)}" for k, v in scal) + ".")
        return " ".join(out) if out else f"Discrepancy workflow: {NOT_BUILT}."

    # -- methods
    def methods(self):
        c = self._cfg
        g = c("geometry", default={}) or {}
        geo = f"Geometry: '{fmt(g.get('kind'))}'" + (f" read from {g.get('path')}" if g.get("kind") ==
                                                      "visible_human" else " (myo-sim meshes with project landmarks)")
        self.doc.add(Para(
            f"{geo}; motion segment {fmt(c('fsu', 'level'))}. Characteristic sets: "
            f"{', '.join(SET_LABELS.get(s, s) for s in c('characteristics', 'sets', default=[]))} "
            f"(tables in {fmt(c('characteristics', 'data_dir'))}). Pure moments "
            f"{fmt(c('fsu', 'moments_nm'))} N*m in {fmt(c('fsu', 'directions'))}; facet contact stiffness "
            f"{fmt(c('fsu', 'facet_stiffness_n_per_m'))} N/m; disc shear stiffness "
            + (f"{fmt(c('fsu', 'disc_shear_stiffness_n_per_m'))} N/m." if c('fsu', 'disc_shear_stiffness_n_per_m')
               else "the characteristic set's default.")))
        self.doc.add(Para(self._which_set_text()))
        self.doc.add(Para(
            f"Solver: batched Newton with exact tangent stiffness, tolerances {fmt(c('solver', 'tol_force_n'))} N "
            f"and {fmt(c('solver', 'tol_moment_nm'))} N*m, at most {fmt(c('solver', 'max_iter'))} iterations, "
            f"{fmt(c('solver', 'load_steps'))} load step(s); scenarios without equilibrium are flagged and counted "
            f"as outliers. Random seed {fmt(c('seed'))}."))
        sr = c("stepwise_reduction", default={}) or {}
        if sr:
            ref = _reference_text(sr, f"noise SD {fmt(sr.get('noise_sd_deg'))} deg, seed {fmt(c('seed'))}")
            self.doc.add(Para(
                f"Stepwise reduction (paper 1, Sect. 2.1-2.2): calibration in reverse removal order and forward "
                f"simulation at {fmt(sr.get('moments_nm'))} N*m, against {ref}; disc-only rows "
                + (f"derived from the published Eq. 3 fit ({sr.get('disc_only_derived')}); "
                   if sr.get("disc_only_derived") else "from the reference table; ") +
                f"rows without a range use mean +- {fmt(sr.get('outlier_tolerance_deg'))} deg."))
        l2 = c("l2s1", default={}) or {}
        if l2:
            ref = _reference_text(l2, f"noise SD {fmt(l2.get('noise_sd_mpa'))} MPa")
            self.doc.add(Para(
                f"L2-S1 intradiscal pressure (paper 1, Sect. 2.3): sets {fmt(l2.get('sets'))}, moments "
                f"+-{fmt(l2.get('moment_nm'))} N*m on L2, wire cables from {fmt(l2.get('cables'))}, IDP formula "
                f"'{fmt(l2.get('idp_formula'))}', compared with {ref}."))
        known = {"geometry", "characteristics", "fsu", "solver", "render", "stepwise_reduction", "l2s1", "paths",
                 "seed"}
        for key in self.config:
            if key in known or not isinstance(self.config[key], Mapping):
                continue
            items = _flatten(self.config[key])
            self.doc.add(Para(f"{key}: " + "; ".join(f"{k} = {fmt(v)}" for k, v in items) + "."))

    def _which_set_text(self):
        """Which characteristic set each model uses: "calibrated" is the workflow's own fit, named once."""
        c = self._cfg
        cal = fmt(c("characteristics", "calibrated_dir", default="results/calibration/characteristics"))
        out = [f"'Calibrated' means this workflow's own calibration (rule calibrate, tables in {cal}, fitted on the "
               f"'{fmt(c('geometry', 'kind'))}' geometry); it is used by the functional unit, the L2-S1 model "
               f"(l2s1.calibrated_characteristics = {fmt(c('l2s1', 'calibrated_characteristics'))}), the other "
               f"levels and the discrepancy discovery (discovery.characteristic_set = "
               f"{fmt(c('discovery', 'characteristic_set'))})."]
        ps = c("muscle_model", "passive_set")
        if ps:
            what = {"workflow_calibrated": f"the workflow's calibrated set ({cal}) applied unchanged at every myo-sim "
                                           "level (ligament laws on elongation, its facet and disc shear stiffness)",
                    "published_table3": f"paper 1's published Table 3 set as printed "
                                        f"({fmt(c('characteristics', 'data_dir'))}), not the workflow's calibration"}
            out.append(f"The muscle-driven model's passive spine (muscle_model.passive_set = {fmt(ps)}): "
                       f"{what.get(ps, 'the literature set ' + SET_LABELS.get(ps, ps))}.")
        return " ".join(out)

    # -- paper 1
    def model_section(self):
        self.figure(F + "fig1_l4l5_model.png", "L4-L5 functional spinal unit (Fig. 1 analog).", label="Fig. 1")
        self.figure(F + "fig3_l2s1_cables.png", "L2-S1 lumbar spine with wire cables (Fig. 3 analog).",
                    label="Fig. 3")
        self.csv_table(T + "fsu_geometry.csv", "Geometry of the motion segments (disc, facets, ligament fibres)")

    def calibration_section(self):
        s = self.sr_surrogate
        self.csv_table(T + "table1_disc_calibrated.csv", "Disc torque-angle parameters, Eq. 3 (Table 1 analog)", s,
                       label="Table 1")
        self.figure(F + "fig4_disc_torque_angle.png", "Disc torque-angle characteristics (Fig. 4 analog).", s,
                    label="Fig. 4")
        self.csv_table(T + "table2_facet_surfaces.csv", "Facet joint regression surfaces, Eq. 4 (Table 2 analog)",
                       label="Table 2")
        self.csv_table(T + "table3_ligaments_calibrated.csv",
                       "Ligament force-strain parameters, Eq. 7 (Table 3 analog)",
                       s, label="Table 3")
        self.figure(F + "fig5_ligament_characteristics.png", "Ligament force-strain characteristics (Fig. 5 analog).",
                    s, label="Fig. 5")
        self.csv_table("results/calibration/calibration_summary.csv",
                       "Calibration steps and RMS residuals (identifiable: the stage's ROM responds to the structure; "
                       "at_bound: a fitted parameter ends within 1 % of its bound)", s)
        targets = "results/calibration/calibration_targets.csv"
        origin = ""
        if self.has(targets):
            t = _read_csv(self.path(targets))
            origin = "; ".join(dict.fromkeys(str(v).split(",")[0] for v in t["source"])) if len(t) else ""
        self.csv_table("results/calibration/calibration_real_fit.csv",
                       f"Final fit on the real targets (intact ROM at 10 N*m{', ' + origin if origin else ''}) and "
                       "the admissibility criteria: force scales, facet stiffness, disc shear stiffness within its "
                       "sourced range", False)

    def forward_section(self):
        s = self.sr_surrogate
        self.figure(F + "fig6_rom_stepwise_reduction.png", "Range of motion per reduction stage (Fig. 6 analog).", s,
                    label="Fig. 6")
        self.csv_table(T + "table4_vs_paper.csv", "ROM outlier counts per characteristic set beside the paper's", s)
        self.grid_table4(s)
        self.figure(F + "table4_grid.png", "Table 4 as a figure.", s)

    def idp_section(self):
        s = self.idp_surrogate
        self.figure(F + "fig7_idp.png", "L4-L5 intradiscal pressure per muscle set-up and load case (Fig. 7 analog).",
                    s, label="Fig. 7")
        self.csv_table(T + "table5_vs_paper.csv", "IDP outlier counts per characteristic set beside the paper's", s)
        self.grid_table5(s)
        self.figure(F + "table5_grid.png", "Table 5 as a figure.", s)
        if self.has(T + "l2s1_internal_loads.csv"):
            df = _read_csv(self.path(T + "l2s1_internal_loads.csv"))
            num = [c for c in df.columns if c.endswith(("_n", "_nm", "_mpa"))
                   and not c.startswith("residual") and pd.api.types.is_numeric_dtype(df[c])]
            agg = df.groupby("set", sort=False)[num].agg(["min", "max"]) if "set" in df and num else None
            if agg is not None:
                rows = [[c] + [f"{fmt(agg.loc[st, (c, 'min')])} to {fmt(agg.loc[st, (c, 'max')])}"
                               if fmt(agg.loc[st, (c, "max")]) else "" for st in agg.index] for c in num]
                self.table_block("Internal loads at L4-L5 over the 49 scenarios (min to max per set)",
                                 ["quantity"] + [SET_LABELS.get(st, st) for st in agg.index], rows,
                                 source=T + "l2s1_internal_loads.csv",
                                 note=self.caption(T + "l2s1_internal_loads.csv", ""), surrogate=s)
        else:
            self.missing("Internal loads (l2s1_internal_loads.csv)")

    def grid_table4(self, surrogate):
        rel = T + "table4_rom_synopsis.csv"
        if not self.has(rel):
            self.missing("Table 4 synopsis (table4_rom_synopsis.csv)")
            return
        df = _read_csv(self.path(rel))
        sets = list(dict.fromkeys(df["set"]))
        dirs = [d for d in DIRECTION_ABBR if d in set(df["direction"])] + \
            [d for d in dict.fromkeys(df["direction"]) if d not in DIRECTION_ABBR]
        keyed = {(r.set, r.stage, r.moment_nm, r.direction): r for r in df.itertuples(index=False)}
        rows = []
        for stage in dict.fromkeys(df["stage"]):
            for m in sorted(set(df.loc[df["stage"] == stage, "moment_nm"])):
                row = [human_value(stage), f"{fmt(m)} N\u00b7m"]
                for st in sets:
                    for d in dirs:
                        r = keyed.get((st, stage, m, d))
                        row.append("" if r is None else NC if not bool(r.converged) else
                                   CROSS if bool(r.outlier) else CHECK)
                rows.append(row)
        header = ["stage", "moment"] + [DIRECTION_ABBR.get(d, d) for _ in sets for d in dirs]
        group = [("", 2)] + [(SET_LABELS.get(s, s), len(dirs)) for s in sets]
        self.table_block("Synopsis of the forward-simulated stepwise reduction (Table 4 analog): "
                         f"{CHECK} within the reference range, {CROSS} outlier, {NC} no equilibrium",
                         header, rows, source=rel, note=self.caption(rel, ""), surrogate=surrogate,
                         group_header=group, marks=True, label="Table 4")

    def grid_table5(self, surrogate):
        rel = T + "table5_idp_synopsis.csv"
        if not self.has(rel):
            self.missing("Table 5 synopsis (table5_idp_synopsis.csv)")
            return
        df = _read_csv(self.path(rel))
        sets = list(dict.fromkeys(df["set"]))
        keyed = {(r.set, r.muscle_setup, r.load_case): r for r in df.itertuples(index=False)}
        rows = []
        for mu in dict.fromkeys(df["muscle_setup"]):
            for lc in dict.fromkeys(df.loc[df["muscle_setup"] == mu, "load_case"]):
                row = [human_value(mu), human_value(lc)]
                for st in sets:
                    r = keyed.get((st, mu, lc))
                    row.append("" if r is None else NC if not bool(r.converged) else
                               CROSS if bool(r.outlier) else CHECK)
                rows.append(row)
        self.table_block("Synopsis of the forward-simulated IDP experiment (Table 5 analog): "
                         f"{CHECK} within mean +- SD, {CROSS} outlier, {NC} no equilibrium",
                         ["muscle set-up", "load case"] + [SET_LABELS.get(s, s) for s in sets], rows, source=rel,
                         note=self.caption(rel, ""), surrogate=surrogate, marks=True, label="Table 5")

    # -- paper 2
    def muscle_section(self):
        files = [T + "muscle_model_segment_loads.csv", T + "in_vivo_validation.csv", MM + "in_vivo_metrics.json",
                 T + "flexion_relaxation.csv", T + "muscle_capacity.csv", T + "sensitivity_idp.csv",
                 T + "sensitivity_directions.csv", T + "sobol_indices.csv"]
        figs = sorted(p for p in self.inputs if p.startswith(F + "muscle_") and p.endswith(".png"))
        if not any(self.has(f) for f in files) and not figs:
            self.doc.add(Para(f"Muscle study: {NOT_BUILT}.", "note"))
            return
        if self.has(MM + "in_vivo_metrics.json"):
            self.doc.add(Para(self._muscle_sentence()))
            self.shown.add(_norm(MM + "in_vivo_metrics.json"))
        else:
            self.missing("In-vivo validation metrics (in_vivo_metrics.json)")
        self.figure(F + "muscle_in_vivo_validation.png", "Predicted vs in-vivo L4-L5 intradiscal pressure.")
        self.csv_table(T + "in_vivo_validation.csv", "In-vivo validation: predicted and measured IDP per activity")
        self.csv_table(T + "muscle_model_segment_loads.csv", "Segmental loads of the musculoskeletal model")
        self.csv_table(T + "flexion_relaxation.csv", "Flexion-relaxation: active and passive muscle forces")
        self.csv_table(T + "muscle_capacity.csv", "Muscle capacity: sagittal moments about each level and the "
                       "largest extension moment of the active fascicles")
        self.csv_table(T + "sensitivity_idp.csv", "Sensitivity of L4-L5 IDP to the muscle parameters")
        self.csv_table(T + "sensitivity_directions.csv", "The paper's sensitivity statements: stated and simulated "
                       "direction of the L4-L5 IDP change")
        sobol, cols = T + "sobol_indices.csv", ["posture", "parameter", "S1", "S1_lo", "S1_hi", "ST", "ST_lo", "ST_hi",
                                                "q2_loo", "n_train", "stable"]   # the rest: caption and CSV
        try:
            have = list(pd.read_csv(self.path(sobol), nrows=0).columns) if self.has(sobol) else []
        except (ValueError, pd.errors.ParserError):
            have = []
        self.csv_table(sobol, "Sobol indices of L4-L5 IDP (polynomial chaos expansion; S1/ST_lo-hi: bootstrap 95 % "
                       "intervals)", columns=cols if set(cols) <= set(have) else None)
        for f in figs:
            if _norm(f) not in self.shown:
                name = Path(f).stem.replace("muscle_", "").replace("_", " ")
                self.figure(f, f"Muscle study: {name}.")

    # -- discrepancy
    def discrepancy_section(self):
        any_d = any(p.startswith(D) for p in self.inputs) or self.has(F + "discrepancy_benchmark.png")
        if not any_d:
            self.doc.add(Para(f"Discrepancy workflow: {NOT_BUILT}.", "note"))
            return
        self.real_data_section()
        for case, label in DISCOVERY_CASES:
            base = f"{D}{case}/"
            sur = self.sr_surrogate if case == "default" else self._file_surrogate(base + "discovery.json")
            self.doc.add(Heading(f"Case: {label}" + (" [SURROGATE reference data]" if sur else ""), 2))
            if not self.has(base + "discovery.json"):
                self.doc.add(Para(f"Discovery for case '{case}': {NOT_BUILT}.", "note"))
                continue
            d = json.loads(self.path(base + "discovery.json").read_text())
            self.shown.add(_norm(base + "discovery.json"))
            keys = ("experiment", "n_scenarios", "named_effect", "parameter_estimate", "gap_before", "gap_after",
                    "gap_reduction", "p_value", "null_distribution_size", "confidence", "gap_after_above_threshold",
                    "decision", "measured")
            rows = [[k, fmt(d[k])] for k in keys if k in d]
            self.table_block(f"Discovery, case '{case}'", ["quantity", "value"], rows,
                             source=base + "discovery.json", surrogate=sur)
            if self.has(base + "section.md"):
                self.shown.add(_norm(base + "section.md"))
                self._markdown(self.path(base + "section.md").read_text(), f"case '{case}'", sur,
                               base + "section.md")
            else:
                ranking = d.get("ranking")
                if isinstance(ranking, list) and ranking:
                    if isinstance(ranking[0], Mapping):
                        keys = list(dict.fromkeys(k for r in ranking for k in r))
                        rows = [[fmt(r.get(k)) for k in keys] for r in ranking[:20]]
                    else:
                        keys = ["rank", "effect", "criterion"]
                        rows = [[str(i)] + [fmt(x) for x in (r if isinstance(r, (list, tuple)) else [r])]
                                for i, r in enumerate(ranking[:20], 1)]
                    self.table_block(f"Ranking of candidate effects, case '{case}'", keys, rows,
                                     source=base + "discovery.json", surrogate=sur)
            for name, cap in (("disagreement_map", "Where the model disagrees with the experiment"),
                              ("ranking", "Candidate effects ranked by how much of the gap they explain"),
                              ("before_after", "Model vs experiment before and after adding the named effect")):
                if self.has(base + f"{name}.png"):
                    self.figure(base + f"{name}.png", f"{cap} (case '{case}').", sur)
        self.doc.add(Heading("Benchmark: planted effects on SURROGATE data", 2))
        self.figure(F + "discrepancy_benchmark.png", "Discrepancy benchmark: recovery of planted effects "
                    "(SURROGATE data).", True)
        if self.has(D + "benchmark_summary.json"):
            d = json.loads(self.path(D + "benchmark_summary.json").read_text())
            self.table_block("Discrepancy benchmark summary", ["quantity", "value"],
                             [[k, fmt(v)] for k, v in _flatten(d)], source=D + "benchmark_summary.json",
                             surrogate=True)
        else:
            self.missing("Benchmark summary (benchmark_summary.json)")
        self.csv_table(D + "benchmark.csv", "Discrepancy benchmark cases", surrogate=True)

    def real_data_section(self):
        """"What the model is missing, on real data": generated from results/discrepancy/real_data_summary.csv."""
        rel = D + "real_data_summary.csv"
        self.doc.add(Heading("What the model is missing, on real data", 2))
        if not self.has(rel):
            self.missing("Discovery on real measurements (real_data_summary.csv)")
            return
        t = _read_csv(self.path(rel))
        t = t.astype(object).where(t.notna(), "")            # empty cells as "" (fillna("") on float columns warns)
        named = t[t["named_effect"].astype(str) != ""]
        few = t[t["note"].astype(str).str.contains("too few rows")]
        text = (f"The discrepancy discovery ran on {len(t)} published dataset(s) the model is compared with. ")
        if len(named):
            text += "Named: " + "; ".join(
                f"{r.dataset}: {r.named_effect} ({r.estimate}, p = {fmt(r.p_value)}; gap {fmt(r.gap_before, 3)} -> "
                f"{fmt(r.gap_after, 3)})" for r in named.itertuples()) + ". "
        else:
            text += "On none of them is a missing effect named at the configured level. "
        if len(few):
            text += ("Too few rows to name anything: " + ", ".join(f"{r.dataset} ({r.n_rows} row(s))"
                                                                  for r in few.itertuples()) + ". ")
        rest = t[(t["named_effect"].astype(str) == "") & ~t.index.isin(few.index)]
        dec = rest["decision"].astype(str)
        for label, sel in (("Tested, nothing named (consistent with the model and specimen variation, or a nuisance "
                            "explains it)", ~dec.str.startswith("unexplained")),
                           ("Tested, unexplained (the data differ from the model and neither a library effect nor a "
                            "nuisance explains it: something the library does not hold is missing)",
                            dec.str.startswith("unexplained"))):
            if sel.any():
                text += (label + ": " + ", ".join(f"{r.dataset} (gap {fmt(r.gap_before, 3)})"
                                                  for r in rest[sel].itertuples()) + ". ")
        text = text.rstrip()
        self.doc.add(Para(text))
        self.csv_table(rel, "Discovery on real measurements", surrogate=False)

    def _markdown(self, text: str, where: str, surrogate: bool, source: str):
        """A small Markdown text (headings, bullets, pipe tables, paragraphs) as report blocks; image
        references are left out (the figures are shown by themselves)."""
        def clean(s):
            return re.sub(r"[*`]", "", s).strip()
        lines = text.splitlines()
        i, para, bullets = 0, [], []

        def flush():
            if para:
                self.doc.add(Para(clean(" ".join(para))))
                para.clear()
            if bullets:
                self.doc.add(Bullets([clean(b) for b in bullets]))
                bullets.clear()
        while i < len(lines):
            s = lines[i].strip()
            if not s or s.startswith("!["):
                flush()
            elif s.startswith("#"):
                flush()
                self.doc.add(Heading(clean(s.lstrip("#")), 3))
            elif s.startswith(("- ", "* ")):
                if para:
                    flush()
                bullets.append(s[2:])
            elif s.startswith("|"):
                flush()
                rows = []
                while i < len(lines) and lines[i].strip().startswith("|"):
                    cells = [clean(c) for c in lines[i].strip().strip("|").split("|")]
                    if not all(re.fullmatch(r":?-{2,}:?", c) for c in cells if c):
                        rows.append(cells)
                    i += 1
                if rows:
                    self.table_block(f"Discrepancy table, {where}", rows[0], rows[1:], source=source,
                                     surrogate=surrogate)
                continue
            else:
                if bullets:
                    flush()
                para.append(s)
            i += 1
        flush()

    def other_figures(self):
        rest = sorted(p for p in self.inputs if p.endswith(".png") and p not in self.shown and self.has(p))
        if not rest:
            self.doc.add(Para("Every figure of this configuration is shown above.", "small"))
        else:
            for p in rest:
                self.figure(p, f"{Path(p).stem.replace('_', ' ')}.", _mentions_surrogate(p))

    # -- provenance
    def provenance_section(self):
        self.doc.add(Para(
            "Kinds: original_text / original_figure = printed in (or read off a figure of) one of the two papers; "
            "third_party = another publication (cited in source); derived_from_published_fit = computed from "
            "published values; surrogate = a labelled stand-in where nothing is published, never a result."))
        sr = self._cfg("stepwise_reduction", default={}) or {}
        l2 = self._cfg("l2s1", default={}) or {}
        rows = []
        for role, measured, surrogate, derived in (
                ("stepwise reduction ROM reference (Tables 1, 3, 4; Figs. 4-6)", sr.get("measured_table"),
                 "results/experiments/stepwise_reduction_surrogate.csv", sr.get("disc_only_derived")),
                ("L2-S1 IDP reference (Table 5, Fig. 7)", l2.get("measured_table"),
                 "results/experiments/idp_wilke1996_surrogate.csv", None)):
            if measured:
                rows.append([role, str(measured), "measured (user-supplied table)", self._kinds_of(measured)])
            else:
                rows.append([role, surrogate, "surrogate", self._kinds_of(surrogate)])
            if derived:
                rows.append([role + ", disc-only stage", str(derived), "derived_from_published_fit",
                             self._kinds_of(derived)])
        self.table_block("Experiment tables: measured, derived from a published fit, or surrogate",
                         ["role", "table", "class", "kinds in the file"], rows)
        drows = []
        for rel in sorted(p for p in self.inputs if p.startswith("data/") and p.endswith(".csv")):
            if not self.has(rel):
                continue
            try:
                df = _read_csv(self.path(rel))
            except (ValueError, pd.errors.ParserError) as e:
                drows.append([rel, "?", f"(not readable as CSV: {' '.join(str(e).split())[:80]})", ""])
                continue
            kinds = [c for c in df.columns if c == "kind" or c.endswith("_kind")]
            srcs = [c for c in df.columns if c == "source" or c.endswith("_source")]
            kind_txt = "; ".join(
                ", ".join(f"{k}: {n}" for k, n in df[c].fillna("(empty)").value_counts(sort=False).items())
                for c in kinds) or "(no kind column)"
            uniq = list(dict.fromkeys(str(v) for c in srcs for v in df[c].dropna()))
            src_txt = "; ".join(u if len(u) <= 110 else u[:107] + "..." for u in uniq[:3])
            if len(uniq) > 3:
                src_txt += f" (+{len(uniq) - 3} more)"
            drows.append([rel, str(len(df)), kind_txt, src_txt])
        if drows:
            self.table_block("Hand-curated inputs (data/): rows per kind and their sources",
                             ["file", "rows", "kind", "source"], drows)
        else:
            self.doc.add(Para(f"Data tables: {NOT_BUILT} (no data/*.csv among the inputs).", "note"))
        pub = self._cfg("paths", "published_model_results")
        self.doc.add(Para(f"Published model results (the paper's counts beside ours) are read at run time from "
                          f"{pub} (not redistributed): "
                          + ("present." if self.published else "not present in this run, paper columns empty.")))

    def _kinds_of(self, rel) -> str:
        p = self.inputs.get(_norm(rel)) or Path(rel)
        if not Path(p).is_file():
            return "(file not present)"
        df = _read_csv(p)
        c = "kind" if "kind" in df else "data_kind" if "data_kind" in df else None
        return ", ".join(f"{k}: {n}" for k, n in df[c].value_counts(sort=False).items()) if c else "(no kind column)"

    def config_appendix(self):
        self.table_block("Configuration used (every key)", ["key", "value"],
                         [[k, fmt(v, 8)] for k, v in _flatten(self.config)])
        rows = []
        for rel in sorted(self.inputs):
            p = self.inputs[rel]
            if p.is_file():
                rows.append([rel, str(p.stat().st_size), hashlib.sha256(p.read_bytes()).hexdigest()[:16]])
            elif p.is_dir():
                rows.append([rel, "(directory)", ""])
            else:
                rows.append([rel, f"({NOT_BUILT})", ""])
        self.table_block("Input files of this report (SHA-256, first 16 hex digits)", ["file", "bytes", "sha256"],
                         rows)


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
    an output of ``final_outputs()`` or ``REPORT_OPTIONAL`` in workflow/rules/common.smk), else it is reported
    as "not built in this configuration". Re-registering an anchor replaces that section."""
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


for _anchor, _title, _method, _numbered in (
        ("validation", "Validation on real data", "scoreboard_section", False),
        ("flags", "Flags: what needs attention", "flags_section", False),
        ("summary", "Summary", "summary", False),
        ("methods", "Methods (generated from the configuration)", "methods", True),
        ("models", "Models", "model_section", True),
        ("calibration", "Calibration on the stepwise reduction (backwards)", "calibration_section", True),
        ("forward", "Forward simulation of the stepwise reduction", "forward_section", True),
        ("idp", "Intradiscal pressure in the L2-S1 spine with wire cables", "idp_section", True),
        ("muscles", "Paraspinal muscles and spinal loading (paper 2)", "muscle_section", True),
        ("discrepancy", "Where model and experiment disagree (discrepancy workflow)", "discrepancy_section", True),
        ("figures", "Further figures", "other_figures", False),
        ("provenance", "Data provenance", "provenance_section", False),
        ("appendix", "Appendix: configuration and input files", "config_appendix", False)):
    report_section(_anchor, _title, numbered=_numbered)(getattr(ReportBuilder, _method))
