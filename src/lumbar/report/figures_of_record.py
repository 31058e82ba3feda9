"""The figures of record: the numbers of a run that must not get worse quietly, read from its result files into one
JSON document, and the comparison of two such documents (the ratchet).

:func:`collect` reads a run's results root (:func:`lumbar.inputs.manifests.results_root`) and returns::

    {"note": ..., "figures": {name: {"value": v, "of": n, "direction": "higher" | "lower" | "informational",
                                     "tolerance": {"abs": x} | {"rel": x}, "file": path, "unit": ...}}}

``value`` is a number (a count, a rate, an R2, millimetres, seconds) or None with ``"absent": reason`` where the file
is not there (a stage switched off in the configuration) or does not hold the figure: an absent figure is an entry,
never an error. ``of``: the count a count is out of (a changed ``of`` is a changed basis, reported by the comparison).
``direction`` says which way is better; ``informational`` figures are never compared (the jobs' wall times: machines
differ, and speed is measured in ``benchmarks/``, ratios against a baseline of the same run).

:func:`compare` sets a run's figures beside a reference (a committed JSON of the same form): a figure worse than the
reference beyond its tolerance is a regression; one present in the reference and absent from the run is missing;
one better beyond its tolerance is an improvement (the reference should then be updated in the same commit). A
reference entry may carry ``"reason"`` (one line) and ``"was"`` (the value it replaced): the record of a worse value
accepted on purpose; a ``was`` worse-or-equal to ``value`` without a one-line reason is refused.

``python -m lumbar.report.figures_of_record`` writes the figures of a results folder to a file (``--out``; a file
that already holds ``records``, e.g. the release history ``figures_default.json`` of ``benchmarks/``, gets one record
per commit),
compares them with a reference (``--compare``) or prints the last two records side by side (``--markdown``).
Reads result files only (no solver, no mesh library)."""
from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path
from typing import Mapping

import pandas as pd

from ..experiments import validation as V
from ..inputs import manifests
from ..inputs.io import write_json_atomic

HIGHER, LOWER, INFO = "higher", "lower", "informational"
#: the note every figures document carries
NOTE = ("Figures of record of one run (lumbar.report.figures_of_record): value, which way is better (direction), the "
        "tolerance within which a worse value is not a regression, and the file it was read from. Job wall times "
        "(job_time_s.*) are informational: they depend on the machine and its load; speed targets are measured in "
        "benchmarks/ as ratios against a baseline of the same run.")
#: the folder of the jobs' Snakemake benchmark files under a run's results root (common.smk, benchmark_file)
BENCHMARKS = "benchmarks"
#: the first page may hold at most this many words before the scoreboard figure
FIRST_PAGE_MAX_WORDS = 250
#: the landmark-accuracy row whose median is a figure of record
LANDMARK_GROUP = "all ligament groups"

ROLE_SLUG = {V.INDEPENDENT: "independent", V.TARGET: "calibration_target", V.INTERNAL: "internal_load",
             V.CONSTRAINT: "internal_load_constraint"}


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", str(text).lower()).strip("_")


def _num(v):
    """A JSON number (int where integral counts are meant, float else; NaN and None as None)."""
    if v is None:
        return None
    if isinstance(v, bool):
        return int(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(f):
        return None
    return int(f) if float(f).is_integer() and not isinstance(v, float) else f


def figure(value, direction, file, tol=None, of=None, unit=None, note=None) -> dict:
    """One figure's entry. ``tol``: ("abs", x) or ("rel", x); None for an informational figure."""
    d = {"value": _num(value), "direction": direction, "file": str(file)}
    if tol is not None:
        d["tolerance"] = {tol[0]: tol[1]}
    if of is not None:
        d["of"] = _num(of)
    if unit:
        d["unit"] = unit
    if note:
        d["note"] = note
    return d


def absent(direction, file, why, tol=None, unit=None) -> dict:
    d = figure(None, direction, file, tol, unit=unit)
    d["absent"] = why
    return d


# ----------------------------------------------------------------------------------------------- the readers
class _Reader:
    """Collects figures from a results root; every reader says "absent" for a missing file or figure."""

    def __init__(self, root: str):
        self.root = str(root).rstrip("/")
        self.figures: dict[str, dict] = {}

    def out(self, stage, role, **fill) -> str:
        return manifests.path(stage, role, self.root, **fill)

    def exists(self, rel) -> bool:
        return Path(rel).is_file()

    def put(self, name, entry):
        self.figures[name] = entry

    def missing(self, names_dirs, rel, why=None):
        why = why or "file not in this run (stage not built in this configuration)"
        for name, direction, tol, unit in names_dirs:
            self.put(name, absent(direction, rel, why, tol, unit))

    # -- validation on real data: counts by role, the trivial models beside them, the other levels
    def validation(self):
        rel = self.out("validation", "scoreboard_table")
        roles = [(f"validation.{s}.within", HIGHER, ("abs", 0), "comparisons") for s in ROLE_SLUG.values()]
        if not self.exists(rel):
            self.missing(roles, rel)
        else:
            df = pd.read_csv(rel)
            counts = V.role_counts(V.distinct_comparisons(df)) if len(df) else {}
            for role, slug in ROLE_SLUG.items():
                name = f"validation.{slug}.within"
                if role in counts:
                    w, n = counts[role]
                    self.put(name, figure(w, HIGHER, rel, ("abs", 0), of=n, unit="comparisons",
                                          note=f"distinct comparisons of role '{role}' within their acceptance "
                                               "interval"))
                else:
                    self.put(name, absent(HIGHER, rel, f"no comparison of role '{role}' in this run", ("abs", 0),
                                          "comparisons"))
        rel = self.out("validation", "null_models")
        if not self.exists(rel):
            self.missing([("validation.null_models", INFO, None, None)], rel)
        else:
            t = pd.read_csv(rel)
            for r in t.itertuples(index=False):
                key = f"{_slug(r.quantity)}.{_slug(r.null_model)}"
                self.put(f"validation.null.{key}.within",
                         figure(r.null_within, INFO, rel, of=r.n_rows, unit="rows",
                                note=f"the trivial model '{r.description}' on the model's independent rows"))
                self.put(f"validation.beyond_null.{key}",
                         figure(int(r.model_within) - int(r.null_within), HIGHER, rel, ("abs", 0), of=r.n_rows,
                                unit="rows", note=f"the model's rows within ({int(r.model_within)}) minus the trivial "
                                                  f"model's ({int(r.null_within)})"))
        rel = self.out("validation", "multilevel_rom")
        name = "other_levels.within_25pct"
        if not self.exists(rel):
            self.missing([(name, HIGHER, ("abs", 0), "rows")], rel)
        else:
            t = pd.read_csv(rel)
            self.put(name, figure(int(t["within"].astype(bool).sum()), HIGHER, rel, ("abs", 0), of=len(t),
                                  unit="rows", note="the other levels' ROM at 10 N*m within 25 % of Yamamoto et al. "
                                                    "(1989), the calibrated characteristics applied unchanged"))

    # -- Tables 4 and 5: outliers per set
    def outliers(self):
        for stage, table, out_col, n_col in (("stepwise_reduction", "table4", "n_outliers", "n_scenarios"),
                                             ("l2s1", "table5", "outliers", "scenarios")):
            rel = self.out(stage, "counts")
            if not self.exists(rel):
                self.missing([(f"{table}.outliers", LOWER, ("abs", 0), "scenarios")], rel)
                continue
            t = pd.read_csv(rel)
            kind = "SURROGATE reference" if t.astype(str).apply(
                lambda c: c.str.contains("surrogate", case=False)).any().any() else "measured reference"
            for r in t.to_dict("records"):
                self.put(f"{table}.outliers.{r['set']}",
                         figure(r[out_col], LOWER, rel, ("abs", 0), of=r[n_col], unit="scenarios",
                                note=f"outliers against the {kind}"))

    # -- the discrepancy discovery's benchmark
    def discovery(self):
        rel = self.out("discovery", "benchmark_summary")
        names = [("discovery.library_accuracy", HIGHER, ("abs", 0.0), None),
                 ("discovery.library_named", HIGHER, ("abs", 0), "cases"),
                 ("discovery.naming_accuracy", HIGHER, ("abs", 0.0), None),
                 ("discovery.false_positives", LOWER, ("abs", 0), "nulls"),
                 ("discovery.out_of_library_unnamed", HIGHER, ("abs", 0), "cases")]
        if not self.exists(rel):
            self.missing(names, rel)
            return
        s = json.loads(Path(rel).read_text())
        lib = s.get("library_at_benchmark_magnitudes") or {}
        ool = s.get("out_of_library_unnamed") or {}
        self.put("discovery.library_accuracy",
                 figure(lib.get("rate"), HIGHER, rel, ("abs", 0.0),
                        note="share of the library effects named correctly at the benchmark magnitudes "
                             "(discovery.library_named: of how many)"))
        self.put("discovery.library_named",
                 figure(lib.get("k"), HIGHER, rel, ("abs", 0), of=lib.get("n"), unit="cases",
                        note="library effects named correctly at the benchmark magnitudes"))
        self.put("discovery.naming_accuracy",
                 figure(s.get("naming_accuracy"), HIGHER, rel, ("abs", 0.0),
                        note=f"share of every library case named correctly, near-threshold magnitudes included "
                             f"({s.get('n_library')} cases)"))
        self.put("discovery.false_positives",
                 figure(s.get("false_positives"), LOWER, rel, ("abs", 0), of=s.get("n_null"), unit="nulls",
                        note="nulls (no planted effect) for which an effect was named"))
        self.put("discovery.out_of_library_unnamed",
                 figure(ool.get("k"), HIGHER, rel, ("abs", 0), of=ool.get("n"), unit="cases",
                        note="causes outside the effect library left unnamed"))

    # -- the muscle-driven model against in-vivo IDP
    def muscle(self):
        rel = self.out("muscle_model", "metrics")
        names = [("muscle.in_vivo_r2", HIGHER, ("abs", 0.02), None),
                 ("muscle.certified_activities", HIGHER, ("abs", 0), "activities")]
        if not self.exists(rel):
            self.missing(names, rel)
            return
        m = json.loads(Path(rel).read_text())
        total = m.get("n_total", m.get("n"))
        if m.get("r2") is None:
            self.put("muscle.in_vivo_r2", absent(HIGHER, rel, "too few activities with a certified optimum for R2",
                                                 ("abs", 0.02)))
        else:
            self.put("muscle.in_vivo_r2", figure(m["r2"], HIGHER, rel, ("abs", 0.02),
                                                 note="R2 of the L4-L5 IDP over the activities with a certified "
                                                      "optimum (muscle.certified_activities)"))
        self.put("muscle.certified_activities", figure(m.get("n"), HIGHER, rel, ("abs", 0), of=total,
                                                       unit="activities",
                                                       note="in-vivo activities reached with a certified optimum"))

    # -- paper 2 claim by claim: reproduced claims per variant and class, the chains' fit to the muscle geometry
    def paper2(self):
        rel = self.out("muscle_model", "reproduction_counts")
        classes = ("all", "validation", "table1", "flexion_relaxation", "sensitivity_headline", "sensitivity_bound")
        variants = ("reproduction", "calibrated_chain")
        names = [(f"paper2.{v}.{c}.reproduced", HIGHER, ("abs", 0), "claims") for v in variants for c in classes]
        if not self.exists(rel):
            self.missing(names, rel)
        else:
            c = pd.read_csv(rel)
            for v in variants:
                for cls in classes:
                    r = c[(c["variant"] == v) & (c["claim_class"] == cls)]
                    name = f"paper2.{v}.{cls}.reproduced"
                    if r.empty:
                        self.put(name, absent(HIGHER, rel, f"no {v} rows of class {cls} in this run", ("abs", 0),
                                              "claims"))
                        continue
                    r = r.iloc[0]
                    self.put(name, figure(r["reproduced"], HIGHER, rel, ("abs", 0), of=r["comparable"],
                                          unit="claims", note=f"paper 2's {cls} claims reproduced (within x1.5 or "
                                          f"the stated bound) of the comparable ones, {v}"))
        rel = self.out("muscle_model", "chain_admissibility")
        names = [(f"paper2.{v}.levels_admissible", HIGHER, ("abs", 0), "levels") for v in variants]
        if not self.exists(rel):
            self.missing(names, rel)
            return
        a = pd.read_csv(rel)
        for v in variants:
            d = a[a["variant"] == v]
            name = f"paper2.{v}.levels_admissible"
            if d.empty:
                self.put(name, absent(HIGHER, rel, f"variant {v} not in this run", ("abs", 0), "levels"))
            else:
                self.put(name, figure(int(d["admissible"].sum()), HIGHER, rel, ("abs", 0), of=len(d), unit="levels",
                                      note="levels without facet overlap at rest that flex in 36 deg flexion"))

    # -- physical admissibility of the calibrated set
    def admissibility(self):
        rel = self.out("admissibility", "table")
        name = "admissibility.passed"
        if not self.exists(rel):
            self.missing([(name, HIGHER, ("abs", 0), "criteria")], rel)
            return
        t = pd.read_csv(rel)
        self.put(name, figure(int(t["passed"].astype(bool).sum()), HIGHER, rel, ("abs", 0), of=len(t),
                              unit="criteria", note="admissibility criteria the calibrated unit passes"))

    # -- automatic landmarks where the truth is known
    def landmarks(self):
        rel = self.out("landmark_accuracy", "summary")
        name = "landmark_accuracy.group_median_mm"
        if not self.exists(rel):
            self.missing([(name, LOWER, ("abs", 0.1), "mm")], rel)
            return
        t = pd.read_csv(rel).set_index("structure")
        if LANDMARK_GROUP not in t.index:
            self.put(name, absent(LOWER, rel, f"no row '{LANDMARK_GROUP}'", ("abs", 0.1), "mm"))
            return
        self.put(name, figure(float(t.loc[LANDMARK_GROUP, "median_mm"]), LOWER, rel, ("abs", 0.1), unit="mm",
                              note="median distance of the automatic ligament insertion-group centroids from the "
                                   "reference (leave one out)"))

    # -- the OpenSim export's check
    def opensim(self):
        rel = self.out("export_opensim", "check")
        names = [("opensim.detailed_max_difference_deg", LOWER, ("abs", 1e-3), "deg"),
                 ("opensim.reduced_max_relative_difference", LOWER, ("abs", 0.01), "-"),
                 ("opensim.scenarios_solved", HIGHER, ("abs", 0), "scenarios")]
        if not self.exists(rel):
            self.missing(names, rel)
            return
        t = pd.read_csv(rel)
        ok = t[t["status"] == "ok"]
        det = ok.loc[ok["variant"].str.startswith("detailed"), "difference_deg"].abs()
        red = ok.loc[ok["variant"] == "reduced", "relative_difference"].abs()
        self.put(names[0][0], figure(float(det.max()) if len(det) else None, LOWER, rel, ("abs", 1e-3), unit="deg",
                                     note="largest |ROM in OpenSim - ROM of the project's solver| of the exported "
                                          "detailed units, with and without facets"))
        self.put(names[1][0], figure(float(red.max()) if len(red) else None, LOWER, rel, ("abs", 0.01), unit="-",
                                     note="largest relative ROM difference of the reduced joint from the detailed "
                                          "unit (acceptance 0.10)"))
        self.put(names[2][0], figure(len(ok), HIGHER, rel, ("abs", 0), of=len(t), unit="scenarios",
                                     note="check scenarios both engines solved"))

    # -- the report's first page
    def first_page(self):
        rel = self.out("report", "html")
        name = "report.first_page_words"
        if not self.exists(rel):
            self.missing([(name, LOWER, ("abs", 10), "words")], rel)
            return
        scoreboard = Path(self.out("validation", "scoreboard")).name
        words = first_page_words(Path(rel).read_text(encoding="utf-8"), scoreboard)
        if words is None:
            self.put(name, absent(LOWER, rel, "the scoreboard figure is not in the report", ("abs", 10), "words"))
            return
        self.put(name, figure(words, LOWER, rel, ("abs", 10), unit="words",
                              note=f"words before the scoreboard figure (at most {FIRST_PAGE_MAX_WORDS})"))

    # -- every job's wall time (Snakemake benchmark: files)
    def job_times(self):
        folder = Path(self.root) / BENCHMARKS
        files = sorted(folder.rglob("*.tsv")) if folder.is_dir() else []
        if not files:
            self.put("job_time_s.total", absent(INFO, folder, "no benchmark files", unit="s"))
            return
        total = 0.0
        for p in files:
            try:
                s = float(pd.read_csv(p, sep="\t")["s"].iloc[-1])
            except (KeyError, IndexError, ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
                self.put(f"job_time_s.{p.relative_to(folder).with_suffix('').as_posix()}",
                         absent(INFO, p, "not a Snakemake benchmark file (no 's' column)", unit="s"))
                continue
            total += s
            self.put(f"job_time_s.{p.relative_to(folder).with_suffix('').as_posix()}",
                     figure(round(s, 3), INFO, p.as_posix(), unit="s"))
        self.put("job_time_s.total", figure(round(total, 3), INFO, folder.as_posix(), unit="s",
                                            note=f"sum over the {len(files)} benchmark files (jobs' time, not the "
                                                 "run's wall time)"))


def collect(root: str | Path = manifests.RESULTS_DIR, job_times: bool = True) -> dict:
    """The figures of record of the run under results root ``root`` (relative paths: from the working directory).
    A stage that is not in the run gives its figures as ``absent`` entries."""
    r = _Reader(str(root))
    r.validation()
    r.outliers()
    r.discovery()
    r.muscle()
    r.paper2()
    r.admissibility()
    r.landmarks()
    r.opensim()
    r.first_page()
    if job_times:
        r.job_times()
    return {"note": NOTE, "figures": dict(sorted(r.figures.items()))}


# ----------------------------------------------------------------------------------------------- the first page
class _FirstPage(HTMLParser):
    """The words of the report's body up to the scoreboard figure's image."""

    SKIP = {"head", "title", "style", "script"}

    def __init__(self, figure_name: str):
        super().__init__()
        self.figure_name, self.words, self.depth, self.done = figure_name, [], 0, False

    def handle_starttag(self, tag, attrs):
        if tag in self.SKIP:
            self.depth += 1
        if tag == "img" and str(dict(attrs).get("data-source", "")).endswith(self.figure_name):
            self.done = True

    def handle_endtag(self, tag):
        if tag in self.SKIP:
            self.depth = max(0, self.depth - 1)

    def handle_data(self, data):
        if not self.done and not self.depth:
            self.words += [w for w in data.split() if re.search(r"\w", w)]


def first_page_words(html_text: str, figure_name: str = "validation_scoreboard.png") -> int | None:
    """How many words the report's HTML holds before the scoreboard figure (title, abstract and whatever else comes
    first; a word: a run of non-space characters with a letter or digit). None when the figure is not there."""
    p = _FirstPage(figure_name)
    p.feed(html_text)
    return len(p.words) if p.done else None


# ----------------------------------------------------------------------------------------------- the ratchet
@dataclass
class Comparison:
    """The outcome of :func:`compare`: lines naming the figure, the reference ("old") and the run's ("new") value
    and the tolerance. ``regressions``, ``missing`` and ``invalid`` fail the ratchet; ``improvements`` and ``new``
    ask for the reference to be updated; ``accepted``: figures whose reference carries a reason."""
    regressions: list = field(default_factory=list)
    missing: list = field(default_factory=list)
    invalid: list = field(default_factory=list)
    improvements: list = field(default_factory=list)
    new: list = field(default_factory=list)
    accepted: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.regressions or self.missing or self.invalid)

    def failures(self) -> list[str]:
        return self.regressions + self.missing + self.invalid

    def report(self) -> str:
        parts = []
        for title, lines in (("worse than the reference beyond its tolerance", self.regressions),
                             ("in the reference, absent from this run", self.missing),
                             ("reference entries that are not valid", self.invalid),
                             ("better than the reference beyond its tolerance: update the reference in this commit",
                              self.improvements),
                             ("in this run, not in the reference: add them", self.new),
                             ("worse values accepted in the reference, with their reason", self.accepted)):
            if lines:
                parts.append(f"{title} ({len(lines)}):\n" + "\n".join(f"  {x}" for x in lines))
        return "\n".join(parts) or "every figure as the reference, within its tolerance"


def tolerance_of(entry: Mapping, old: float) -> float:
    """The tolerance of a figure as a value: ``{"abs": x}`` or ``{"rel": x}`` (of the reference value)."""
    tol = entry.get("tolerance") or {}
    if "abs" in tol:
        return float(tol["abs"])
    if "rel" in tol:
        return float(tol["rel"]) * abs(float(old))
    return 0.0


def _tol_text(entry: Mapping) -> str:
    tol = entry.get("tolerance") or {}
    return (f"tolerance {tol['abs']:g}" if "abs" in tol else f"tolerance {100 * tol['rel']:g} %" if "rel" in tol
            else "tolerance 0")


def _worse(direction: str, old: float, new: float, tol: float) -> bool:
    return new < old - tol if direction == HIGHER else new > old + tol if direction == LOWER else False


def _better(direction: str, old: float, new: float, tol: float) -> bool:
    return _worse(LOWER if direction == HIGHER else HIGHER, old, new, tol) if direction in (HIGHER, LOWER) else False


def _figures(doc: Mapping) -> Mapping:
    return doc.get("figures", doc) if isinstance(doc, Mapping) else {}


def compare(reference: Mapping, current: Mapping) -> Comparison:
    """The run's figures (``current``) against the ``reference`` (both documents of :func:`collect`'s form, or
    their ``figures``). Direction and tolerance are the reference's: the reference is the decision of record."""
    ref, cur = _figures(reference), _figures(current)
    res = Comparison()
    for name, r in ref.items():
        direction = r.get("direction", INFO)
        if direction not in (HIGHER, LOWER, INFO):
            res.invalid.append(f"{name}: direction {direction!r}; expected 'higher', 'lower' or 'informational'")
            continue
        reason = r.get("reason")
        if reason is not None and (not isinstance(reason, str) or not reason.strip() or "\n" in reason
                                   or len(reason) > 300):
            res.invalid.append(f"{name}: reason must be one line of text (at most 300 characters), got {reason!r}")
            continue
        old = r.get("value")
        if "was" in r and direction != INFO and old is not None and r["was"] is not None:
            if _worse(direction, float(r["was"]), float(old), 0.0) and not reason:
                res.invalid.append(f"{name}: the reference value {old} is worse than the value it replaced "
                                   f"({r['was']}) and gives no reason: add a one-line \"reason\" beside it")
                continue
        if reason:
            res.accepted.append(f"{name}: {old}" + (f" (was {r['was']})" if "was" in r else "") + f": {reason}")
        if direction == INFO:
            continue
        c = cur.get(name)
        if old is None:              # absent in the reference: nothing to hold the run to
            if c is not None and c.get("value") is not None:
                res.new.append(f"{name}: absent in the reference, now {c['value']}")
            continue
        if c is None or c.get("value") is None:
            why = "not in this run's figures" if c is None else f"absent: {c.get('absent', 'no value')}"
            res.missing.append(f"{name}: reference {old}, {why} ({r.get('file', '')})")
            continue
        new, tol = float(c["value"]), tolerance_of(r, float(old))
        of_old, of_new = r.get("of"), c.get("of")
        basis = (f" (out of {of_new}, was out of {of_old}: the basis changed, update the reference)"
                 if of_old is not None and of_new is not None and of_old != of_new else "")
        line = (f"{name}: old {old}, new {c['value']}, {_tol_text(r)} ({direction} is better; "
                f"{c.get('file', r.get('file', ''))}){basis}")
        if _worse(direction, float(old), new, tol):
            res.regressions.append(line)
        elif basis:
            res.invalid.append(line)
        elif _better(direction, float(old), new, tol):
            res.improvements.append(line)
    for name, c in _figures(current).items():
        if name not in ref and c.get("direction") != INFO and c.get("value") is not None:
            res.new.append(f"{name}: not in the reference, now {c['value']}")
    return res


# ----------------------------------------------------------------------------------------------- the reference
#: the note of a reference file (tests/reference/figures_test_config.json)
REFERENCE_NOTE = ("Reference figures of record (lumbar.report.figures_of_record.compare): a run's figure worse than "
                  "its value here beyond its tolerance fails the ratchet. Improving a figure: update this file in the "
                  "same commit (python -m lumbar.report.figures_of_record --results <root> --update-reference <this "
                  "file>). Accepting a worse one: the same command keeps the old value as 'was' and adds an empty "
                  "'reason', which must be filled with one line before the ratchet passes. Job times are "
                  "informational (machines differ): only their total is kept, never compared.")
#: the fields of a figure that a reference keeps
_KEPT = ("value", "of", "direction", "tolerance", "unit", "file", "note", "absent")


def update_reference(reference: Mapping | None, current: Mapping) -> dict:
    """A new reference from a run's figures (``current``; ``reference``: the old one, or None). Every figure but the
    single jobs' times (their total stays, informational). A figure worse than the old reference beyond its
    tolerance keeps the old value as ``was`` and gets an empty ``reason`` to be filled in (:func:`compare` refuses
    it until then); an entry whose value is unchanged keeps its ``was`` and ``reason``."""
    old, cur = _figures(reference or {}), _figures(current)
    out = {}
    for name, c in cur.items():
        if name.startswith("job_time_s.") and name != "job_time_s.total":
            continue
        e = {k: c[k] for k in _KEPT if k in c}
        r = old.get(name)
        if r is not None and r.get("value") is not None and c.get("value") is not None:
            if r.get("value") == c.get("value"):
                e.update({k: r[k] for k in ("was", "reason") if k in r})
            elif _worse(r.get("direction", INFO), float(r["value"]), float(c["value"]),
                        tolerance_of(r, float(r["value"]))):
                e.update(was=r["value"], reason="")
        out[name] = e
    return {"note": REFERENCE_NOTE, "figures": dict(sorted(out.items()))}


# ----------------------------------------------------------------------------------------------- records
def git_commit(cwd=".") -> str | None:
    """The working tree's commit (short hash, ``+dirty`` for uncommitted changes), None outside a git checkout."""
    try:
        h = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=cwd, capture_output=True, text=True,
                           timeout=30)
        if h.returncode != 0:
            return None
        d = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd, capture_output=True,
                           text=True, timeout=30)
        return h.stdout.strip() + ("+dirty" if d.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


def write_figures(doc: Mapping, path, commit: str | None = None) -> dict:
    """Write a figures document to ``path``. A file that holds ``records`` (a history, e.g.
    ``figures_default.json`` in the repository's benchmarks folder) keeps them and gets this run as the record of ``commit`` (default:
    the working tree's), replacing an earlier record of the same commit; any other path gets the document."""
    p = Path(path)
    old = json.loads(p.read_text()) if p.is_file() else None
    if isinstance(old, Mapping) and "records" in old:
        commit = commit or git_commit() or "unknown"
        rec = {"commit": commit, "figures": dict(doc["figures"])}
        records = [x for x in old["records"] if x.get("commit") != commit] + [rec]
        out = dict(old, records=records)
    else:
        out = dict(doc)
    write_json_atomic(out, p)
    return out


def _fmt_value(e: Mapping | None) -> str:
    if e is None:
        return "-"
    v = e.get("value")
    if v is None:
        return "absent"
    s = f"{v:.3g}" if isinstance(v, float) and not float(v).is_integer() else f"{v:g}"
    return s + (f" of {e['of']:g}" if e.get("of") is not None else "")


def side_by_side(history: Mapping, n: int = 2, job_times: bool = False) -> str:
    """The last ``n`` records of a history as a Markdown table (figure, direction, one column per commit); job
    times left out unless ``job_times``."""
    recs = list(history.get("records", []))[-n:]
    if not recs:
        return "(no records yet)\n"
    names = list(dict.fromkeys(k for r in recs for k in r["figures"]))
    if not job_times:
        names = [k for k in names if not k.startswith("job_time_s.") or k == "job_time_s.total"]
    head = "| figure | better | " + " | ".join(f"`{r['commit']}`" for r in recs) + " |"
    lines = [head, "| --- | --- | " + " | ".join("---" for _ in recs) + " |"]
    for k in names:
        d = next((r["figures"][k].get("direction") for r in reversed(recs) if k in r["figures"]), "")
        lines.append(f"| `{k}` | {d} | " + " | ".join(_fmt_value(r["figures"].get(k)) for r in recs) + " |")
    return "\n".join(lines) + "\n"


#: the markers of the side-by-side table in docs/benchmarks.md (:func:`doc_with_table`)
DOC_BEGIN, DOC_END = "<!-- figures of record: begin (written by --markdown --doc) -->", "<!-- figures of record: end -->"


def doc_with_table(text: str, history: Mapping) -> str:
    """A Markdown document's ``text`` with the block between :data:`DOC_BEGIN` and :data:`DOC_END` replaced by the
    last two records of ``history`` side by side (a ValueError when the markers are not there)."""
    i, j = text.find(DOC_BEGIN), text.find(DOC_END)
    if i < 0 or j < i:
        raise ValueError(f"the document has no block between {DOC_BEGIN!r} and {DOC_END!r}")
    return text[:i + len(DOC_BEGIN)] + "\n\n" + side_by_side(history) + "\n" + text[j:]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m lumbar.report.figures_of_record", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default=manifests.RESULTS_DIR, help="the run's results root (default: results)")
    ap.add_argument("--out", help="write the figures here (a file holding 'records' gets one record per commit)")
    ap.add_argument("--commit", help="the commit the record is of (default: the working tree's)")
    ap.add_argument("--compare", metavar="REFERENCE", help="compare the figures with this reference JSON; exit 1 on "
                                                            "a regression or a missing figure")
    ap.add_argument("--update-reference", metavar="REFERENCE", help="rewrite this reference with the figures "
                                                                     "(update_reference: a worse one needs a reason)")
    ap.add_argument("--markdown", metavar="HISTORY", help="print the last two records of HISTORY side by side")
    ap.add_argument("--doc", help="with --markdown: write the table into this Markdown file, between its markers")
    a = ap.parse_args(argv)
    if a.markdown:
        history = json.loads(Path(a.markdown).read_text())
        if a.doc:
            Path(a.doc).write_text(doc_with_table(Path(a.doc).read_text(), history))
        else:
            sys.stdout.write(side_by_side(history))
        return 0
    doc = collect(a.results)
    if a.out:
        write_figures(doc, a.out, a.commit)
    if a.update_reference:
        p = Path(a.update_reference)
        new = update_reference(json.loads(p.read_text()) if p.is_file() else None, doc)
        write_json_atomic(new, p)
        todo = [k for k, v in new["figures"].items() if v.get("reason") == ""]
        if todo:
            print(f"{p}: worse than before, write a one-line reason beside: {', '.join(todo)}")
    if a.compare:
        res = compare(json.loads(Path(a.compare).read_text()), doc)
        print(res.report())
        return 0 if res.ok else 1
    if not (a.out or a.update_reference):
        print(json.dumps(doc, indent=2, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
