"""Identity of the results: the test-config DAG writes the same result tables as the reference run
(tests/data/results_sha256_test_config.json: SHA-256 of the tables of every stage except the Sobol indices and
the two *_vs_paper tables, whose paper columns come from ../shared; tests/data/results_test_config.tar.gz: the
tables themselves). A table whose bytes differ is compared cell by cell with the reference: floating-point
round-off differs between CPUs and BLAS builds (the manifest of 2ed2998 was not reproduced byte for byte on
another machine of the same kind, by the same code), so where the bytes differ every text and flag cell must be
equal and every number within a relative 1e-6 of its scale (the column's largest magnitude among rows of the same
unit): far below any change a refactoring could make by mistake, far above round-off. Tables downstream of a
least-squares fit compare their numbers to RTOL_FIT / ATOL_FIT (see there: the fits amplify round-off), their flags
exactly. A refactoring must leave it green; a change meant to change results re-writes the reference and says so in
its commit. Re-writing the reference is one line from the repository root (runs the test-config DAG in a fresh
copy, as the test session does, then writes both files):

    python tests/data/results_manifest.py --run
"""
import importlib.util
import io
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("results_manifest", HERE / "data" / "results_manifest.py")
rm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rm)


def test_manifest_checker_detects_a_changed_table(tmp_path):
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "a.csv").write_text("x\n1\n")
    (tmp_path / "tables" / "sobol_indices.csv").write_text("excluded\n")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "t.csv").write_text("excluded\n")
    assert rm.covered(tmp_path) == ["tables/a.csv"]
    before = rm.digest(tmp_path / "tables" / "a.csv")
    (tmp_path / "tables" / "a.csv").write_text("x\n1.0\n")
    assert rm.digest(tmp_path / "tables" / "a.csv") != before


RTOL = 1e-6     # of a value's scale (see numeric_differences)
#: Tables downstream of a least-squares fit (the calibration, the surrogate generators' anchoring on the real rows,
#: the discovery's fits): their numbers are compared to RTOL_FIT of the value plus ATOL_FIT of its scale. The fits
#: amplify round-off: a relative change at machine precision in a residual moves a fitted parameter that the targets
#: barely constrain (the facet stiffness) in its fourth significant digit, and the optimiser then stops at another
#: point of its tolerance region (docs/design.md, "The compiled solver core"). Measured on the test config, the
#: numpy reference path of the solver against the compiled one (the same arithmetic in another order, as another
#: CPU or BLAS build gives): at most 1.1e-3 of a value (the fitted facet stiffness; 1.9e-4 for the stepwise ROM,
#: 1.6e-4 for the validation table), and entries near zero (a nearly slack ligament's force) within 6.9e-4 of their
#: column's scale. RTOL_FIT and ATOL_FIT leave a factor of about 5 and 3 above that. Their text and flag columns
#: (passed, within, outlier, decision, named_effect, ...) are compared exactly, as every table's: a flag at its
#: threshold that flips between machines is a finding to look at, not round-off.
RTOL_FIT = 5e-3
ATOL_FIT = 2e-3
#: Rows of a scenario with wire cables (a ``muscle_setup`` other than ``none``): the cable attachments come from an ICP
#: registration of the myo-sim vertebrae onto the geometry (``l2s1.register_vertebra``), whose fixed point moves with
#: round-off: on one machine, OpenBLAS's Haswell and SkylakeX kernels gave registrations that differ by 2e-5 to 7e-4
#: (matrix entries, also when the ICP is run to a fixed point) and IDP tables of the published Rupp set that differ
#: by up to 2.3e-4 of a column's largest value (rows without cables: identical). Those rows are compared to this
#: fraction of their column's scale (the documented exception; AVX-512 / OpenBLAS kernel choice).
RTOL_REGISTRATION = 2e-3
#: A solver's residual (columns named ``*residual*``) is round-off at convergence: its digits differ between CPUs and
#: BLAS builds (1e-14 ... 1e-10 N or N*m), so it is compared as a quantity that must stay at the reference's level:
#: within RESIDUAL_FACTOR x the reference column's largest magnitude, not digit by digit.
RESIDUAL_FACTOR = 10.0
#: Columns that count the optimiser's work, not a result: a fit that stops at another point of its tolerance region
#: takes another number of steps (measured: 21 -> 3x evaluations of a stepwise calibration step between the two solver
#: paths). Not compared.
PATH_COLUMNS = ("n_evaluations",)
#: The fit's active penalty terms at its optimum (calibration_penalties.csv: one-sided hinges, each the small
#: difference of two nearly equal quantities, so a move of the optimum inside its tolerance region changes them by a
#: larger share: measured up to 9 % between the two solver paths, "disc stays compressed" 0.00247 -> 0.00225 of a
#: largest 0.0053): RTOL_PENALTY of the value plus ATOL_FIT of the scale. Whether a penalty is active (0 or not) is
#: what the table is read for; a penalty appearing or vanishing beyond that fails.
PENALTY_TABLES = ("calibration/calibration_penalties.csv",)
RTOL_PENALTY = 0.2
#: Tables no fit touches (the published literature sets, the geometry). table2_facet_surfaces.csv is not one of them:
#: it prints the calibrated facet stiffness beside the surfaces.
FIT_INDEPENDENT = ("rupp2015", "chazal1985", "shirazi_adl1986", "white_panjabi1990", "nolte1990",
                   "tables/fsu_geometry.csv")


def fit_dependent(rel: str) -> bool:
    return not any(k in rel for k in FIT_INDEPENDENT)


#: unit suffixes of column names (``PLL_moment_z_nm``: N*m): columns of one unit share one scale
UNIT_SUFFIXES = ("nm", "n", "deg", "mm", "mm2", "mpa", "m", "rad", "s")


def _unit_of(column: str) -> str:
    tail = column.rsplit("_", 1)[-1].lower() if "_" in column else ""
    return tail if tail in UNIT_SUFFIXES else ""


def _scale(a: pd.DataFrame, xf: np.ndarray, column: str | None = None) -> np.ndarray:
    """Per row: the largest magnitude among the rows of the same unit (a ``unit`` column: one column may hold mm^2 and
    degrees, as the validation table's ``sim``); else among every column of the table with the column's unit suffix
    (a column of round-off, e.g. the moment of a slack ligament about an axis it cannot load, ~1e-7 N*m, is compared
    at the scale of the table's moments, not at its own); else of the whole column. Infinite values are no scale."""
    mag = np.where(np.isfinite(xf), np.abs(xf), np.nan)
    if "unit" in a.columns:
        s = pd.Series(mag).groupby(a["unit"].astype(str).to_numpy()).transform("max").to_numpy(float)
    elif column is not None and _unit_of(column):
        cols = [c for c in a.columns if _unit_of(c) == _unit_of(column) and pd.api.types.is_numeric_dtype(a[c])
                and not pd.api.types.is_bool_dtype(a[c])]
        v = np.abs(a[cols].to_numpy(float))
        v = v[np.isfinite(v)]
        s = np.full(len(xf), float(v.max()) if v.size else 0.0)
    else:
        s = np.full(len(xf), np.nanmax(mag) if np.isfinite(mag).any() else 0.0)
    return np.where(np.isfinite(s), s, 0.0)


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _text_same(x: str, y: str, close) -> bool:
    """Text cells: equal, or equal in their words with the numbers printed in them (a fitted law's "a=37.324 N, ...")
    equal by ``close(ref, now, scale)`` (the table's numeric tolerance; scale: the cell's largest number). A flag or a
    category word is compared exactly."""
    if x == y:
        return True
    if _NUMBER.split(x) != _NUMBER.split(y):
        return False
    nx, ny = [float(v) for v in _NUMBER.findall(x)], [float(v) for v in _NUMBER.findall(y)]
    scale = max((abs(v) for v in nx), default=0.0)          # the cell's own scale (near-zero numbers beside it)
    return len(nx) == len(ny) and all(close(a, b, scale) for a, b in zip(nx, ny))


def numeric_differences(ref: bytes, now: bytes, rtol=RTOL, fit=False, rtol_fit=None) -> list[str]:
    """Where two CSV tables differ beyond round-off: columns, row count, every text and flag cell (exactly), numbers
    (NaN = NaN) to ``rtol`` of their scale (:func:`_scale`); ``fit``: a table downstream of a fit, its numbers to
    RTOL_FIT of the value plus ATOL_FIT of the scale. Rows with cables are compared to max(that, RTOL_REGISTRATION of
    the scale), residual columns to RESIDUAL_FACTOR x their level."""
    a, b = pd.read_csv(io.BytesIO(ref)), pd.read_csv(io.BytesIO(now))
    if list(a.columns) != list(b.columns):
        return [f"columns {list(a.columns)} -> {list(b.columns)}"]
    if len(a) != len(b):
        return [f"rows {len(a)} -> {len(b)}"]
    cable = (a["muscle_setup"].astype(str) != "none").to_numpy() if "muscle_setup" in a.columns \
        else np.zeros(len(a), bool)
    out = []
    for c in a.columns:
        x, y = a[c], b[c]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y) and not (
                pd.api.types.is_bool_dtype(x) or pd.api.types.is_bool_dtype(y)):
            xf, yf = x.to_numpy(float), y.to_numpy(float)
            scale = _scale(a, xf, c)
            if c in PATH_COLUMNS:
                continue
            if "residual" in c:
                level = np.nanmax(np.abs(xf)) if np.isfinite(xf).any() else 0.0
                ok = np.abs(yf) <= RESIDUAL_FACTOR * max(level, 1e-300)
            else:
                tol = (rtol_fit or RTOL_FIT) * np.abs(xf) + ATOL_FIT * scale if fit else rtol * scale
                tol = np.where(cable, np.maximum(tol, RTOL_REGISTRATION * scale), tol)
                with np.errstate(invalid="ignore"):                  # inf - inf; decided on the next line
                    ok = np.abs(xf - yf) <= np.maximum(tol, 1e-300)
            ok = np.where(np.isinf(xf) | np.isinf(yf), xf == yf, ok)       # an infinity only equals itself
            same = (np.isnan(xf) & np.isnan(yf)) | ok
            if not same.all():
                k = int(np.flatnonzero(~same)[0])
                out.append(f"{c}: {int((~same).sum())} values, e.g. row {k}: {xf[k]!r} -> {yf[k]!r}")
        else:
            def close(u, v, scale):
                tol = (rtol_fit or RTOL_FIT) * abs(u) + ATOL_FIT * scale if fit else rtol * scale
                return abs(u - v) <= tol + 1e-300
            xs, ys = [str(v) for v in x], [str(v) for v in y]
            bad = [k for k in range(len(xs)) if not _text_same(xs[k], ys[k], close)]
            if bad:
                out.append(f"{c}: text row {bad[0]}: {x.iloc[bad[0]]!r} -> {y.iloc[bad[0]]!r}")
    return out


def test_numeric_comparison_tolerates_round_off_only():
    ref = b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,,5,True\n"
    assert numeric_differences(ref, ref) == []
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0000000000000002,3,True\nb,2.5e-3,4,False\nc,,5,True\n") == []
    assert numeric_differences(ref, b"name,v,n,ok\na,1.00001,3,True\nb,2.5e-3,4,False\nc,,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,True\nc,,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,0.1,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\n")
    assert numeric_differences(ref, b"name,w,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,,5,True\n")


def test_residual_columns_and_cable_rows_have_their_own_tolerance():
    """A residual at round-off may change its digits but not grow to another level; rows with cables (behind an
    ICP registration) tolerate RTOL_REGISTRATION, rows without cables keep RTOL."""
    ref = b"muscle_setup,v,residual_force_n\nnone,1.0,3e-10\nall,2.0,1e-10\n"
    assert numeric_differences(ref, b"muscle_setup,v,residual_force_n\nnone,1.0,2e-10\nall,2.0,2.9e-9\n") == []
    assert numeric_differences(ref, b"muscle_setup,v,residual_force_n\nnone,1.0,3e-10\nall,2.0,4e-9\n")
    assert numeric_differences(ref, b"muscle_setup,v,residual_force_n\nnone,1.0,3e-10\nall,2.002,1e-10\n") == []
    assert numeric_differences(ref, b"muscle_setup,v,residual_force_n\nnone,1.0,3e-10\nall,2.006,1e-10\n")
    assert numeric_differences(ref, b"muscle_setup,v,residual_force_n\nnone,1.001,3e-10\nall,2.0,1e-10\n")


def test_fit_dependent_tables_compare_numbers_to_the_fit_tolerance_and_flags_exactly():
    ref = b"name,v,ok\na,1.0,True\nb,2.0,False\n"
    assert numeric_differences(ref, b"name,v,ok\na,1.003,True\nb,2.004,False\n", fit=True) == []
    assert numeric_differences(ref, b"name,v,ok\na,1.0,True\nb,2.0,True\n", fit=True)          # a flag flipped
    assert numeric_differences(ref, b"name,v,ok\na,1.01,True\nb,2.0,False\n", fit=True)        # 1 % of a value
    assert numeric_differences(ref, b"name,v,ok\na,1.0,True\n", fit=True)
    # near zero, ATOL_FIT of the column's scale: 0.001 of 2000 moves by 3 (1.5e-3 of the scale), not by 5
    ref = b"v\n0.001\n2000.0\n"
    assert numeric_differences(ref, b"v\n3.0\n2000.0\n", fit=True) == []
    assert numeric_differences(ref, b"v\n5.0\n2000.0\n", fit=True)
    assert fit_dependent("calibration/calibration_real_fit.csv") and not fit_dependent("l2s1/idp_rupp2015.csv")


def test_scale_is_per_unit_where_a_column_mixes_units():
    """The validation table's ``sim`` holds mm^2 (about 1800) and degrees (about 5): a degree row is compared to the
    scale of the degree rows, not to 5 % (or 1e-6) of the area."""
    ref = b"unit,sim,within\nmm2,1800.0,True\ndeg,4.61,True\n"
    assert numeric_differences(ref, b"unit,sim,within\nmm2,1800.0,True\ndeg,4.62,True\n", fit=True) == []
    assert numeric_differences(ref, b"unit,sim,within\nmm2,1800.0,True\ndeg,4.77,True\n", fit=True)
    assert numeric_differences(ref, b"unit,sim,within\nmm2,1800.0,True\ndeg,4.61,False\n", fit=True)


def test_reference_snapshot_matches_the_manifest():
    snap = rm.read_snapshot()
    manifest = json.loads(rm.MANIFEST.read_text())
    assert sorted(snap) == sorted(manifest)
    import hashlib
    assert all(hashlib.sha256(snap[k]).hexdigest() == manifest[k] for k in manifest)


@pytest.mark.workflow
def test_result_tables_identical_to_reference(dag_workdir):
    manifest = json.loads(rm.MANIFEST.read_text())
    snap = rm.read_snapshot()
    results = Path(dag_workdir) / "results"
    now = {rel: rm.digest(results / rel) for rel in rm.covered(results)}
    assert sorted(now) == sorted(manifest), (
        f"tables added {sorted(set(now) - set(manifest))}, missing {sorted(set(manifest) - set(now))}")
    bytes_differ = sorted(k for k in manifest if now[k] != manifest[k])
    changed = {k: d for k in bytes_differ if (d := numeric_differences(
        snap[k], (results / k).read_bytes(), fit=fit_dependent(k),
        rtol_fit=RTOL_PENALTY if k in PENALTY_TABLES else None))}
    assert not changed, (f"result tables changed beyond round-off: {changed} (re-write the reference only for an "
                         f"intended change); {len(bytes_differ)} tables differ in their bytes")


def test_numbers_printed_in_text_are_compared_as_numbers_and_words_exactly():
    ref = b'name,law\na,"a=37.324 N, b=-10.06 %"\nb,"both facets: 0.0109 -> 364 N"\n'
    assert numeric_differences(ref, b'name,law\na,"a=37.325 N, b=-10.06 %"\nb,"both facets: 0.0112 -> 364 N"\n',
                               fit=True) == []
    assert numeric_differences(ref, b'name,law\na,"a=37.9 N, b=-10.06 %"\nb,"both facets: 0.0109 -> 364 N"\n', fit=True)
    assert numeric_differences(ref, b'name,law\na,"a=37.324 N, c=-10.06 %"\nb,"both facets: 0.0109 -> 364 N"\n',
                               fit=True)
    assert numeric_differences(ref, b'name,law\na,"a=37.325 N, b=-10.06 %"\nb,"both facets: 0.0109 -> 364 N"\n')


def test_a_round_off_column_is_compared_at_its_units_scale_and_equal_infinities_are_equal():
    ref = b"disc_moment_y_nm,PLL_moment_z_nm,measured_high\n5.0,1.355e-07,inf\n"
    assert numeric_differences(ref, b"disc_moment_y_nm,PLL_moment_z_nm,measured_high\n5.0,1.340e-07,inf\n",
                               fit=True) == []
    # controls: a real change of a moment, and an infinity that becomes finite, still fail
    assert numeric_differences(ref, b"disc_moment_y_nm,PLL_moment_z_nm,measured_high\n5.0,0.2,inf\n", fit=True)
    assert numeric_differences(ref, b"disc_moment_y_nm,PLL_moment_z_nm,measured_high\n5.0,1.355e-07,3.0\n",
                               fit=True)
