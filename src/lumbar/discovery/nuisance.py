"""Nuisance explanations of a discrepancy: what a table can differ by without any missing physics of the library.

Fitted beside the candidate effects in every discovery, on top of the specimen-mean prediction r (the nominal model
plus the specimen-mean shift of :mod:`lumbar.discovery.specimens`; the nominal model itself where the experiment has
no specimens):

* ``uniform scale``: every measured value x s (a calibration factor of the goniometer or the pressure transducer, a
  disc area, a stiffer or softer set of specimens);
* ``uniform offset``: every measured value + o (a zero offset, a different neutral position);
* for the stepwise-reduction ROM also ``scale per direction`` and ``offset per direction`` (one parameter per loading
  direction of the table: a per-axis calibration, a direction-dependent stiffness).

Each is linear in its parameters, so it is fitted in closed form (least squares in the metric of the tests,
:class:`lumbar.discovery.specimens.Metric`) on every bootstrap table at once. A candidate effect is named only when it beats the best of them by the
same bootstrap likelihood-ratio test (:func:`lumbar.discovery.fit.discover`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Nuisance:
    """One nuisance family: ``kind`` "scale" | "offset", applied per group of rows (``groups``: group index per
    row, ``labels``: the groups' names; one group = uniform)."""

    name: str
    kind: str
    groups: np.ndarray
    labels: tuple

    @property
    def k(self) -> int:
        return len(self.labels)

    def columns(self, r):
        """The family's design (n, k): the change of the prediction per unit of each parameter (scale: r in the
        group's rows; offset: 1 there)."""
        G = np.zeros((len(self.groups), self.k))
        G[np.arange(len(self.groups)), self.groups] = 1.0
        return G * np.asarray(r, float)[:, None] if self.kind == "scale" else G

    def predict(self, r, p):
        """Prediction(s) for parameters p (k,) or (B, k)."""
        per_row = np.asarray(p)[..., self.groups]
        return r * per_row if self.kind == "scale" else r + per_row

    def transform(self, Y, SIG, r, p):
        """Tables of the nuisance hypothesis from null tables (centred on r): the measured quantity scaled (with its
        spread) or offset by the fitted parameters p (k,)."""
        per_row = np.asarray(p)[self.groups]
        if self.kind == "scale":
            return Y * per_row, SIG * np.abs(per_row)
        return Y + per_row, SIG

    def describe(self, p, unit) -> str:
        p = np.asarray(p, float)
        if self.k == 1:
            return f"{self.name} {p[0]:.3g}" if self.kind == "scale" else f"{self.name} {p[0]:+.3g} {unit}"
        parts = [f"{lab} {v:.3g}" if self.kind == "scale" else f"{lab} {v:+.3g} {unit}" for lab, v in zip(self.labels, p)]
        return f"{self.name}: " + ", ".join(parts)


def families(problem, valid) -> list[Nuisance]:
    """The nuisance families of a problem: uniform scale and offset; per direction for the stepwise-reduction ROM
    when the table has >= 2 directions with >= 2 compared rows each (and at least 2 rows more than parameters)."""
    n = len(problem.y)
    if valid.sum() < 3:                 # a nuisance fitted to one or two rows explains nothing
        return []
    one = np.zeros(n, int)
    out = [Nuisance("uniform scale", "scale", one, ("all",)), Nuisance("uniform offset", "offset", one, ("all",))]
    g = problem.meta.get("groups")
    if g is not None:
        labels = tuple(dict.fromkeys(np.asarray(g)[valid]))
        idx = np.array([labels.index(x) if x in labels else 0 for x in g], int)
        counts = np.bincount(idx[valid], minlength=len(labels))
        if len(labels) >= 2 and counts.min() >= 2 and valid.sum() - len(labels) >= 2:
            out += [Nuisance("scale per direction", "scale", idx, labels),
                    Nuisance("offset per direction", "offset", idx, labels)]
    return out


def multiple_correlation(s, basis) -> float:
    """|projection of the sensitivity vector s onto the span of ``basis``| / |s| (the multiple correlation, through
    the origin): 1 = the candidate does on this experiment exactly what the nuisance family can do."""
    ns = np.linalg.norm(s)
    if ns == 0 or not np.isfinite(basis).all() or np.linalg.norm(basis) == 0:
        return float("nan")
    q, _ = np.linalg.qr(basis[:, np.linalg.norm(basis, axis=0) > 0])
    return float(np.linalg.norm(q.T @ s) / ns)
