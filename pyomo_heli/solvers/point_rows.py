"""Rows evaluated point by point: one casadi function per block mapped over its points.

The model side describes the rows (``blk.point_rows``, contract in :mod:`pyomo_heli.nlp.point_rows`):
a function ``F(z, d) -> r`` of one point's leaves ``z`` and data ``d``, the Pyomo leaves of every
point and the constraint behind each evaluated output. Here they become, for the whole NLP,

- the rows: ``F`` mapped over the points, fed with the leaves gathered from the NLP vector;
- the Jacobian: the structural nonzeros of ``dF/dz`` of one point, mapped, then put into the
  global pattern: by one gather where a global nonzero has one local entry (nearly all), through a
  small constant sparse matrix where several add up (a leaf used twice at one point, e.g. the input
  error at a sample);
- the Hessian of the Lagrangian: the upper triangle of ``d2(lam . F)/dz2`` of one point, mapped and
  put together the same way (a leaf used at many points, e.g. a parameter, adds up over them; an
  off-diagonal local entry whose two leaves are one variable counts twice).

The derivatives are those of one point, found once, where the NL route differentiates the whole
graph (docs/performance.md, "What was done"); ``tests/test_point_rows.py`` checks the values against
it. Leaves that are numbers or fixed variables are constants (read at build, as the NL file does).
"""
from __future__ import annotations

import numpy as np
import pyomo.environ as pyo


def _cat(arrays, dtype=np.int64) -> np.ndarray:
    return np.concatenate(arrays).astype(dtype) if arrays else np.zeros(0, dtype)


def find_point_rows(model) -> list:
    """The active blocks of ``model`` that describe their rows point by point."""
    found = []
    for blk in model.component_data_objects(pyo.Block, active=True, descend_into=True):
        pr = getattr(blk, "point_rows", None)
        if pr is not None:
            found.append(pr)
    return found


class PointRowsAssembly:
    """The rows, Jacobian and Lagrangian Hessian of all point-described blocks, as casadi MX.

    column_of: id(VarData) -> column of the NLP vector for every free variable; variables of the
    blocks that are free and not in it are appended (``self.extra``). ``self.constraints`` are the
    evaluated constraints in row order (active ones only).
    """

    def __init__(self, ca, blocks, column_of: dict, n_columns: int):
        self.ca = ca
        self.extra = []
        consts = [0.0]  # slot 0 of the constants: the zero that unused multipliers read
        const_of = {}
        n = n_columns
        self.constraints = []
        self._blocks = []
        for pr in blocks:
            F = pr.function(ca)
            nz, nr = F.size1_in(0), F.size1_out(0)
            n_pts = len(pr.leaves)
            leaf_col = np.empty((n_pts, nz), dtype=np.int64)
            for p, leaves in enumerate(pr.leaves):
                for j, v in enumerate(leaves):
                    if isinstance(v, (int, float)) or v.fixed:
                        val = float(v) if isinstance(v, (int, float)) else float(v.value)
                        if val not in const_of:
                            const_of[val] = len(consts)
                            consts.append(val)
                        leaf_col[p, j] = -1 - const_of[val]  # constants: negative, decoded below
                    else:
                        c = column_of.get(id(v))
                        if c is None:
                            c = column_of[id(v)] = n
                            self.extra.append(v)
                            n += 1
                        leaf_col[p, j] = c
            row_of = np.full((n_pts, nr), -1, dtype=np.int64)
            for con, p, j in pr.rows:
                if not con.active:
                    continue
                if not (con.equality and con.lb == 0 and con.ub == 0):
                    raise ValueError(f"constraint {con.name}: a point-described row must be an equality with zero "
                                     f"bounds (body == 0)")
                row_of[p, j] = len(self.constraints)
                self.constraints.append(con)
            self._blocks.append({"F": F, "nz": nz, "nr": nr, "n_pts": n_pts, "leaf_col": leaf_col,
                                 "row_of": row_of, "data": np.asarray(pr.data(), dtype=float).T})
        self.n = n
        self.m = len(self.constraints)
        self._consts = np.array(consts)
        for b in self._blocks:  # constants after the n columns of x: x_ext = [x; consts]
            lc = b["leaf_col"]
            lc[lc < 0] = n + (-1 - lc[lc < 0])
        self._jacobian_map = self._hessian_map = None

    def shift_columns(self, n_before: int, n_extra: int) -> None:
        """Move the appended variables to the front: columns < n_before shift up by n_extra, the
        appended ones (n_before ... n - 1) go to 0 ... n_extra - 1; constants stay after n."""
        if self._jacobian_map is not None or self._hessian_map is not None:
            raise RuntimeError("shift the columns before the derivative maps are built")
        for b in self._blocks:
            lc = b["leaf_col"]
            nl, extra = lc < n_before, (lc >= n_before) & (lc < self.n)
            lc[nl] += n_extra
            lc[extra] -= n_before

    # ---------------------------------------------------------------- pieces
    def _extended(self, X):
        """[X; constants]: what the leaves' columns index (made once per evaluation, not once per
        block: it copies X)."""
        return self.ca.vertcat(X, self.ca.DM(self._consts))

    def _gather(self, x_ext, b):
        return self.ca.reshape(x_ext[b["leaf_col"].ravel().tolist()], b["nz"], b["n_pts"])

    def _select_rows(self, parts):
        """The evaluated constraints' rows out of every block's (rows x points) output, in row order."""
        ca = self.ca
        where, offset = np.empty(self.m, dtype=np.int64), 0
        for b in self._blocks:
            rr = b["row_of"].ravel()  # point-major, as vec(R) (column-major, one column per point)
            hit = rr >= 0
            where[rr[hit]] = offset + np.flatnonzero(hit)
            offset += b["nr"] * b["n_pts"]
        if not parts:
            return ca.MX(0, 1)
        return ca.vertcat(*[ca.vec(R) for R in parts])[where.tolist()]

    def rows(self, X):
        """g of the evaluated constraints (m x 1) at the NLP vector X (MX, n x 1)."""
        ca = self.ca
        x_ext = self._extended(X)
        return self._select_rows([b["F"].map(b["n_pts"])(self._gather(x_ext, b), ca.DM(b["data"]))
                                  for b in self._blocks])

    def _scatter(self, entries, shape):
        """(rows, cols, weights, local positions) of all local entries -> (sparsity, how), where
        ``how`` = (gather indices, summed part or None) is what :meth:`_combine` needs (None: no entries).

        Most global nonzeros have one local entry of weight 1 (every Jacobian entry of a row: a row
        belongs to one point); they are picked by one gather. The few that add several entries up
        (a parameter's Hessian entries, summed over every point) or carry a weight go through a
        small sparse matrix over only the entries they need, instead of one sparse product over all
        local entries at every evaluation (docs/performance.md, "What was done" 9).
        """
        ca = self.ca
        rows, cols, weights, pos, n_local = entries
        if len(rows) == 0:
            return ca.Sparsity(shape[0], shape[1]), None
        key = cols.astype(np.int64) * shape[0] + rows  # column-major order, as casadi stores nonzeros
        uniq, nz_index = np.unique(key, return_inverse=True)
        ucol, urow = uniq // shape[0], uniq % shape[0]
        colind = np.searchsorted(ucol, np.arange(shape[1] + 1))
        sp = ca.Sparsity(shape[0], shape[1], colind.tolist(), urow.tolist())
        count = np.bincount(nz_index, minlength=len(uniq))
        single = (count == 1)[nz_index] & (weights == 1.0)  # local entries that are their nonzero alone
        pick = np.empty(len(uniq), dtype=np.int64)
        pick[nz_index[single]] = pos[single]
        multi = ~single
        summed = None
        if multi.any():
            targets, target_index = np.unique(nz_index[multi], return_inverse=True)
            sources, source_index = np.unique(pos[multi], return_inverse=True)
            matrix = ca.DM(ca.Sparsity.triplet(len(targets), len(sources), target_index.tolist(),
                                               source_index.tolist()), weights[multi].tolist())
            pick[targets] = n_local + np.arange(len(targets))  # after the local entries
            summed = (sources.tolist(), matrix)
        return sp, (pick.tolist(), summed)

    def _combine(self, local, how):
        """The global nonzeros from the local entries (``how`` from :meth:`_scatter`)."""
        ca = self.ca
        pick, summed = how
        if summed is not None:
            sources, matrix = summed
            local = ca.vertcat(local, ca.mtimes(matrix, local[sources]))
        return local[pick]

    def _local_jacobian(self, b):
        """One point's rows and the structural nonzeros of their Jacobian, as one function (the two
        share their subexpressions), with the nonzeros' local (row, leaf)."""
        ca = self.ca
        F = b["F"]
        z, d = ca.SX.sym("z", b["nz"]), ca.SX.sym("d", F.size1_in(1))
        r_z = F(z, d)
        J = ca.jacobian(r_z, z)
        r, c = J.sparsity().get_triplet()
        return ca.Function("point_jac", [z, d], [r_z, ca.vertcat(*J.nonzeros()) if J.nnz() else ca.SX(0, 1)]), \
            np.array(r, dtype=np.int64), np.array(c, dtype=np.int64)

    def _local_hessian(self, b):
        ca = self.ca
        F = b["F"]
        z, d, lam = ca.SX.sym("z", b["nz"]), ca.SX.sym("d", F.size1_in(1)), ca.SX.sym("lam", b["nr"])
        H = ca.triu(ca.hessian(ca.dot(lam, F(z, d)), z)[0])
        r, c = H.sparsity().get_triplet()
        return ca.Function("point_hess", [z, d, lam], [ca.vertcat(*H.nonzeros()) if H.nnz() else ca.SX(0, 1)]), \
            np.array(r, dtype=np.int64), np.array(c, dtype=np.int64)

    def rows_and_jacobian(self, X):
        """(rows, d(rows)/dX): m x 1 and m x n sparse MX, from one mapped evaluation per block."""
        ca = self.ca
        if self._jacobian_map is None:
            funs, rows, cols, pos, total = [], [], [], [], 0
            for b in self._blocks:
                f, lr, lc = self._local_jacobian(b)
                k = len(lr)
                P = np.arange(b["n_pts"])[:, None]
                g_row, g_col = b["row_of"][P, lr[None, :]], b["leaf_col"][P, lc[None, :]]
                ok = (g_row >= 0) & (g_col < self.n)
                local_pos = total + P * k + np.arange(k)[None, :]  # vec of the (k x n_pts) output
                rows.append(g_row[ok])
                cols.append(g_col[ok])
                pos.append(local_pos[ok])
                funs.append(f)
                total += k * b["n_pts"]
            rows, cols, pos = (_cat(a) for a in (rows, cols, pos))
            self._jacobian_map = (funs, *self._scatter((rows, cols, np.ones(len(rows)), pos, total), (self.m, self.n)))
        funs, sp, how = self._jacobian_map
        if not funs:
            return ca.MX(0, 1), ca.MX(self.m, self.n)
        x_ext = self._extended(X)
        outs = [f.map(b["n_pts"])(self._gather(x_ext, b), ca.DM(b["data"])) for f, b in zip(funs, self._blocks)]
        local = ca.vertcat(*[ca.vec(jnz) for _, jnz in outs])
        if how is None:
            return self._select_rows([r for r, _ in outs]), ca.MX(self.m, self.n)
        return self._select_rows([r for r, _ in outs]), ca.MX(sp, self._combine(local, how))

    def hessian(self, X, lam):
        """Upper triangle of sum_i lam_i d2(row_i)/dX2, n x n sparse MX; lam: the rows' multipliers (m x 1)."""
        ca = self.ca
        if self._hessian_map is None:
            funs, rows, cols, weights, pos, total = [], [], [], [], [], 0
            for b in self._blocks:
                f, la, lb = self._local_hessian(b)
                k = len(la)
                P = np.arange(b["n_pts"])[:, None]
                ca_, cb_ = b["leaf_col"][P, la[None, :]], b["leaf_col"][P, lb[None, :]]
                ok = (ca_ < self.n) & (cb_ < self.n)
                i, j = np.minimum(ca_, cb_), np.maximum(ca_, cb_)
                # a local off-diagonal pair whose two leaves are one variable is that variable's
                # diagonal twice (d2/dv2 of f(v, v) = f_aa + 2 f_ab + f_bb)
                w = np.where((la[None, :] != lb[None, :]) & (ca_ == cb_), 2.0, 1.0)
                local_pos = total + P * k + np.arange(k)[None, :]
                rows.append(i[ok])
                cols.append(j[ok])
                weights.append(w[ok])
                pos.append(local_pos[ok])
                funs.append(f)
                total += k * b["n_pts"]
            entries = (_cat(rows), _cat(cols), _cat(weights, float), _cat(pos), total)
            self._hessian_map = (funs, *self._scatter(entries, (self.n, self.n)))
        funs, sp, how = self._hessian_map
        if not funs or how is None:
            return ca.MX(self.n, self.n)
        lam_ext = ca.vertcat(lam, ca.MX(1, 1))  # the zero that rows without a constraint read
        local, x_ext = [], self._extended(X)
        for f, b in zip(funs, self._blocks):
            idx = np.where(b["row_of"] >= 0, b["row_of"], self.m).ravel().tolist()
            L = ca.reshape(lam_ext[idx], b["nr"], b["n_pts"])
            local.append(ca.vec(f.map(b["n_pts"])(self._gather(x_ext, b), ca.DM(b["data"]), L)))
        return ca.MX(sp, self._combine(ca.vertcat(*local), how))
