"""The admissible fit's probe: the equilibria of one unit under the moments and the follower load the fit's
residuals read, warm-started, with their linearisation (one Newton step) for the fit's Jacobian, and the metrics the
admissibility penalties are computed from."""
from __future__ import annotations

import numpy as np

from ...geometry.visible_human import uw_force
from ...mechanics import so3
from ...mechanics.solve import solve, solve_sequence
from .. import admissibility as ADM
from ..fsu import moment_loads
from ..load_sharing import AXIS_OF, level_structures

#: the fields of a Remus et al. (2021) material that its law (uw_force) reads
UW_KEYS = ("reference_strain", "transition_strain", "stiffness_n")

#: moments [N*m] of the fit's probe (the admissibility check itself uses 0.25 N*m steps); 0.25 N*m watches the
#: compliance at the neutral position (the snap-through criterion's first step), 1 N*m gives the neutral-zone proxy
PROBE_MOMENTS = (0.25, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0)
PROBE_DIRECTIONS = ("flexion", "extension", "lateral_bending_right", "lateral_bending_left",
                    "axial_rotation_left", "axial_rotation_right")


class Probe:
    """Rest state, pure moments at PROBE_MOMENTS in PROBE_DIRECTIONS and a 1000 N follower load of a unit (built with
    ``follower=True``), solved in one batch warm-started from the last converged states.

    :meth:`linearised` returns the states after one Newton step from the last equilibrium under changed parameters:
    the first-order change of every state with a parameter (implicit function theorem), which makes the fit's
    finite-difference Jacobian cost one residual evaluation per parameter instead of one equilibrium solve."""

    def __init__(self, fsu, max_iter=50, tol=1e-8):
        self.fsu, m = fsu, fsu.model
        self.scen = [("rest", "", 0.0)] + [("moment", d, M) for M in PROBE_MOMENTS for d in PROBE_DIRECTIONS] + \
                    [("compression", "", 1000.0)]
        B = len(self.scen)
        self.loads = np.zeros((B, m.nb, 6))
        self.fm = np.repeat(fsu.masks(["intact"])[0], B, axis=0)
        cab = m.f_group == fsu.follower_group
        for i, (kind, d, M) in enumerate(self.scen):
            if kind == "moment":
                self.loads[i] = moment_loads([d], [M], m.nb)[0]
            elif kind == "compression":
                self.fm[i, cab] = M
        self.cm = np.ones((B, m.nc))
        self.kw = dict(max_iter=max_iter, tol_force=tol, tol_moment=tol)
        self.st = level_structures(m, fsu.level.name, dict(enumerate(fsu.surface_side)))
        self.sel = [0, self.scen.index(("moment", "flexion", PROBE_MOMENTS[-1])), B - 1]
        # what metrics() reads, fixed per probe: the moment scenarios (row, axis, sign), the fibre groups of each
        # ligament kind and each structure's fibre mask
        self.rot_rows = [i for i, sc in enumerate(self.scen) if sc[0] == "moment"]
        self.rot_axis = np.array([AXIS_OF[self.scen[i][1]][0] for i in self.rot_rows])
        self.rot_sign = np.array([AXIS_OF[self.scen[i][1]][1] for i in self.rot_rows], float)
        self.kinds = {}
        for g, (_, k, _lv) in enumerate(m.fibre_groups):
            self.kinds.setdefault(k, []).append(g)
        self.group_masks = {k: np.isin(m.f_group, g) for k, g in self.st.groups.items()}
        self.group_sum = np.zeros((len(m.fibre_groups), m.nf))    # fibre tensions -> group totals (group_forces)
        self.group_sum[m.f_group, np.arange(m.nf)] = 1.0
        self.remus = None          # kind -> [(fibre mask, Remus et al. 2021 material)] (:meth:`set_remus`)
        self.warm = None
        self.state = None
        self.n_solves = 0

    def set_remus(self, materials: dict):
        """Evaluate the Remus et al. (2021) law of every fibre group named in ``materials`` (``read_uw_materials`` of
        the level) at the 10 N*m flexion state too (metrics ``flex_remus``): the sourced exception of the force-scale
        criterion, compared inside the fit."""
        m = self.fsu.model
        self.remus = {}
        for g, (name, kind, lv) in enumerate(m.fibre_groups):
            if lv == self.fsu.level.name and name in materials:
                self.remus.setdefault(kind, []).append((m.f_group == g, materials[name]))
        # every part's fibres side by side, with their material per column: one evaluation of the law per call, whose
        # per-part sums are those of a call per part (the same elementwise arithmetic, the same columns in order)
        idx, cols, self._remus_parts = [], {key: [] for key in UW_KEYS}, {}
        for kind, parts in self.remus.items():
            for mask, mat in parts:
                i = np.flatnonzero(mask)
                self._remus_parts.setdefault(kind, []).append(slice(len(idx), len(idx) + len(i)))
                idx += i.tolist()
                for key in UW_KEYS:
                    cols[key] += [mat[key]] * len(i)
        self._remus_idx = np.array(idx, dtype=np.int64)
        self._remus_mat = {key: np.array(v, float) for key, v in cols.items()}

    def _remus_rows(self):
        return [0] + [self.scen.index(("moment", d, M)) for _, d, M in ADM.REMUS_STATES if d] if self.remus else []

    def _remus_pairs(self, length, T):
        """{kind: (model tension, Remus et al. 2021 tension) [N]} at the state of the admissibility criterion's
        comparison (``ADM.REMUS_STATES``: rest and 10 N*m in four directions) where the Remus law carries the kind
        most, from the fibre lengths and tensions (rows :meth:`_remus_rows`); {} without :meth:`set_remus`."""
        if not self.remus:
            return {}
        m = self.fsu.model
        idx = self._remus_idx
        F = uw_force(length[:, idx], m.f_lref[idx], self._remus_mat)
        Tp = T[:, idx]
        out = {}
        for k, parts in self._remus_parts.items():
            t_r = sum(F[:, p].sum(axis=1) for p in parts)
            t_m = sum(Tp[:, p].sum(axis=1) for p in parts)
            j = int(np.argmax(t_r))
            out[k] = (float(t_m[j]), float(t_r[j]))
        return out

    def _cold(self):
        m = self.fsu.model
        i_comp = len(self.scen) - 1
        idx = {M: [i for i, s in enumerate(self.scen) if s[0] == "moment" and s[2] == M] for M in PROBE_MOMENTS}
        rest = solve(m, self.loads[[0]], fmask=self.fm[[0]], retry_load_steps=(4, 16), **self.kw)
        nd = len(PROBE_DIRECTIONS)
        path = np.stack([self.loads[idx[M]] for M in PROBE_MOMENTS])
        seq = solve_sequence(m, path, x0=np.repeat(rest.x, nd, 0), R0=np.repeat(rest.R, nd, 0),
                             fmask=self.fm[idx[PROBE_MOMENTS[0]]], **self.kw)
        comp = solve(m, self.loads[[i_comp]], x0=rest.x, R0=rest.R, fmask=self.fm[[i_comp]], load_steps=4, **self.kw)
        x = np.empty((len(self.scen), m.nb, 3))
        R = np.empty((len(self.scen), m.nb, 3, 3))
        x[0], R[0] = rest.x[0], rest.R[0]
        x[i_comp], R[i_comp] = comp.x[0], comp.R[0]
        for M, r in zip(PROBE_MOMENTS, seq):
            x[idx[M]], R[idx[M]] = r.x, r.R
        return x, R

    def run(self):
        """Equilibria at the model's current parameters; keeps them (and their stiffness) for :meth:`linearised`."""
        m = self.fsu.model
        if self.warm is None:
            self.warm = self._cold()
        res = solve(m, self.loads, x0=self.warm[0], R0=self.warm[1], fmask=self.fm, cmask=self.cm,
                    retry_load_steps=(), **self.kw)
        if not res.converged.all():      # fall back to the continuation from the reference state
            x, R = self._cold()
            res = solve(m, self.loads, x0=x, R0=R, fmask=self.fm, cmask=self.cm, retry_load_steps=(4,), **self.kw)
        self.n_solves += len(self.scen)
        if res.converged.all():
            self.warm = (res.x, res.R)
            _, J = m.evaluate(res.x, res.R, self.loads, self.fm, self.cm, jacobian=True)
            n = 6 * m.nb
            self.state = (res.x, res.R, J.reshape(-1, n, n))
        else:
            self.state = None
        return res.x, res.R, bool(res.converged.all())

    def linearised(self):
        """(x, R) one Newton step from the kept equilibria under the model's current parameters."""
        m = self.fsu.model
        x, R, J = self.state
        Q, _ = m.evaluate(x, R, self.loads, self.fm, self.cm, jacobian=False)
        d = np.linalg.solve(J, -Q.reshape(len(x), -1)[..., None])[..., 0].reshape(len(x), m.nb, 6)
        return x + d[..., :3], so3.exp(d[..., 3:]) @ R

    def metrics(self, x, R):
        """Rotations [deg] at every probe scenario, rest and 10 N*m flexion internal loads, compression share."""
        m = self.fsu.model
        rows = self.rot_rows
        phi = so3.log(R[rows, 0] @ R[0, 0].T)                       # one batch: every moment scenario
        deg = np.degrees(phi[np.arange(len(rows)), self.rot_axis] * self.rot_sign)
        rot = {self.scen[i][1:]: float(v) for i, v in zip(rows, deg)}
        sel = self.sel
        # one fibre state for every row read below (rest, 10 N*m flexion, compression, the Remus states): each row is
        # computed on its own, so the values are those of separate calls
        frows = list(sel) + self._remus_rows()
        length, _, T, _, d, dn, pa, _ = m.fibre_state(x[frows], R[frows], self.fm[frows])
        gf = T[:3] @ self.group_sum.T                              # m.group_forces at the rows of sel
        cf = m.contact_forces(x[sel], R[sel], self.cm[sel])
        kinds = self.kinds
        # ligament moments about the disc centre at 10 N*m flexion, straight from the fibre forces
        i = sel[1]
        f = -T[1, :, None] * d[1] / dn[1, :, None]                 # force on the upper vertebra at pa
        st = self.st
        centre = x[i, st.upper] + R[i, st.upper] @ (st.centre - m.c[st.upper])
        mom = np.cross(pa[1] - centre, f)[:, 1]                   # flexion component (world y)
        flex_moment = {k: float(-mom[mask].sum()) for k, mask in self.group_masks.items()}
        # facets' share of the follower load: their contact forces along the disc normal (masked residuals)
        j = [sel[2]]
        base, _ = m.evaluate(x[j], R[j], None, self.fm[j] * 0, self.cm[j] * 0, jacobian=False)
        onlyf, _ = m.evaluate(x[j], R[j], None, self.fm[j] * 0, self.cm[j], jacobian=False)
        up = float((onlyf - base)[0, st.upper, :3] @ m.discs[st.disc].frame[2])
        r = m.disc_displacement(x, R, st.disc)                     # every scenario in one batch
        disc_up = float(m.disc_axial_force(r[j], st.disc)[0][0])
        disc_r = r[:, 2]                                           # axial displacement [m], < 0 = compression
        moment_rows = [i for i, sc in enumerate(self.scen) if sc[0] != "compression"]
        return {"rot": rot, "min_disc_compression_mm": float(-disc_r[moment_rows].max() * 1e3),
                "rest_tension": {k: float(gf[0, g].sum()) for k, g in kinds.items()},
                "rest_facet": cf[0].copy(),
                "flex_tension": {k: float(gf[1, g].sum()) for k, g in kinds.items()},
                "flex_moment": flex_moment, "remus": self._remus_pairs(length[3:], T[3:]),
                "compression_facet_share": max(up, 0.0) / max(max(up, 0.0) + max(disc_up, 0.0), 1e-9)}


def rom_of(mt, directions):
    """ROM [deg] at 10 N*m per direction of the probe metrics ``mt`` (lateral bending and axial rotation: the mean of
    the two sides, as the real rows give them)."""
    out = []
    for d in directions:
        if d in ("lateral_bending", "axial_rotation"):
            sides = ("right", "left")
            out.append(0.5 * (mt["rot"][(f"{d}_{sides[0]}", 10.0)] + mt["rot"][(f"{d}_{sides[1]}", 10.0)]))
        else:
            out.append(mt["rot"][(d, 10.0)])
    return np.array(out)
