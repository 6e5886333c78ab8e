"""The derivative functions of the casadi-Ipopt adapter: constraint Jacobian and Lagrangian Hessian.

casadi's own Jacobian and Hessian colour the whole matrix at once, and the dense rows and columns of
the identification NLPs (the epsilon row, the free parameters used at every collocation point) make
that quadratic in size; the functions here split the matrices into sparse and dense blocks
(:meth:`DerivativeFunctions._jacobian_function`, :meth:`DerivativeFunctions._nl_hessian_function`)
and join the NL file's part with the point-described rows' (solvers/point_rows.py). A mixin of
:class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver`: it reads the adapter's state
(``self._ca``, ``self._nlp``, ``self._assembly``, ``self.settings``, the column and row offsets).
"""

from __future__ import annotations

import numpy as np


class DerivativeFunctions:
    """Builders of the adapter's casadi derivative functions (mixed into CasadiIpoptSolver)."""


    def _dense(self, counts: np.ndarray, percentile: float = 99) -> list[int]:
        """Indices whose nonzero count is an outlier (see ``dense_row_threshold``)."""
        if len(counts) == 0:
            return []
        cfg = self.settings
        threshold = max(cfg.dense_row_threshold, cfg.dense_factor * np.percentile(counts, percentile))
        return np.flatnonzero(counts > threshold).tolist()


    def _jacobian_function(self, x, g):
        """Constraint Jacobian built block-wise, or None for casadi's default.

        casadi colours the whole Jacobian at once, and every colour costs a
        sweep over the whole expression graph. One dense row together with a
        dense column (a model parameter used at every time step) defeats both
        forward and reverse colouring and the build becomes quadratic (15 s at
        4k variables, 64 s at 8k). Here the sparse rows x sparse columns block
        is one casadi Jacobian (8 forward colours on the identification NLPs,
        instead of 39 with the epsilon row or 47 with the dense columns), the
        dense columns are one forward block over the sparse rows, and the dense
        rows one reverse block over their own small subgraph: linear in size.
        """
        ca = self._ca
        n, m = x.shape[0], g.shape[0]
        if not self._dense_rows and not self._dense_cols:
            return None
        dense_rows, dense_cols = self._dense_rows, self._dense_cols
        rows = np.setdiff1d(np.arange(m), dense_rows).tolist()
        cols = np.setdiff1d(np.arange(n), dense_cols).tolist()
        g_sparse = g[rows]
        blocks = [ca.jacobian(g_sparse, x[cols])]
        if dense_cols:
            blocks.append(ca.jacobian(g_sparse, x[dense_cols]))
        jac = ca.horzcat(*blocks)[:, np.argsort(cols + dense_cols).tolist()]  # columns back into NL order
        if dense_rows:
            jac = ca.vertcat(jac, ca.jacobian(g[dense_rows], x))[np.argsort(rows + dense_rows).tolist(), :]
        p = ca.SX.sym("p", 0)
        return ca.Function("nlp_jac_g", [x, p], [g, jac], ["x", "p"], ["g", "jac_g_x"])

    # ------------------------------------------------ with point-described rows
    def _full_jacobian(self, jac_nl):
        """g and its Jacobian of the whole NLP: the NL part's and the point-described rows', in NLP order."""
        ca, A = self._ca, self._assembly
        n, n_nl, m_nl = len(self.variables), self._n_nl, self._m_nl
        if jac_nl is None:
            x, g = self._nlp["x"], self._nlp["g"]
            jac_nl = ca.Function("nl_jac_g", [x, ca.SX.sym("p", 0)], [g, ca.jacobian(g, x)])
        X, P = ca.MX.sym("x", n), ca.MX.sym("p", 0)
        c0 = self._nl_col0
        g_nl, J_nl = jac_nl(X[c0:c0 + n_nl], P)
        J_nl = ca.horzcat(ca.MX(m_nl, c0), J_nl, ca.MX(m_nl, n - n_nl - c0))
        g_map, J_map = A.rows_and_jacobian(X)
        if self._nl_row0:
            g, J = ca.vertcat(g_map, g_nl), ca.vertcat(J_map, J_nl)
        else:
            g, J = ca.vertcat(g_nl, g_map), ca.vertcat(J_nl, J_map)
        return ca.Function("nlp_jac_g", [X, P], [g, J], ["x", "p"], ["g", "jac_g_x"])

    def _hessian_function(self):
        """The Lagrangian Hessian function of the whole NLP (None: casadi's own, NL route only)."""
        h_nl = self._nl_hessian_function()
        if self._assembly is None:
            return h_nl
        ca, A = self._ca, self._assembly
        n, n_nl, m_nl = len(self.variables), self._n_nl, self._m_nl
        if h_nl is None:
            x, f, g = self._nlp["x"], self._nlp["f"], self._nlp["g"]
            lf, lg = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
            h_nl = ca.Function("nl_hess_l", [x, ca.SX.sym("p", 0), lf, lg],
                               [ca.triu(ca.hessian(lf * f + ca.dot(lg, g), x)[0])])
        X, P = ca.MX.sym("x", n), ca.MX.sym("p", 0)
        lf, lg = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", len(self.constraints))
        c0, r0 = self._nl_col0, self._nl_row0
        H_nl = h_nl(X[c0:c0 + n_nl], P, lf, lg[r0:r0 + m_nl])
        lam_map = lg[:r0] if r0 else lg[m_nl:]
        H = ca.diagcat(ca.MX(c0, c0), H_nl, ca.MX(n - n_nl - c0, n - n_nl - c0)) + A.hessian(X, lam_map)
        return ca.Function("nlp_hess_l", [X, P, lf, lg], [H], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])

    def _nlp_functions(self):
        """(f, g) and (f, grad f) of the whole NLP as casadi Functions of (x, p)."""
        ca, (x, f, g) = self._ca, (self._nlp["x"], self._nlp["f"], self._nlp["g"])
        p = ca.SX.sym("p", 0)
        nlp = ca.Function("nlp", [x, p], [f, g], ["x", "p"], ["f", "g"])
        grad = ca.Function("nlp_grad_f", [x, p], [f, ca.gradient(f, x)], ["x", "p"], ["f", "grad_f_x"])
        if self._assembly is None:
            return nlp, grad
        n, n_nl, c0 = len(self.variables), self._n_nl, self._nl_col0
        X, P = ca.MX.sym("x", n), ca.MX.sym("p", 0)
        f_nl, g_nl = nlp(X[c0:c0 + n_nl], P)
        f_g, gf = grad(X[c0:c0 + n_nl], P)
        rows = self._assembly.rows(X)
        g = ca.vertcat(rows, g_nl) if self._nl_row0 else ca.vertcat(g_nl, rows)
        return (ca.Function("nlp", [X, P], [f_nl, g], ["x", "p"], ["f", "g"]),
                # dense: casadi hands Ipopt the output buffer as it is, and the structural zeros of a
                # sparse gradient would be whatever the buffer held (seen: inf_du 1e12 at iteration 0)
                ca.Function("nlp_grad_f", [X, P],
                            [f_g, ca.densify(ca.vertcat(ca.MX(c0, 1), gf, ca.MX(n - n_nl - c0, 1)))], ["x", "p"],
                            ["f", "grad_f_x"]))

    def _nl_hessian_function(self):
        """Lagrangian Hessian of the NL part built block-wise, or None for casadi's default.

        casadi's Hessian is one symmetric (star) colouring of the whole
        Hessian and one forward sweep over the gradient graph per colour. On
        the identification NLPs, 8 dense columns (free parameters, trim
        controls used at every collocation point) and ~40 trim-block variables
        that couple in a dense ~50x50 block force 53 colours, although the
        rest needs 7: 45 s at 25k variables. Split of the columns:

        * ``S``: the rest - one symmetric casadi Jacobian of grad[S] w.r.t. x[S];
        * ``D2``: dense in the Hessian but in few Jacobian rows - rows of the
          Hessian by reverse mode, over the small subgraph of grad[D2];
        * ``D1``: the dense Jacobian columns (see :meth:`_jacobian_function`),
          dense in the Hessian too on these NLPs - rows of the Hessian by
          reverse mode (few colours, large subgraph).

        The blocks together cover the Hessian exactly once up to symmetry;
        the values equal casadi's up to rounding.
        """
        ca = self._ca
        x, f, g = self._nlp["x"], self._nlp["f"], self._nlp["g"]
        n, m = x.shape[0], g.shape[0]
        lam_f = ca.SX.sym("lam_f")
        lam_g = ca.SX.sym("lam_g", m)
        grad = ca.gradient(lam_f * f + ca.dot(lam_g, g), x)
        # The dense Jacobian columns are D1 whatever their Hessian degree, so the Hessian's
        # sparsity is only needed for the other columns: the pattern of grad[rest] w.r.t.
        # x[rest]. Without the dense columns casadi's bitwise propagation stays cheap
        # (docs/performance.md, "What was done" 7).
        d1 = list(self._dense_cols)
        rest = np.setdiff1d(np.arange(n), d1)
        hsp = ca.Function("nlp_grad_l", [x, lam_f, lam_g], [grad[rest.tolist()]]).jac_sparsity(0, 0)
        degree = np.diff(np.array(hsp.colind(), dtype=int))[rest]
        # 90th percentile: the ~45 dense Hessian columns (objective settings,
        # trim-block variables coupled through J_trim) are more than 1 % of a
        # small NLP; with the 99th percentile they hid themselves and the
        # symmetric colouring of the rest took 8.5 s instead of 2.2 s at 3k
        # variables (benchmark --quick, docs/performance.md).
        d2 = rest[self._dense(degree, percentile=self.settings.hessian_dense_percentile)].tolist()
        if not d1 and not d2:
            return None
        dense = d1 + d2
        s = np.setdiff1d(np.arange(n), dense).tolist()
        ns, n2 = len(s), len(d2)
        self._hessian_split = {"S": ns, "D2": n2, "D1": len(d1)}
        perm = s + d2 + d1
        h_ss = ca.jacobian(grad[s], x[s], {"symmetric": True})
        h_2 = ca.jacobian(grad[d2], x[s + d2]) if d2 else ca.SX(0, ns)  # rows D2, columns S + D2
        h_1 = ca.jacobian(grad[d1], x[perm]).T if d1 else ca.SX(n, 0)  # columns D1, rows S + D2 + D1
        h_2s, h_22 = h_2[:, :ns], h_2[:, ns:]
        h_1s, h_12, h_11 = h_1[:ns, :], h_1[ns:ns + n2, :], h_1[ns + n2:, :]
        hp = ca.vertcat(
            ca.horzcat(h_ss, h_2s.T, h_1s),
            ca.horzcat(h_2s, h_22, h_12),
            ca.horzcat(h_1s.T, h_12.T, h_11),
        )
        back = np.argsort(perm).tolist()
        hess = ca.triu(hp[back, back])
        p = ca.SX.sym("p", 0)
        return ca.Function(
            "nlp_hess_l", [x, p, lam_f, lam_g], [hess], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]
        )
