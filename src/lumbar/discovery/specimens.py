"""The null hypothesis with specimens in it: banks of virtual specimens of the nominal model and the null datasets
drawn from them.

A measured table is the mean of n real specimens, and a specimen is not the nominal model plus noise: the model is
nonlinear, so the mean of varied specimens differs from the nominal model (the *specimen-mean shift*), and one
specimen's stiffness moves all its rows together. The discovery's null hypothesis is therefore "n virtual specimens
of the nominal model (:class:`lumbar.experiments.virtual_experiment.SpecimenVariation` of the configuration) plus
measurement noise, summarised as the table is":

* a **bank** (:class:`SpecimenBank`) holds the response of K virtual specimens (no noise) in every compared
  scenario: :func:`rom_bank` (L4-L5 ROM, ``lumbar.experiments.virtual_experiment.rom_specimens``), :func:`idp_bank`
  (L2-S1 IDP, ``idp_specimens``); it is built once per configuration and scenario set (seeded, cached in the
  process; the workflow writes it to the role ``discovery.specimen_bank`` of the stage manifests, config
  ``discovery.specimen_bank_rom`` / ``specimen_bank_idp``);
* :func:`null_datasets` draws B null tables: per table the row's ``n_specimens`` distinct specimens of the bank
  (without replacement), their deviation from the bank mean scaled by the variation scale ``lam``, measurement noise
  of SD ``sqrt(a2 + b2 r^2)`` per specimen (r the bank mean), ROM values clipped at 0 as the generator does, and the
  table's summary (mean; ROM min/max -> sigma from the range, IDP SD -> sigma = SD / sqrt(n); rows without a spread
  keep the table's sigma). The bank mean r is itself uncertain (K specimens): the mean's deviation from r is scaled
  by ``sqrt((K + n) / (K - n))``, which gives it the variance sigma^2 (1/n + 1/K) that a table of n new specimens has
  about r (for draws without replacement from K; with replacement, when K < n, ``sqrt((1 + n/K) K / (K - 1))``).
  The bank's between-specimen variance is uncertain too (K - 1 degrees of freedom): each null table's specimen
  deviations are scaled by its own draw of sqrt((K - 1) / chi2(K - 1)), so the null integrates over the variances a
  bank of K is consistent with (a predictive draw; about 1.02 on average for K = 48, wider tails).
  This is the fast path; the reference path draws every null table from new specimens (``fresh=``: a second bank of
  at least B n specimens, partitioned), and ``tests/test_discover_null.py`` checks that both give the same p-values;
* :func:`fit_null_noise` estimates ``a2`` and ``b2`` from the table's own spread (min/max or SD, per specimen)
  against the bank's: where the table varies more than the virtual specimens, the excess variance is measurement
  noise, additive plus multiplicative, fitted by non-negative least squares. The variation scale ``lam`` stays 1:
  the rows of a table share its n specimens, so its spread says little more about the population's than n - 1
  values would (a table of similar specimens would shrink the null and make it anti-conservative); a table that
  varies less than the virtual specimens is reported (``table_to_bank_variance_ratio`` < 1) and tested against the
  wider null, which errs on the side of naming nothing.
"""
from __future__ import annotations

import functools
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import nnls

from ..experiments.fsu import MAIN_DIRECTIONS, STAGES, disc_shear_override
from ..experiments.l2s1 import LEVELS, derive_cables
from ..experiments.stepwise_reduction import scenario_grid
from ..experiments.virtual_experiment import SpecimenVariation, idp_specimens, rom_specimens
from ..geometry.configured import load_configured
from ..inputs.characteristics import resolve_characteristic_set
from ..inputs.io import Column, TableError, TableSchema, read_table, write_table_atomic
from ..mechanics.idp import DISC_AREA_M2
from .detect import benchmark_settings, discovery_settings

log = logging.getLogger(__name__)


#: experiments whose measured quantity cannot be negative (a range of motion, a nucleus pressure): a generator's
#: specimen value with noise is cut at 0 there, as a transducer reads it (the signed neutral angle is not)
NON_NEGATIVE = ("stepwise_rom", "idp_invitro", "in_vivo")

# expected range of n normal samples in SDs (d2 of quality control), n = 2..10; beyond 10: 3.078 (n = 10)
D2 = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326, 6: 2.534, 7: 2.704, 8: 2.847, 9: 2.970, 10: 3.078}
_D2 = np.array([np.nan, np.nan] + [D2[k] for k in range(2, 11)])

#: scenario keys of the experiments that have a specimen bank
BANK_KEYS = {"stepwise_rom": ("stage", "direction", "moment_nm"), "idp_invitro": ("muscle_setup", "load_case")}
#: seed offsets of the two specimen streams: the discovery's null bank and the benchmark's fixture specimens
#: (disjoint streams of the same population: a fixture is never made of the specimens its null is made of)
NULL_STREAM, FIXTURE_STREAM = 30, 31


def d2(n):
    """d2(n) of an array of specimen counts (NaN below 2)."""
    n = np.asarray(n)
    return _D2[np.clip(n, 0, 10).astype(int)]


@dataclass
class SpecimenBank:
    """Responses of K virtual specimens of the nominal model (no noise) in the scenarios ``keys``: ``values``
    (K, n) in the problem's unit, NaN where a specimen has no equilibrium."""

    experiment: str
    keys: pd.DataFrame
    values: np.ndarray
    source: str
    extra: dict = field(default_factory=dict)      # IDP: per-specimen disc moment (K, n), idp_per_newton_pa (K,)

    @property
    def K(self) -> int:
        return self.values.shape[0]

    @functools.cached_property
    def mean(self) -> np.ndarray:
        """Bank mean per scenario (NaN where fewer than half the specimens reached equilibrium: a limit of the
        model there, as ``stepwise_reduction_table`` leaves such rows out)."""
        ok = np.isfinite(self.values)
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.where(ok, self.values, 0.0).sum(0) / ok.sum(0)
        return np.where(ok.mean(0) >= 0.5, m, np.nan)

    @functools.cached_property
    def var(self) -> np.ndarray:
        """Between-specimen variance per scenario (ddof 1)."""
        ok = np.isfinite(self.values)
        d = np.where(ok, self.values - self.mean, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return (d ** 2).sum(0) / (ok.sum(0) - 1)

    def align(self, keys: pd.DataFrame) -> "SpecimenBank | None":
        """The bank restricted to (and ordered as) ``keys``; None when a scenario of ``keys`` is not in it."""
        cols = list(BANK_KEYS[self.experiment])
        idx = {k: i for i, k in enumerate(_key_tuples(self.keys, cols))}
        want = _key_tuples(keys, cols)
        if not all(k in idx for k in want):
            return None
        j = np.array([idx[k] for k in want], int)
        extra = {k: (v[:, j] if np.ndim(v) == 2 else v) for k, v in self.extra.items()}
        return SpecimenBank(self.experiment, keys[cols].reset_index(drop=True), self.values[:, j], self.source, extra)


def _key_tuples(df, cols):
    return [tuple(float(x) if c == "moment_nm" else str(x) for c, x in zip(cols, row))
            for row in df[cols].itertuples(index=False)]


# ------------------------------------------------------------------ building banks (the virtual experiments)
def _variation(config, section) -> SpecimenVariation:
    return SpecimenVariation(**(((config or {}).get(section) or {}).get("variation") or {}))


def _geometry(config, levels):
    g = (config or {}).get("geometry", {})
    return load_configured({"kind": "default", **g}, levels=list(levels))


def _charset(config):
    c = (config or {}).get("characteristics") or {}
    return resolve_characteristic_set(discovery_settings(config)["characteristic_set"], data_dir=c.get("data_dir"),
                                      calibrated_dir=c.get("calibrated_dir"))


def bank_seed(config, stream) -> tuple:
    """Seed of a specimen stream: (configuration seed, stream), a numpy SeedSequence entropy."""
    return (int((config or {}).get("seed", 0)), int(stream))


def rom_bank(config, keys: pd.DataFrame, n_specimens: int, stream=NULL_STREAM, variants=(({}, None),)):
    """ROM of ``n_specimens`` virtual specimens of the discovery's nominal L4-L5 model (geometry, characteristic
    set ``discovery.characteristic_set``, ``stepwise_reduction.variation``) in the scenarios ``keys``, for each
    variant (see ``rom_specimens``). Returns (values (K, G, n), converged)."""
    f = (config or {}).get("fsu") or {}
    level = f.get("level", "L4-L5")
    return rom_specimens(_geometry(config, [level]), _charset(config), bank_seed(config, stream), int(n_specimens),
                         keys[list(BANK_KEYS["stepwise_rom"])].reset_index(drop=True),
                         _variation(config, "stepwise_reduction"), variants, level=level,
                         k_shear=disc_shear_override(f),
                         max_iter=int(((config or {}).get("solver") or {}).get("max_iter", 50)))


def idp_bank_table(config, n_specimens: int, stream=NULL_STREAM, disc_scale=1.0, first=0) -> pd.DataFrame:
    """Per-specimen L2-S1 results of ``n_specimens`` virtual specimens of the discovery's nominal model
    (``l2s1.variation``; see ``lumbar.experiments.virtual_experiment.idp_specimens``), from specimen ``first`` of
    the stream on."""
    l2 = (config or {}).get("l2s1") or {}
    return idp_specimens(_geometry(config, LEVELS), _charset(config), bank_seed(config, stream), int(n_specimens),
                         _variation(config, "l2s1"), derive_cables(l2.get("cables")), l2.get("idp_formula", "paper1"),
                         l2.get("disc_area_m2", DISC_AREA_M2), disc_shear_override(config), disc_scale=disc_scale,
                         max_iter=int(((config or {}).get("solver") or {}).get("max_iter", 50)), first=first)


def rom_design(config, keys=None) -> pd.DataFrame:
    """The ROM scenarios a bank covers: every stage and direction at the moments of ``stepwise_reduction``, of the
    benchmark and of ``keys`` (the discovery's design space)."""
    m = set(map(float, ((config or {}).get("stepwise_reduction") or {}).get("moments_nm") or [1, 2.5, 5, 7.5, 10]))
    m |= set(map(float, benchmark_settings(config)["moments_nm"]))
    if keys is not None:
        m |= set(map(float, keys["moment_nm"]))
    return scenario_grid(STAGES, MAIN_DIRECTIONS, sorted(m)).reset_index(drop=True)


BANK_SCHEMAS = {
    "stepwise_rom": TableSchema("specimen_bank_rom", {
        "specimen": Column("int", min=0), "stage": Column("str", allowed=frozenset(STAGES)),
        "direction": Column("str", allowed=frozenset(MAIN_DIRECTIONS)), "moment_nm": Column("float", min=0.0),
        "rom_deg": Column("float", nullable=True, finite=False), "source": Column("str")}),
    "idp_invitro": TableSchema("specimen_bank_idp", {
        "specimen": Column("int", min=0), "muscle_setup": Column("str"), "load_case": Column("str"),
        "idp_mpa": Column("float", nullable=True, finite=False),
        "disc_moment_sagittal_nm": Column("float", nullable=True, finite=False),
        "idp_per_newton_pa": Column("float", min=0.0), "source": Column("str")}),
}


def bank_table(config, experiment, n_specimens, stream=NULL_STREAM) -> pd.DataFrame:
    """The null bank of ``experiment`` as a long table (one row per specimen and scenario; the workflow's
    role ``discovery.specimen_bank`` of the stage manifests)."""
    src = (f"virtual specimens of the nominal model (lumbar.discovery.specimens, seed {bank_seed(config, stream)}, "
           f"{int(n_specimens)} specimens, no measurement noise): the discrepancy discovery's null hypothesis; "
           f"SURROGATE, not data")
    if experiment == "stepwise_rom":
        keys = rom_design(config)
        vals, _ = rom_bank(config, keys, n_specimens, stream)
        K, n = vals.shape[0], len(keys)
        out = pd.concat([keys] * K, ignore_index=True)
        out.insert(0, "specimen", np.repeat(np.arange(K), n))
        out["rom_deg"] = vals[:, 0, :].ravel()
    elif experiment == "idp_invitro":
        t = idp_bank_table(config, n_specimens, stream)
        out = t[["specimen", "muscle_setup", "load_case", "idp_mpa", "disc_moment_sagittal_nm", "idp_per_newton_pa"]]
        out = out.copy()
    else:
        raise ValueError(f"no specimen bank for experiment {experiment!r}; banks: {sorted(BANK_KEYS)}")
    out["source"] = src
    return out


def bank_from_table(df: pd.DataFrame, experiment: str) -> SpecimenBank:
    """A :class:`SpecimenBank` from its long table (:func:`bank_table`)."""
    cols = list(BANK_KEYS[experiment])
    spec = np.sort(df["specimen"].unique())
    keys = df[df["specimen"] == spec[0]][cols].reset_index(drop=True)
    n = len(keys)
    if len(df) != len(spec) * n:
        raise ValueError(f"specimen bank: {len(df)} rows for {len(spec)} specimens x {n} scenarios")
    d = df.sort_values("specimen", kind="stable")
    vcol = "rom_deg" if experiment == "stepwise_rom" else "idp_mpa"
    vals = d[vcol].to_numpy(float).reshape(len(spec), n)
    extra = {}
    if experiment == "idp_invitro":
        extra = {"moment": d["disc_moment_sagittal_nm"].to_numpy(float).reshape(len(spec), n),
                 "per_n": d["idp_per_newton_pa"].to_numpy(float).reshape(len(spec), n)[:, 0]}
    return SpecimenBank(experiment, keys, vals, str(df["source"].iat[0]) if "source" in df else "", extra)


_READ_BANKS: dict = {}     # (path, size, mtime, experiment) -> SpecimenBank: a bank file is parsed once per process


def read_bank(path, experiment) -> SpecimenBank:
    """The bank file ``path`` (validated against its schema); parsed once per process and file version (a benchmark
    job runs one discovery per fixture, each on the same bank)."""
    p = Path(path).resolve()
    st = p.stat()
    key = (str(p), st.st_size, st.st_mtime_ns, experiment)
    if key not in _READ_BANKS:
        try:
            df = read_table(p, BANK_SCHEMAS[experiment])
        except TableError as e:
            raise ValueError(f"specimen bank: {e}") from e
        _READ_BANKS[key] = bank_from_table(df, experiment)
    return _READ_BANKS[key]


def write_bank(df: pd.DataFrame, path) -> Path:
    return write_table_atomic(df, path, float_format="%.9g")


_BANKS: dict = {}


def bank_for(experiment, keys, config, n_specimens) -> SpecimenBank:
    """The null bank of ``experiment`` aligned with the scenarios ``keys``: the configured file
    (``discovery.specimen_bank_rom`` / ``specimen_bank_idp``) when it covers them and has ``n_specimens``
    specimens, else built (seeded; cached in the process per configuration and scenario set)."""
    s = discovery_settings(config)
    path = s.get("specimen_bank_rom" if experiment == "stepwise_rom" else "specimen_bank_idp")
    if path and Path(path).is_file():
        b = read_bank(path, experiment)
        a = b.align(keys) if b.K == int(n_specimens) else None
        if a is not None:
            return a
        log.info("specimen bank %s: %d specimens or a missing scenario; building one for this table", path, b.K)
    sections = ("geometry", "characteristics", "fsu", "solver", "l2s1", "seed")
    key = json.dumps({k: (config or {}).get(k) for k in sections}
                     | {"variation": ((config or {}).get("stepwise_reduction") or {}).get("variation"),
                        "set": s["characteristic_set"], "K": int(n_specimens), "x": experiment}, sort_keys=True,
                     default=str)
    if experiment == "stepwise_rom":
        key += json.dumps(_key_tuples(keys, list(BANK_KEYS[experiment])))
        if key not in _BANKS:
            k = keys[list(BANK_KEYS[experiment])].reset_index(drop=True)
            vals, _ = rom_bank(config, k, n_specimens)
            _BANKS[key] = SpecimenBank(experiment, k, vals[:, 0, :], f"rom_bank(seed {bank_seed(config, NULL_STREAM)}, "
                                                                     f"{int(n_specimens)} specimens)")
        return _BANKS[key].align(keys)
    if key not in _BANKS:
        t = bank_table(config, experiment, n_specimens)
        _BANKS[key] = bank_from_table(t, experiment)
    a = _BANKS[key].align(keys)
    if a is None:
        raise ValueError(f"the IDP specimen bank has no row for some scenario of the table; it covers "
                         f"{len(_BANKS[key].keys)} scenarios")
    return a


# ------------------------------------------------------------------ the null datasets
@dataclass
class NullModel:
    """How the null tables are drawn from a bank: variation scale ``lam`` and measurement-noise variance
    ``a2 + b2 r^2`` per specimen, with what they were fitted from."""

    lam: float = 1.0
    a2: float = 0.0
    b2: float = 0.0
    spread_ratio: float = float("nan")     # mean of (table's per-specimen variance / bank's), rows with a spread
    rows_with_spread: int = 0

    def describe(self, unit) -> dict:
        return {"variation_scale": self.lam, "noise_additive_sd": float(np.sqrt(self.a2)),
                "noise_relative_sd": float(np.sqrt(self.b2)), "unit": unit,
                "table_to_bank_variance_ratio": self.spread_ratio, "rows_with_spread": self.rows_with_spread}


def fit_null_noise(spec_sd, bank: SpecimenBank, valid) -> NullModel:
    """Variation scale and measurement noise of the null from the table's per-specimen SD ``spec_sd`` (NaN where
    the row gives no spread) against the bank's between-specimen variance (see the module doc)."""
    r, v = bank.mean, bank.var
    ok = valid & np.isfinite(spec_sd) & np.isfinite(v) & (v > 0) & np.isfinite(r)
    if not ok.any():
        return NullModel(rows_with_spread=0)
    s2 = spec_sd[ok] ** 2
    ratio = float(np.mean(s2 / v[ok]))
    if ratio < 1.0:
        return NullModel(spread_ratio=ratio, rows_with_spread=int(ok.sum()))
    # rows weighted by their expected variance (bank + mean excess), not by their own noisy s^2: a row whose few
    # specimens happen to be alike must not pull the fit below zero
    expect = v[ok] + max(float(np.mean(s2 - v[ok])), 0.0)
    A = np.column_stack([np.ones(ok.sum()), r[ok] ** 2]) / expect[:, None]
    norm = np.linalg.norm(A, axis=0)
    norm = np.where(norm > 0, norm, 1.0)
    coef, _ = nnls(A / norm, (s2 - v[ok]) / expect)                        # columns scaled for nnls
    coef = coef / norm
    return NullModel(1.0, float(coef[0]), float(coef[1]), ratio, int(ok.sum()))


def null_datasets(problem, bank: SpecimenBank, model: NullModel, B: int, rng: np.random.Generator,
                  fresh: SpecimenBank | None = None):
    """B null tables of ``problem`` from ``bank`` (see the module doc): (Y, SIG), each (B, n). ``fresh``: the
    reference path, every table from its own new specimens (a bank of at least B x max(n) specimens, partitioned
    in order; no bank-mean correction)."""
    r = bank.mean
    npr = np.asarray(problem.meta["n_per_row"], int)
    hr = np.asarray(problem.meta["has_range"], bool)
    n = len(r)
    N = max(1, int(npr.max()))
    if fresh is not None:
        if fresh.K < B * N:
            raise ValueError(f"reference path: {fresh.K} new specimens for {B} tables of {N}")
        A = fresh.values[: B * N].reshape(B, N, n)
        ck = np.ones(n)
    else:
        K = bank.K
        if K >= N:
            idx = np.argsort(rng.random((B, K)), axis=1)[:, :N]
            ck = np.sqrt((K + npr) / np.maximum(K - npr, 1))
        else:
            idx = rng.integers(0, K, (B, N))
            ck = np.sqrt((1 + npr / K) * K / max(K - 1, 1))
        A = bank.values[idx]
    use = (np.arange(N)[:, None] < npr[None, :])[None]
    S = model.lam * (A - r)
    if fresh is None and bank.K > 3:
        S = S * np.sqrt((bank.K - 1) / rng.chisquare(bank.K - 1, B))[:, None, None]
    fin = np.isfinite(S) & use
    E = np.sqrt(model.a2 + model.b2 * np.where(np.isfinite(r), r, 0.0) ** 2) * rng.standard_normal((B, N, n))
    V = r + S + E
    if problem.experiment in NON_NEGATIVE:
        V = np.maximum(V, 0.0)
    cnt = fin.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        Y = np.where(fin, V, 0.0).sum(1) / cnt + (ck - 1.0) * np.where(fin, S, 0.0).sum(1) / cnt
        if problem.experiment == "stepwise_rom":
            hi = np.where(fin, V, -np.inf).max(1)
            lo = np.where(fin, V, np.inf).min(1)
            spread = (hi - lo) / d2(cnt) / np.sqrt(cnt)
        else:
            m = np.where(fin, V, 0.0).sum(1, keepdims=True) / cnt[:, None, :]
            spread = np.sqrt(np.where(fin, (V - m) ** 2, 0.0).sum(1) / (cnt - 1)) / np.sqrt(cnt)
    floor = float(problem.meta.get("sigma_floor", 0.0))
    SIG = np.where(hr[None, :] & (cnt > 1), np.maximum(spread, floor), problem.sigma[None, :])
    SIG = np.where(np.isfinite(SIG), SIG, problem.sigma[None, :])
    return Y, SIG


# ------------------------------------------------------------------ the metric of the test statistics
@dataclass
class Metric:
    """The quadratic form every test statistic uses: residuals in standard errors of the table's specimen mean
    (``sig``, the table's own per-row uncertainty), decorrelated by ``linv`` = L^-1 (R = L L^T the correlation of
    the table mean's deviations under the null; None = independent rows). ``metric(X)`` maps predictions or tables
    (m, n) to (m, p) over the ``valid`` rows, where the chi-square is the plain sum of squares."""

    valid: np.ndarray
    sig: np.ndarray
    linv: np.ndarray | None = None
    shrinkage: float = float("nan")

    def __call__(self, X):
        X = np.atleast_2d(np.asarray(X, float))[:, self.valid] / self.sig[self.valid]
        return X if self.linv is None else X @ self.linv.T


def ledoit_wolf(Z):
    """Ledoit-Wolf shrinkage of the correlation of the standardised samples Z (K, p) towards the identity:
    (intensity in [0, 1], shrunk correlation). Ledoit & Wolf (2004), J Multivar Anal 88:365-411, Lemma 3.2 and
    Theorem 3.1 with the identity (scaled by the mean variance, 1 here) as the target."""
    K, p = Z.shape
    S = Z.T @ Z / K
    d2 = float(np.sum((S - np.eye(p)) ** 2)) / p
    b2 = float(np.sum([np.sum((np.outer(z, z) - S) ** 2) for z in Z])) / p / K ** 2
    lam = 1.0 if d2 <= 0 else min(b2, d2) / d2
    return lam, (1 - lam) * S + lam * np.eye(p)


#: least shrinkage of the specimens' correlation towards independent rows in the metric of the tests [-]: directions
#: in which the virtual specimens hardly vary keep this share of every row's uncertainty, so that the table's own
#: noise, estimated and not known (fit_null_noise), cannot make a small deviation there look enormous
MIN_SHRINKAGE = 0.3


def specimen_metric(bank: SpecimenBank, model: NullModel, sig, valid) -> Metric:
    """The metric of a problem with a specimen bank: the correlation of a table mean's deviations from r under the
    null, from the bank's specimens (standardised; Ledoit-Wolf shrinkage towards independent rows, at least
    :data:`MIN_SHRINKAGE`: K specimens estimate a p x p correlation poorly when K is not much larger than p) and the
    fitted independent measurement noise; the scale of each row is the table's own sigma. A specimen without
    equilibrium in a row counts as no deviation there."""
    r = bank.mean
    X = np.where(np.isfinite(bank.values), bank.values - r, 0.0)[:, valid]
    sd = X.std(0, ddof=1)
    sd = np.where(sd > 0, sd, 1.0)
    Z = (X - X.mean(0)) / sd
    lam = max(ledoit_wolf(Z)[0], MIN_SHRINKAGE)
    R = (1 - lam) * (Z.T @ Z / len(Z)) + lam * np.eye(Z.shape[1])
    C = sd[:, None] * R * sd[None, :] + np.diag(model.a2 + model.b2 * r[valid] ** 2)
    d = np.sqrt(np.diag(C))
    L = np.linalg.cholesky(C / np.outer(d, d))
    return Metric(valid, np.asarray(sig, float), np.linalg.inv(L), lam)
