"""Parameter sets of the passive elements (disc, facet joints, ligaments).

All sets share the intervertebral-disc parameters (Table 1 and Sect. 2.2.2 of
the specification paper) and the facet parameters (Sect. 2.2.3); they differ
in the ligament laws:

* ``calibrated``, ``chazal1985``, ``shirazi_adl1986``, ``white_panjabi1990``,
  ``nolte1990``: Eq. 7 softplus laws (Table 3 / Appendix 1) with the prestrains
  of Sect. 2.2.4;
* ``rupp2015``: the nonlinear-to-linear law of Rupp et al. (2015), Appendix 1,
  with its own prestrains.

Data live in ``data/characteristics`` (see its README.md). The directory is
found from ``data_dir``, else ``$LUMBAR_DATA_DIR`` (the repository ``data``
directory, or the ``characteristics`` directory itself), else the package data
(:func:`lumbar.inputs.resources.data_dir`: the checkout's or the wheel's copy), else ``./data/characteristics``.

Units: SI at load (m, N, N*m, rad) - except the softplus parameters, which stay
in the paper's units [N, %] because Eq. 7 is defined in percent strain.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from fractions import Fraction
from pathlib import Path
from typing import Mapping

from lumbar.inputs import resources, tables
from lumbar.mechanics.elements.ligament import slack_length
from lumbar.inputs.io import TableError, TableSchema, read_table
from lumbar.inputs.tables import CHARACTERISTIC_SETS, LIGAMENT_KINDS

__all__ = [
    "CHARACTERISTIC_SETS",
    "LIGAMENT_KINDS",
    "EXPECTED_LIGAMENTS",
    "CharacteristicsError",
    "DiscParams",
    "FacetParams",
    "SoftplusLaw",
    "RuppLaw",
    "CharacteristicSet",
    "load_characteristic_set",
    "rupp_shape_parameters",
    "default_data_dir",
    "CHARACTERISTIC_TABLES",
]

DISC_DIRECTIONS = ("flexion", "extension", "lateral_bending", "axial_rotation")

# the files of a characteristic directory that load_characteristic_set reads
DISC_TABLE, FACET_TABLE = "disc.csv", "facet.csv"
PRESTRAIN_TABLE, SOFTPLUS_TABLE, RUPP2015_TABLE = "ligament_prestrain.csv", "ligaments_softplus.csv", "ligaments_rupp2015.csv"
RUPP2015_SHAPE_TABLE = "rupp2015_shape_check.csv"     # the paper's calculated Rupp shape parameters (a check)
#: the tables load_characteristic_set reads for a softplus set (every set but rupp2015) and for rupp2015: the workflow
#: declares them as the inputs of a rule that loads a set (workflow/rules/common.smk, characteristic_tables)
CHARACTERISTIC_TABLES = {"softplus": (DISC_TABLE, FACET_TABLE, PRESTRAIN_TABLE, SOFTPLUS_TABLE),
                         "rupp2015": (DISC_TABLE, FACET_TABLE, RUPP2015_TABLE)}

#: Ligament kinds each set must provide, and the documented reason for each absence.
ABSENT_LIGAMENTS: dict[str, dict[str, str]] = {
    "calibrated": {"ITL": "Table 3 has no ITL row: the paper's ITL characteristic is non-validated "
                          "(the stepwise-reduction experiment did not measure the ITL)"},
    "chazal1985": {"CL": "CL was not investigated by Chazal et al. (1985) (paper, Appendix 1)"},
    "shirazi_adl1986": {},
    "white_panjabi1990": {"ITL": "White and Panjabi (1990) give no ITL curve (paper, Appendix 1)"},
    "nolte1990": {"ITL": "no ITL parameters in the paper's Nolte et al. (1990) table (Appendix 1)"},
    "rupp2015": {},
}
EXPECTED_LIGAMENTS: dict[str, tuple[str, ...]] = {
    s: tuple(k for k in LIGAMENT_KINDS if k not in ABSENT_LIGAMENTS[s]) for s in CHARACTERISTIC_SETS
}

# unit -> factor to SI, per parameter family
_LEN = {"m": 1.0, "mm": 1e-3}
_STIFF = {"N/m": 1.0, "N/mm": 1e3}


class CharacteristicsError(TableError):
    """Invalid or missing characteristic data (a ``ValueError``)."""


# ------------------------------------------------------------------ dataclasses
@dataclass(frozen=True)
class DiscParams:
    """Intervertebral disc (SI units).

    Axial: F_z = k_axial_quadratic * r**2 + k_axial_linear * r for compression
    r >= 0 [m]; k_tension [N/m] in axial tension (0: the paper's disc transmits no
    traction). torque[direction] = (p1 [N*m], p2 [rad^3], p3 [N*m/rad]) of Eq. 3,
    T = p1*tanh(phi**3/p2) + p3*phi; lateral_bending and axial_rotation are
    symmetric, flexion/extension separate. k_shear [N/m]: the paper gives no number; the
    published lumbar motion-segment range found is ``k_shear_range`` (N/m) and the default is
    its midpoint (a project decision), unless a ``shear_stiffness`` row or an override
    ``{"disc.k_shear": value}`` is given.
    """

    k_axial_quadratic: float
    k_axial_linear: float
    k_shear: float | None
    k_tension: float
    torque: dict[str, tuple[float, float, float]]
    damping_translational: float
    damping_rotational: float
    k_shear_range: tuple[float, float] | None = None
    source: str = ""


@dataclass(frozen=True)
class FacetParams:
    """Facet joint contact (SI): stiffness [N/m], damping [N*s/m].

    ``surface_paper[side][p]`` holds the paper's Table 2 regression coefficients
    (paper frame, mm-based units, for comparison only; never used by the model).
    """

    stiffness: float
    damping: float
    surface_paper: dict[str, dict[str, float]] = field(default_factory=dict)
    source: str = ""


class _PrestrainInPercent:
    """A ligament law whose table gives ``prestrain_pct`` [%]: ``prestrain`` is the strain the mechanics use."""

    @property
    def prestrain(self) -> float:
        """The prestrain as a strain (fraction): ``prestrain_pct / 100``, the one conversion from the tables' %."""
        return self.prestrain_pct / 100.0


@dataclass(frozen=True)
class SoftplusLaw(_PrestrainInPercent):
    """Eq. 7: F(eps) = a * ln(exp((eps + b)/d) + 1) + c, eps in percent.

    EXCEPTION to the SI rule: a, c in N and b, d in % (the paper's units), because
    Eq. 7 is defined in percent strain. prestrain_pct in %. Note the paper's
    calibrated FL (d < 0) and the 'SSL neg.' alternative (a < 0) have negative
    slope: this is published data, not an error.

    ``law_length_m`` [m] (optional): the law is defined on ELONGATION. eps = 100 * (l - l0) / law_length,
    the slack length of every fibre l0 = l_ref - prestrain * law_length (l_ref its reference length), so
    the force depends on how far the fibre is stretched in mm, whatever the fibre's own length (the
    transfer of a law between geometries whose fibres differ in length, docs/validity.md). ``None``: the
    paper's own rule, eps in percent of each fibre's slack length l0 = l_ref / (1 + prestrain).
    """

    a: float
    b: float
    c: float
    d: float
    prestrain_pct: float
    source: str = ""
    law_length_m: float | None = None

    @property
    def pre_elongation_m(self) -> float | None:
        """Elongation beyond slack at the reference length [m] of a law on elongation (None otherwise)."""
        return None if self.law_length_m is None else self.prestrain * self.law_length_m


@dataclass(frozen=True)
class RuppLaw(_PrestrainInPercent):
    """Rupp et al. (2015) nonlinear-to-linear law inputs (SI): l_a_m, l_b_m [m]
    (elongations of the Chazal tuples), f_a_n, f_b_n [N] (whole ligament),
    n_strands (fibres representing one ligament), prestrain_pct [%].
    Shape parameters per fibre: :func:`rupp_shape_parameters`."""

    l_a_m: float
    l_b_m: float
    f_a_n: float
    f_b_n: float
    n_strands: int
    prestrain_pct: float
    source: str = ""


@dataclass(frozen=True)
class CharacteristicSet:
    name: str
    disc: DiscParams
    facet: FacetParams
    ligaments: dict[str, SoftplusLaw | RuppLaw]
    source: str
    absent: dict[str, str] = field(default_factory=dict)  # kind -> reason
    alternatives: dict[str, SoftplusLaw] = field(default_factory=dict)  # e.g. calibrated "SSL neg."


def rupp_shape_parameters(law: RuppLaw, l_set_m: float) -> dict[str, float]:
    """Shape parameters of one fibre of in-situ length ``l_set_m`` [m] (paper, Appendix 1).

    l0 = l_set/(1+eps0); dU_nll = l_A/l0; dF0 = F_A/n;
    dU_l = dF0/l0 * (l_B-l_A)/((F_B-F_A)/n); nu = dU_nll/dU_l;
    K_nl = dF0/(dU_nll*l0)**nu [N/m**nu]; K_l = dF0/(dU_l*l0) [N/m].
    """
    if not (math.isfinite(l_set_m) and l_set_m > 0):
        raise ValueError(f"l_set_m must be a positive finite length in m, got {l_set_m!r}")
    n = law.n_strands
    l0 = slack_length(l_set_m, law.prestrain)
    du_nll = law.l_a_m / l0
    df0 = law.f_a_n / n
    du_l = df0 / l0 * (law.l_b_m - law.l_a_m) / ((law.f_b_n - law.f_a_n) / n)
    nu = du_nll / du_l
    return {
        "l0": l0,
        "dU_nll": du_nll,
        "nu": nu,
        "K_nl": df0 / (du_nll * l0) ** nu,
        "K_l": df0 / (du_l * l0),
        "dF0": df0,
        "dU_l": du_l,
    }


# ------------------------------------------------------------------ data dir
def default_data_dir() -> Path:
    env = os.environ.get("LUMBAR_DATA_DIR")
    candidates = []
    if env:
        e = Path(env)
        candidates += [e / "characteristics", e]
    candidates.append(resources.data_dir() / "characteristics")
    candidates.append(Path.cwd() / "data" / "characteristics")
    for c in candidates:
        if (c / DISC_TABLE).is_file():
            return c
    raise CharacteristicsError(
        candidates[0], "characteristics data directory not found",
        expected="a directory containing disc.csv (set LUMBAR_DATA_DIR to the repository 'data' dir); "
                 f"tried {[str(c) for c in candidates]}")


# parameter -> (allowed units -> SI factor, sign constraint) ; sign: "pos", "nonneg", "nonzero", None
_DISC_PARAMS = {
    "torque_p1": ({"N*m": 1.0}, None),
    "torque_p2": ({"rad^3": 1.0}, "nonzero"),
    "torque_p3": ({"N*m/rad": 1.0}, None),
    "axial_quadratic": ({"N/m^2": 1.0, "N/mm^2": 1e6}, "nonneg"),
    "axial_linear": (_STIFF, "nonneg"),
    "axial_tension": (_STIFF, "nonneg"),
    "damping_translational": ({"N*s/m": 1.0, "N*s/mm": 1e3}, "nonneg"),
    "damping_rotational": ({"N*m*s": 1.0, "N*m*s/rad": 1.0}, "nonneg"),
    "shear_stiffness_min": (_STIFF, "pos"),
    "shear_stiffness_max": (_STIFF, "pos"),
    "shear_stiffness": (_STIFF, "pos"),
}
_FACET_PARAMS = {
    "stiffness": (_STIFF, "pos"),
    "damping": ({"N*s/m": 1.0, "N*s/mm": 1e3}, "nonneg"),
    "p30": ({"1/mm^2": 1.0}, None), "p03": ({"1/mm^2": 1.0}, None),
    "p20": ({"1/mm": 1.0}, None), "p02": ({"1/mm": 1.0}, None), "p00": ({"mm": 1.0}, None),
}
_SOFTPLUS_UNITS = {"a": "N", "b": "%", "c": "N", "d": "%", "law_length": "mm", "prestrain": "%"}
_RUPP_PARAMS = {
    "l_a": (_LEN, "pos"), "l_b": (_LEN, "pos"), "f_a": ({"N": 1.0}, "pos"), "f_b": ({"N": 1.0}, "pos"),
    "prestrain": ({"%": 1.0}, None), "n_strands": ({"1": 1.0}, "pos"),
}
_SIGN_TEXT = {"pos": "a positive number", "nonneg": "a number >= 0", "nonzero": "a non-zero number"}

# physical range of every characteristic, in SI (softplus: N and % strain), generous around the published
# values: a value outside is a typo or a unit slip (e.g. a prestrain of 1e6 %), never a model choice
_BOUNDS = {
    "torque_p1": (-100.0, 100.0, "N*m"), "torque_p2": (-1.0, 1.0, "rad^3"), "torque_p3": (-1000.0, 1000.0, "N*m/rad"),
    "axial_quadratic": (0.0, 1e11, "N/m^2"), "axial_linear": (0.0, 1e8, "N/m"), "axial_tension": (0.0, 1e8, "N/m"),
    "shear_stiffness": (1e3, 1e7, "N/m"), "shear_stiffness_min": (1e3, 1e7, "N/m"),
    "shear_stiffness_max": (1e3, 1e7, "N/m"),
    "facet.stiffness": (0.0, 1e7, "N/m"),
    "prestrain": (-50.0, 50.0, "%"),
    "l_a": (0.0, 0.02, "m"), "l_b": (0.0, 0.02, "m"), "f_a": (0.0, 5000.0, "N"), "f_b": (0.0, 5000.0, "N"),
    "n_strands": (1.0, 20.0, "1"),
    "softplus.a": (-1e6, 1e6, "N"), "softplus.c": (-1e6, 1e6, "N"),
    "softplus.b": (-200.0, 200.0, "%"), "softplus.d": (-200.0, 200.0, "%"),
    # a law on elongation keeps its pre-elongation in percent of its law length: a short capsule slack by more than
    # half its law length at rest is a model value (the Remus et al. 2021 capsules are), a whole law length is the limit
    "softplus.law_length": (0.0, 200.0, "mm"), "softplus.prestrain": (-100.0, 100.0, "%"),
}


def _check_bounds(path, row, column, key, value, label=None):
    """Raise when ``value`` (SI) lies outside the physical range of characteristic ``key``."""
    lo, hi, unit = _BOUNDS[key]
    if not lo <= value <= hi:
        raise _err(path, row, column, f"{value!r} {unit} for {label or repr(key)} is outside its physical range",
                   f"a value in [{lo:g}, {hi:g}] {unit}")


def _no_duplicate(path, row, seen: set, key, column, what, expected):
    """Duplicate rows are an error (never last-wins)."""
    if key in seen:
        raise _err(path, row, column, f"duplicate row for {what}", expected)
    seen.add(key)


def _err(path, row, column, message, expected):
    return CharacteristicsError(path, message, row=row, column=column, expected=expected)


def _read(path: Path, schema: TableSchema):
    try:
        return read_table(path, schema)
    except CharacteristicsError:
        raise
    except TableError as exc:
        raise CharacteristicsError(exc.path, exc.message,
                                   row=exc.row, column=exc.column, expected=exc.expected) from None


def _check_sign(path, row, value, sign, param):
    ok = {"pos": value > 0, "nonneg": value >= 0, "nonzero": value != 0, None: True}[sign]
    if not ok:
        what = "negative stiffness/damping" if value < 0 else "invalid value"
        raise _err(path, row, "value", f"{what} {value!r} for parameter '{param}'", _SIGN_TEXT[sign])


def _si_value(path, row, param, value, unit, spec):
    units, sign = spec
    if unit not in units:
        raise _err(path, row, "unit", f"unit {unit!r} is not valid for parameter '{param}'",
                   "one of " + ", ".join(repr(u) for u in units))
    _check_sign(path, row, value, sign, param)
    return value * units[unit]


def _iter(df):
    for i, rec in enumerate(df.to_dict("records")):
        yield i + 1, rec


def _load_disc(d: Path) -> DiscParams:
    path = d / DISC_TABLE
    df = _read(path, tables.DISC)
    vals: dict[tuple[str, str], float] = {}
    for row, r in _iter(df):
        p = r["parameter"]
        if p not in _DISC_PARAMS:
            raise _err(path, row, "parameter", f"unknown parameter {p!r}",
                       "one of " + ", ".join(sorted(_DISC_PARAMS)))
        if p.startswith("torque_") and r["direction"] not in DISC_DIRECTIONS:
            raise _err(path, row, "direction", f"unknown direction {r['direction']!r}",
                       "one of " + ", ".join(DISC_DIRECTIONS))
        key = (p, r["direction"] if p.startswith("torque_") else "")
        if key in vals:
            raise _err(path, row, "parameter", f"duplicate parameter {key}", "each parameter once")
        vals[key] = _si_value(path, row, p, r["value"], r["unit"], _DISC_PARAMS[p])
        if p in _BOUNDS:
            _check_bounds(path, row, "value", p, vals[key], f"parameter '{p}'")
    need = [(f"torque_p{i}", dr) for dr in DISC_DIRECTIONS for i in (1, 2, 3)]
    need += [(p, "") for p in ("axial_quadratic", "axial_linear", "axial_tension",
                               "damping_translational", "damping_rotational")]
    for k in need:
        if k not in vals:
            raise _err(path, None, "parameter", f"missing row for parameter {k[0]!r}"
                       + (f" direction {k[1]!r}" if k[1] else ""),
                       "one row per parameter (and direction for torque_p1..p3)")
    rng = None
    if ("shear_stiffness_min", "") in vals and ("shear_stiffness_max", "") in vals:
        rng = (vals[("shear_stiffness_min", "")], vals[("shear_stiffness_max", "")])
    return DiscParams(
        k_axial_quadratic=vals[("axial_quadratic", "")],
        k_axial_linear=vals[("axial_linear", "")],
        # project decision: without a disc-only value in the sources, the default shear
        # stiffness is the midpoint of the sourced motion-segment range (data/characteristics/README.md)
        k_shear=vals.get(("shear_stiffness", ""), None if rng is None else 0.5 * (rng[0] + rng[1])),
        k_tension=vals[("axial_tension", "")],
        torque={dr: tuple(vals[(f"torque_p{i}", dr)] for i in (1, 2, 3)) for dr in DISC_DIRECTIONS},
        damping_translational=vals[("damping_translational", "")],
        damping_rotational=vals[("damping_rotational", "")],
        k_shear_range=rng,
        source=str(path),
    )


def _load_facet(d: Path) -> FacetParams:
    path = d / FACET_TABLE
    df = _read(path, tables.FACET)
    vals: dict[str, float] = {}
    surface: dict[str, dict[str, float]] = {}
    seen: set = set()
    for row, r in _iter(df):
        p = r["parameter"]
        if p not in _FACET_PARAMS:
            raise _err(path, row, "parameter", f"unknown parameter {p!r}",
                       "one of " + ", ".join(sorted(_FACET_PARAMS)))
        key = p if p in ("stiffness", "damping") else (p, r["side"])
        _no_duplicate(path, row, seen, key, "parameter", f"parameter {p!r}"
                      + ("" if isinstance(key, str) else f" side {r['side']!r}"),
                      "each parameter once (surface coefficients once per side)")
        v = _si_value(path, row, p, r["value"], r["unit"], _FACET_PARAMS[p])
        if p == "stiffness":
            _check_bounds(path, row, "value", "facet.stiffness", v, "parameter 'stiffness'")
        if p in ("stiffness", "damping"):
            vals[p] = v
        else:
            surface.setdefault(r["side"], {})[p] = v
    for p in ("stiffness", "damping"):
        if p not in vals:
            raise _err(path, None, "parameter", f"missing row for parameter {p!r}", "one row per parameter")
    return FacetParams(stiffness=vals["stiffness"], damping=vals["damping"], surface_paper=surface,
                       source=str(path))


def _load_prestrain(d: Path) -> dict[str, float]:
    path = d / PRESTRAIN_TABLE
    df = _read(path, tables.LIGAMENT_PRESTRAIN)
    out = {}
    for row, r in _iter(df):
        if r["unit"] != "%":
            raise _err(path, row, "unit", f"unit {r['unit']!r} is not valid for a prestrain", "'%'")
        if r["ligament"] in out:
            raise _err(path, row, "ligament", f"duplicate row for ligament {r['ligament']!r}", "one row per ligament")
        _check_bounds(path, row, "prestrain", "prestrain", r["prestrain"], f"the prestrain of {r['ligament']}")
        out[r["ligament"]] = r["prestrain"]
    return out


def _load_softplus(d: Path, name: str, prestrain: dict[str, float]):
    path = d / SOFTPLUS_TABLE
    df = _read(path, tables.LIGAMENTS_SOFTPLUS)
    params: dict[tuple[str, str], dict[str, float]] = {}
    srcs: dict[tuple[str, str], str] = {}
    calibrated_kinds: dict[tuple[str, str], bool] = {}
    seen: set = set()
    for row, r in _iter(df):
        p = r["parameter"]
        if r["unit"] != _SOFTPLUS_UNITS[p]:
            raise _err(path, row, "unit", f"unit {r['unit']!r} is not valid for softplus parameter '{p}'",
                       f"'{_SOFTPLUS_UNITS[p]}' (Eq. 7 uses N and percent strain)")
        if p == "d" and r["value"] == 0:
            raise _err(path, row, "value", "d = 0 (division by zero in Eq. 7)", "a non-zero number")
        _check_bounds(path, row, "value", f"softplus.{p}", r["value"],
                      f"softplus parameter '{p}' of {r['set']} {r['ligament']}")
        if p == "law_length" and not r["value"] > 0:
            raise _err(path, row, "value", f"law_length {r['value']!r} mm is not positive",
                       "a length > 0 mm (the length on which the law's percent elongation is defined)")
        dkey = (r["set"], r["ligament"], r["variant"], p)
        if dkey in seen:
            raise _err(path, row, "parameter", f"duplicate row for (set, ligament, variant, parameter) {dkey}",
                       "each parameter once per set, ligament and variant")
        seen.add(dkey)
        if r["set"] != name:
            continue
        key = (r["ligament"], r["variant"])
        if p in params.setdefault(key, {}):
            raise _err(path, row, "parameter", f"duplicate parameter {p!r} for {key}", "each of a,b,c,d once")
        params[key][p] = r["value"]
        srcs[key] = r["source"]
        if str(r["kind"]).startswith("calibrated_on_"):
            calibrated_kinds[key] = True
    ligs, alts = {}, {}
    for kind in EXPECTED_LIGAMENTS[name]:
        if (kind, "primary") not in params:
            raise _err(path, None, "ligament", f"set '{name}' has no rows for ligament '{kind}'",
                       f"rows (set={name}, ligament={kind}, variant=primary, parameter=a|b|c|d)")
    for (kind, variant), pv in params.items():
        missing = [p for p in "abcd" if p not in pv]
        if missing:
            raise _err(path, None, "parameter", f"set '{name}' ligament '{kind}' ({variant}) lacks {missing}",
                       "one row for each of a, b, c, d")
        if kind in ABSENT_LIGAMENTS[name] and variant == "primary" and not calibrated_kinds.get((kind, variant)):
            raise _err(path, None, "ligament", f"set '{name}' has rows for '{kind}', which the paper "
                       f"does not provide ({ABSENT_LIGAMENTS[name][kind]})",
                       "no such rows (a calibration output, kind calibrated_on_*, may add them)")
        if kind not in prestrain and "prestrain" not in pv:
            raise _err(d / PRESTRAIN_TABLE, None, "ligament", f"no prestrain for '{kind}'",
                       "one row per ligament kind (or a 'prestrain' row of the set in ligaments_softplus.csv)")
        length = pv.get("law_length")
        law = SoftplusLaw(pv["a"], pv["b"], pv["c"], pv["d"], pv.get("prestrain", prestrain.get(kind)),
                          source=srcs[(kind, variant)], law_length_m=None if length is None else length * 1e-3)
        (ligs if variant == "primary" else alts)[kind] = law
    return ligs, alts


def _parse_printed(s: str) -> float:
    return float(sum((Fraction(t) for t in s.strip().strip("()").split()), Fraction(0)))


def _load_rupp(d: Path):
    path = d / RUPP2015_TABLE
    df = _read(path, tables.LIGAMENTS_RUPP2015)
    vals: dict[str, dict[str, float]] = {}
    srcs: dict[str, str] = {}
    for row, r in _iter(df):
        p = r["parameter"]
        try:
            printed = _parse_printed(r["value_as_printed"])
        except (ValueError, ZeroDivisionError):
            raise _err(path, row, "value_as_printed", f"cannot parse {r['value_as_printed']!r}",
                       "a number or mixed fraction such as '1 13/25' (optionally in parentheses)") from None
        if not math.isclose(printed, r["value"], rel_tol=1e-9, abs_tol=1e-12):
            raise _err(path, row, "value", f"{r['value']!r} disagrees with value_as_printed "
                       f"{r['value_as_printed']!r} (= {printed!r})", "the decimal value of value_as_printed")
        v = _si_value(path, row, p, r["value"], r["unit"], _RUPP_PARAMS[p])
        if p == "n_strands" and v != int(v):
            raise _err(path, row, "value", f"n_strands {v!r} is not an integer", "a positive integer")
        if p in vals.get(r["ligament"], {}):
            raise _err(path, row, "parameter", f"duplicate row for ligament {r['ligament']!r} parameter {p!r}",
                       "each parameter once per ligament")
        _check_bounds(path, row, "value", p, v, f"parameter '{p}' of {r['ligament']}")
        vals.setdefault(r["ligament"], {})[p] = v
        srcs[r["ligament"]] = r["source"]
    ligs = {}
    for kind in EXPECTED_LIGAMENTS["rupp2015"]:
        pv = vals.get(kind)
        if pv is None:
            raise _err(path, None, "ligament", f"no rows for ligament '{kind}'",
                       "rows for l_a, l_b, f_a, f_b, prestrain, n_strands per ligament")
        missing = [p for p in _RUPP_PARAMS if p not in pv]
        if missing:
            raise _err(path, None, "parameter", f"ligament '{kind}' lacks {missing}",
                       "rows for l_a, l_b, f_a, f_b, prestrain, n_strands")
        if not (pv["l_b"] > pv["l_a"] and pv["f_b"] > pv["f_a"]):
            raise _err(path, None, "value", f"ligament '{kind}': need l_b > l_a and f_b > f_a "
                       "(positive linear stiffness)", "l_a < l_b and f_a < f_b")
        ligs[kind] = RuppLaw(pv["l_a"], pv["l_b"], pv["f_a"], pv["f_b"], int(pv["n_strands"]),
                             pv["prestrain"], source=srcs[kind])
    return ligs


# ------------------------------------------------------------------ overrides
def _apply_overrides(cs: CharacteristicSet, overrides: Mapping[str, float]) -> CharacteristicSet:
    disc, facet, ligs = cs.disc, cs.facet, dict(cs.ligaments)
    disc_fields = {"k_axial_quadratic", "k_axial_linear", "k_shear", "k_tension",
                   "damping_translational", "damping_rotational"}
    for key, value in overrides.items():
        where = f"overrides[{key!r}]"
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise _err("<overrides>", None, key, f"{where} = {value!r} is not a number",
                       "a finite number in SI units (softplus: N / %)") from None
        if not math.isfinite(v):
            raise _err("<overrides>", None, key, f"{where} is not finite", "a finite number")
        parts = key.split(".")
        if parts[0] == "disc" and len(parts) == 2 and parts[1] in disc_fields:
            if v < 0 or (parts[1] == "k_shear" and v == 0):
                raise _err("<overrides>", None, key, f"negative/zero stiffness {v!r}", "a positive number")
            disc = replace(disc, **{parts[1]: v})
        elif parts[0] == "facet" and len(parts) == 2 and parts[1] in ("stiffness", "damping"):
            if v < 0 or (parts[1] == "stiffness" and v == 0):
                raise _err("<overrides>", None, key, f"negative/zero value {v!r}", "a positive number")
            facet = replace(facet, **{parts[1]: v})
        elif parts[0] == "ligaments" and len(parts) == 3 and parts[1] in ligs:
            law = ligs[parts[1]]
            names = {f for f in law.__dataclass_fields__ if f != "source"}
            if parts[2] not in names:
                raise _err("<overrides>", None, key, f"unknown field {parts[2]!r} for {type(law).__name__}",
                           "one of " + ", ".join(sorted(names)))
            ligs[parts[1]] = replace(law, **{parts[2]: int(v) if parts[2] == "n_strands" else v})
        else:
            raise _err("<overrides>", None, key, f"unknown override key {key!r}",
                       "'disc.<field>', 'facet.stiffness|damping' or 'ligaments.<KIND>.<field>' "
                       f"with KIND in {sorted(ligs)}")
    return replace(cs, disc=disc, facet=facet, ligaments=ligs)


# ------------------------------------------------------------------ public loader
def load_characteristic_set(name: str, data_dir=None,
                            overrides: Mapping[str, float] | None = None) -> CharacteristicSet:
    """Load one of :data:`CHARACTERISTIC_SETS` from ``data_dir`` (see module doc).

    ``overrides``: dotted keys in SI (softplus laws: paper units), e.g.
    ``{"disc.k_shear": 1.0e5, "facet.stiffness": 12000, "ligaments.ALL.prestrain_pct": 6}``.
    Raises :class:`CharacteristicsError` (a ValueError) naming file, row, column
    and the expected form.
    """
    if name not in CHARACTERISTIC_SETS:
        raise CharacteristicsError("<set name>", f"unknown characteristic set {name!r}",
                                   column="name", expected="one of " + ", ".join(CHARACTERISTIC_SETS))
    d = Path(data_dir) if data_dir is not None else default_data_dir()
    if not d.is_dir():
        raise CharacteristicsError(d, "data directory not found", expected="a directory containing disc.csv")
    disc = _load_disc(d)
    facet = _load_facet(d)
    alts: dict[str, SoftplusLaw] = {}
    if name == "rupp2015":
        ligs = _load_rupp(d)
        src = str(d / RUPP2015_TABLE)
    else:
        ligs, alts = _load_softplus(d, name, _load_prestrain(d))
        src = str(d / SOFTPLUS_TABLE)
    cs = CharacteristicSet(name=name, disc=disc, facet=facet, ligaments=ligs, source=src,
                           absent=dict(ABSENT_LIGAMENTS[name]), alternatives=alts)
    if overrides:
        cs = _apply_overrides(cs, overrides)
    return cs


def load_shape_check(data_dir=None):
    """The paper's calculated Rupp shape parameters (rupp2015_shape_check.csv) as a DataFrame."""
    d = Path(data_dir) if data_dir is not None else default_data_dir()
    return _read(d / RUPP2015_SHAPE_TABLE, tables.RUPP2015_SHAPE_CHECK)


# ------------------------------------------------------------------ one resolver of a characteristic set
def resolve_characteristic_set(name: str, data_dir=None, calibrated_dir=None, overrides=None) -> CharacteristicSet:
    """The one place that decides where a characteristic set comes from (every stage asks it).

    ``"calibrated"`` comes from ``calibrated_dir`` (the workflow's calibration output, role
    calibration.characteristics of the stage manifests, fitted on the geometry it runs on) when that directory holds a
    disc.csv, else from ``data_dir`` (data/characteristics: the paper's published Table 3 set, as printed).
    Every other name (the literature sets) comes from ``data_dir``. The facet stiffness and the disc shear
    stiffness are the set's own values (facet.csv / disc.csv); a caller overrides them only explicitly
    (``overrides``, or ``build_fsu(facet_stiffness_n_per_m=...)`` from the config key fsu.facet_stiffness_n_per_m).
    """
    if name == "calibrated" and calibrated_dir is not None and (Path(calibrated_dir) / DISC_TABLE).is_file():
        return load_characteristic_set(name, data_dir=calibrated_dir, overrides=overrides)
    return load_characteristic_set(name, data_dir=data_dir, overrides=overrides)
