"""Numba kernels of the finite element assembly: pure functions over plain arrays.

Notation: ``nb`` cells in a batch, ``nq`` quadrature points, ``nl`` local Q2 nodes, ``d`` the
dimension. ``Jinv[c, q, l, i] = d xi_l / d x_i`` is the inverse Jacobian of the multilinear cell
map, ``detJw[c, q] = |det J| w_q``. Every kernel is checked against a plain NumPy reference in
``tests/fem/test_kernels.py``.
"""
import numpy as np

from .._jit import jitable, njit, prange


@njit(parallel=True)
def cell_geometry(cell_coords, dN, weights):
    """Jacobians of the multilinear maps at the quadrature points.

    Parameters
    ----------
    cell_coords : (n_cells, n_v, d) float64   vertex coordinates per cell
    dN : (nq, n_v, d) float64                  reference gradients of the Q1 basis
    weights : (nq,) float64                    quadrature weights

    Returns
    -------
    detJw : (n_cells, nq) float64   |det J| times the weight
    Jinv : (n_cells, nq, d, d) float64   ``Jinv[c, q, l, i] = d xi_l / d x_i``
    """
    n_cells, n_v, d = cell_coords.shape
    nq = dN.shape[0]
    detJw = np.empty((n_cells, nq))
    Jinv = np.empty((n_cells, nq, d, d))
    for c in prange(n_cells):
        J = np.zeros((d, d))
        for q in range(nq):
            J[:, :] = 0.0
            for v in range(n_v):
                for i in range(d):
                    for ax in range(d):
                        J[i, ax] += cell_coords[c, v, i] * dN[q, v, ax]  # J[i, ax] = dx_i/dxi_ax
            if d == 2:
                det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
                Jinv[c, q, 0, 0] = J[1, 1] / det
                Jinv[c, q, 0, 1] = -J[0, 1] / det
                Jinv[c, q, 1, 0] = -J[1, 0] / det
                Jinv[c, q, 1, 1] = J[0, 0] / det
            else:
                det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
                       - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
                       + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
                for ax in range(3):
                    for i in range(3):
                        # inverse = adjugate / det; adj[ax, i] = cofactor[i, ax]
                        r0, r1 = (i + 1) % 3, (i + 2) % 3
                        c0, c1 = (ax + 1) % 3, (ax + 2) % 3
                        Jinv[c, q, ax, i] = (J[r0, c0] * J[r1, c1] - J[r0, c1] * J[r1, c0]) / det
            detJw[c, q] = abs(det) * weights[q]
    return detJw, Jinv


@njit(inline="always")
def _point_convection(e, c, q, uq, detJw, Jinv, conv):
    """``conv[e, q d + ax] = w (Jinv uq)_ax`` at point ``q`` of cell ``c`` for the velocity ``uq``
    (d,) there; returns the point's weight ``w = detJw[c, q]``."""
    d = uq.shape[0]
    w = detJw[c, q]
    for ax in range(d):
        s = 0.0
        for i in range(d):
            s += Jinv[c, q, ax, i] * uq[i]
        conv[e, q * d + ax] = w * s
    return w


@njit(inline="always")
def _cell_velocities(c, u, cell_dofs, ul):
    """The nodal velocities of cell ``c`` into ``ul (d, nl)``: ``ul[i, a] = u[i, cell_dofs[c, a]]``
    (read once, not once per point)."""
    for a in range(cell_dofs.shape[1]):
        dof = cell_dofs[c, a]
        for i in range(ul.shape[0]):
            ul[i, a] = u[i, dof]


@njit(inline="always")
def _convection_cell(e, c, ul, phi, detJw, Jinv, conv, uq):
    """:func:`convection_coefficients`' ``conv`` row ``e`` of cell ``c`` from its nodal velocities
    ``ul (d, nl)`` (``uq (d,)`` work)."""
    nq, nl = phi.shape
    for q in range(nq):
        for i in range(ul.shape[0]):
            s = 0.0
            for a in range(nl):
                s += ul[i, a] * phi[q, a]
            uq[i] = s
        _point_convection(e, c, q, uq, detJw, Jinv, conv)


@njit(inline="always")
def _newton_cell(e, c, ul, phi, dphi, detJw, Jinv, conv, react, uq, gref):
    """:func:`convection_coefficients`' ``conv`` row ``e`` and ``react`` rows ``e d d ...`` of
    cell ``c`` from its nodal velocities ``ul (d, nl)`` (``uq (d,)``, ``gref (d, d)`` work)."""
    nq, nl, d = dphi.shape
    for q in range(nq):
        for i in range(d):
            s = 0.0
            for a in range(nl):
                s += ul[i, a] * phi[q, a]
            uq[i] = s
            for ax in range(d):
                g = 0.0
                for a in range(nl):
                    g += ul[i, a] * dphi[q, a, ax]
                gref[i, ax] = g
        w = _point_convection(e, c, q, uq, detJw, Jinv, conv)
        for i in range(d):
            for k in range(d):
                s = 0.0
                for ax in range(d):
                    s += gref[i, ax] * Jinv[c, q, ax, k]
                react[(e * d + i) * d + k, q] = w * s


@njit(parallel=True)
def convection_coefficients(cells, u, cell_dofs, phi, dphi, detJw, Jinv, newton, chunks):
    """Quadrature-point coefficients of the convection and Newton (reaction) terms.

    With ``u_h = sum_a u_a phi_a`` (component-wise) the local matrices are

        N[a, b] = sum_q sum_l conv[q, l] phi_a(q) dphi_b/dxi_l(q)              (u . grad) term
        R_ik[a, b] = sum_q react[i, k, q] phi_a(q) phi_b(q)                      (grad u) term

    where ``conv[q, l] = detJw (Jinv u_h)_l`` and ``react[i, k, q] = detJw d u_i / d x_k``.
    The cells in ``chunks`` contiguous chunks in parallel, each with its own work arrays.

    Parameters
    ----------
    cells : (nb,) int64             cells of the batch (-1 = padding, left zero)
    u : (d, n_dofs) float64         velocity, component-blocked
    cell_dofs : (n_cells, nl) int64
    phi : (nq, nl), dphi : (nq, nl, d) float64   reference tabulation
    detJw : (n_cells, nq), Jinv : (n_cells, nq, d, d) float64
    newton : bool                   also compute ``react``
    chunks : int                    chunks of cells (a few per thread)

    Returns
    -------
    conv : (nb, nq * d) float64
    react : (nb * d * d, nq) float64 (zero rows when ``newton`` is False)
    """
    nb = cells.shape[0]
    nq, nl, d = dphi.shape
    conv = np.zeros((nb, nq * d))
    react = np.zeros((nb * d * d, nq)) if newton else np.zeros((0, nq))
    n_chunks = max(1, min(nb, chunks))
    for t in prange(n_chunks):
        ul, uq, gref = np.empty((d, nl)), np.empty(d), np.empty((d, d))
        for e in range(t * nb // n_chunks, (t + 1) * nb // n_chunks):
            c = cells[e]
            if c < 0:
                continue
            _cell_velocities(c, u, cell_dofs, ul)
            if newton:
                _newton_cell(e, c, ul, phi, dphi, detJw, Jinv, conv, react, uq, gref)
            else:  # the velocity alone: the gradient's loop left out, 2.5x as fast
                _convection_cell(e, c, ul, phi, detJw, Jinv, conv, uq)
    return conv, react


@njit(parallel=True)
def rows_times(a, b, out, chunks):
    """``out = a @ b`` for C-contiguous float64 ``a (m, k)``, ``b (k, n)``, ``out (m, n)``: the
    rows of ``a`` in ``chunks`` contiguous chunks, one BLAS product each, the chunks in parallel
    (a batch's local matrices from its coefficients and a reference table on every thread; BLAS
    itself on one thread, :func:`~fbmflow.fem.assembly.single_threaded_blas`)."""
    m = a.shape[0]
    for k in prange(chunks):
        lo, hi = m * k // chunks, m * (k + 1) // chunks
        if hi > lo:
            np.dot(a[lo:hi], b, out[lo:hi])


@njit(parallel=True)
def mass_laplace_coefficients(detJw, Jinv, alpha, beta):
    """The coefficients of :attr:`~fbmflow.fem.space.FlowSpace.table_mass_laplace` per cell:
    ``alpha detJw[q]`` for every point ``q``, then ``beta detJw[q] (Jinv Jinv^T)[l, m]`` for every
    point and pair ``l <= m``; (n_cells, nq (1 + d (d + 1) / 2)) float64."""
    n_cells, nq, d, _ = Jinv.shape
    pairs = d * (d + 1) // 2
    out = np.empty((n_cells, nq * (1 + pairs)))
    for c in prange(n_cells):
        for q in range(nq):
            out[c, q] = alpha * detJw[c, q]
            k = nq + q * pairs
            for ax in range(d):
                for m in range(ax, d):
                    s = 0.0
                    for i in range(d):
                        s += Jinv[c, q, ax, i] * Jinv[c, q, m, i]
                    out[c, k] = beta * detJw[c, q] * s
                    k += 1
    return out


@njit
def node_cells(cell_dofs, n):
    """The cells of every node: ``(ptr (n + 1,) int64, cells (n_cells nl,) int32)``, node ``a``'s
    cells ``cells[ptr[a]:ptr[a + 1]]`` ascending; ``cell_dofs (n_cells, nl)``, ``n`` nodes."""
    n_cells, nl = cell_dofs.shape
    ptr = np.zeros(n + 1, dtype=np.int64)
    for c in range(n_cells):
        for a in range(nl):
            ptr[cell_dofs[c, a] + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    cells = np.empty(ptr[n], dtype=np.int32)
    for c in range(n_cells):
        for a in range(nl):
            node = cell_dofs[c, a]
            cells[fill[node]] = c
            fill[node] += 1
    return ptr, cells


@njit
def _row_columns(node, cell_dofs, ptr, cells, work):
    """The nodes that share a cell with ``node``, ascending, into ``work``; returns their count."""
    nl = cell_dofs.shape[1]
    m = 0
    for j in range(ptr[node], ptr[node + 1]):
        for b in range(nl):
            work[m] = cell_dofs[cells[j], b]
            m += 1
    row = work[:m]
    row.sort()
    k = 0
    for j in range(m):
        if j == 0 or row[j] != row[k - 1]:
            row[k] = row[j]
            k += 1
    return k


@njit(parallel=True)
def scalar_pattern(cell_dofs, n, n_chunks):
    """CSR pattern ``(indptr (n + 1,) int64, indices int32)`` of a scalar operator on ``n``
    nodes coupling every two nodes of a cell, columns ascending in each row; nodes in
    ``n_chunks`` parallel chunks. Nothing larger than the pattern itself is allocated (a sort of
    every cell's node pairs needed 4 arrays of ``n_cells nl^2`` int64)."""
    ptr, cells = node_cells(cell_dofs, n)
    nl = cell_dofs.shape[1]
    most = 0
    for i in range(n):
        most = max(most, ptr[i + 1] - ptr[i])
    indptr = np.zeros(n + 1, dtype=np.int64)
    for t in prange(n_chunks):
        work = np.empty(most * nl, dtype=cell_dofs.dtype)
        for i in range(t * n // n_chunks, (t + 1) * n // n_chunks):
            indptr[i + 1] = _row_columns(i, cell_dofs, ptr, cells, work)
    for i in range(n):
        indptr[i + 1] += indptr[i]
    indices = np.empty(indptr[n], dtype=np.int32)
    for t in prange(n_chunks):
        work = np.empty(most * nl, dtype=cell_dofs.dtype)
        for i in range(t * n // n_chunks, (t + 1) * n // n_chunks):
            k = _row_columns(i, cell_dofs, ptr, cells, work)
            for j in range(k):
                indices[indptr[i] + j] = work[j]
    return indptr, indices


@njit(parallel=True)
def pattern_offsets(cell_dofs, indptr, indices):
    """Where the pair ``(a, b)`` of cell ``c`` sits within the row of its node ``a``:
    ``indices[indptr[cell_dofs[c, a]] + out[c, a, b]] == cell_dofs[c, b]``, (n_cells, nl, nl)
    uint8 (rows of at most 256 entries)."""
    n_cells, nl = cell_dofs.shape
    out = np.empty((n_cells, nl, nl), dtype=np.uint8)
    for c in prange(n_cells):
        for a in range(nl):
            r = cell_dofs[c, a]
            row = indices[indptr[r]:indptr[r + 1]]
            for b in range(nl):
                out[c, a, b] = np.searchsorted(row, cell_dofs[c, b])
    return out


@njit(parallel=True)
def scatter_scalar(cells, local, offsets, cell_dofs, indptr, out):
    """``out[indptr[cell_dofs[c, a]] + offsets[c, a, b]] += local[e, a * nl + b]`` for a batch
    of cells.

    cells (n_groups, length) int64, -1 = padding; local (n_groups * length, nl * nl) float64 with
    row ``e = g * length + j`` for ``cells[g, j]``; offsets (n_cells, nl, nl) uint8 positions
    within the rows of the scalar Q2 pattern (``FlowSpace.offsets``), cell_dofs (n_cells, nl)
    int64, indptr (n + 1,) int64 of that pattern; out (nnz,) float64, updated in place. Groups
    must not share DOFs: they run in parallel, each sequentially.
    """
    n_groups, length = cells.shape
    nl = offsets.shape[1]
    for g in prange(n_groups):
        for j in range(length):
            c = cells[g, j]
            if c < 0:
                continue
            e = g * length + j
            for a in range(nl):
                start = indptr[cell_dofs[c, a]]
                for b in range(nl):
                    out[start + offsets[c, a, b]] += local[e, a * nl + b]


@njit(parallel=True)
def scatter_coupled(cells, conv, react, sym, offsets, cell_dofs, indptr, d, out):
    """Scatter ``delta_ik N + R_ik`` into the coupled velocity matrix.

    The coupled matrix has rows ``(i, r)`` = ``i * n + r`` and, within a row, the columns of
    component 0, then 1, ... each in the order of the scalar pattern. Hence the entry
    ``(i, r), (k, s)`` sits at ``i d nnz + d indptr[r] + k len_r + offset(r, s)``.

    cells (n_groups, length) int64, -1 = padding, groups DOF-disjoint; conv
    (n_groups * length, nl * nl) float64 local convection matrices, row ``e = g * length + j``;
    react (n_groups * length * d * d, n_sym) float64 local Newton blocks, rows ordered (e, i, k),
    stored as upper triangles (they are symmetric in ``a, b``); sym (nl, nl) int64 maps ``(a, b)``
    to the triangle column; offsets (n_cells, nl, nl) uint8 (``FlowSpace.offsets``); cell_dofs
    (n_cells, nl) int64; indptr (n + 1,) int64 of the scalar pattern; d int; out
    (d * d * nnz,) float64 updated in place.
    """
    n_groups, length = cells.shape
    nl = offsets.shape[1]
    nnz = indptr[-1]
    for g in prange(n_groups):
        for j in range(length):
            c = cells[g, j]
            if c < 0:
                continue
            e = g * length + j
            for a in range(nl):
                r = cell_dofs[c, a]
                start = indptr[r]
                ln = indptr[r + 1] - start
                for i in range(d):
                    base = i * d * nnz + d * start
                    row = (e * d + i) * d
                    for b in range(nl):
                        off = base + offsets[c, a, b]
                        t = sym[a, b]
                        for k in range(d):
                            out[off + k * ln] += react[row + k, t]
                        out[off + i * ln] += conv[e, a * nl + b]


@njit(parallel=True)
def divergence_local(dphi, detJw, Jinv, psi, rank, out):
    """Data of ``B^T``: ``B^T[(c, m), (i, a)] = -int_c psi_m d phi_a / d x_i``.

    Row ``(c, m)`` of the CSR matrix ``B^T`` holds ``d * nl`` entries: component ``i``, then the
    cell's DOFs in ascending global order (``rank[c, a]`` is the position of local node ``a``).

    dphi (nq, nl, d); detJw (n_cells, nq); Jinv (n_cells, nq, d, d); psi (n_cells, nq, d + 1)
    pressure basis at the quadrature points; rank (n_cells, nl) int64;
    out (n_cells * (d + 1) * d * nl,) float64, overwritten.
    """
    nq, nl, d = dphi.shape
    n_cells = detJw.shape[0]
    npl = d + 1
    for c in prange(n_cells):
        local = np.zeros((npl, d, nl))
        for q in range(nq):
            for a in range(nl):
                for i in range(d):
                    g = 0.0
                    for ax in range(d):
                        g += dphi[q, a, ax] * Jinv[c, q, ax, i]
                    g *= detJw[c, q]
                    for m in range(npl):
                        local[m, i, a] += psi[c, q, m] * g
        for m in range(npl):
            row = (c * npl + m) * d * nl
            for i in range(d):
                for a in range(nl):
                    out[row + i * nl + rank[c, a]] = -local[m, i, a]


@njit(parallel=True)
def set_identity_rows(indptr, indices, rows, data):
    """Replace CSR rows ``rows`` by unit rows (1 on the diagonal, 0 elsewhere), in place.

    indptr (n + 1,) int64; indices (nnz,) int32; rows (n_rows,) int64; data (nnz,) float64.
    """
    for j in prange(rows.shape[0]):
        r = rows[j]
        for s in range(indptr[r], indptr[r + 1]):
            data[s] = 1.0 if indices[s] == r else 0.0


@njit
def replace_rows(indptr, indices, data, rows, r_indptr, r_indices, r_data):
    """Replace CSR rows ``rows`` (n_rows,) of ``(indptr, indices, data)`` by the rows of the
    small CSR matrix ``(r_indptr, r_indices, r_data)`` (n_rows rows, same columns; duplicates
    summed), in place, if all its entries lie in the pattern. Column indices sorted within
    rows in both. Returns False, changing nothing, when an entry does not fit."""
    for j in range(rows.shape[0]):  # check first: all or nothing
        r = rows[j]
        q, end = indptr[r], indptr[r + 1]
        for k in range(r_indptr[j], r_indptr[j + 1]):
            while q < end and indices[q] < r_indices[k]:
                q += 1
            if q == end or indices[q] != r_indices[k]:
                return False
    for j in range(rows.shape[0]):
        r = rows[j]
        q, end = indptr[r], indptr[r + 1]
        data[q:end] = 0.0
        for k in range(r_indptr[j], r_indptr[j + 1]):
            while indices[q] < r_indices[k]:
                q += 1
            data[q] += r_data[k]
    return True


# -- matrix-free operators: values at the quadrature points, tested with the Q2 basis ----------
@jitable
def _point_values(c, u, cell_dofs, phi, dphi, Jinv, ul, uq, gq):
    """Velocity ``uq (nq, d)`` and gradient ``gq (nq, d, d)`` (``d u_i / d x_k``) of ``u (d, n_v)``
    at the quadrature points of cell ``c``, ``d`` 2 or 3; ``ul (d, nl)`` work. One pass over the
    cell's nodes per point and component, nothing allocated (the kernels call it per cell in
    parallel loops)."""
    nq, nl = phi.shape
    d = u.shape[0]
    for a in range(nl):
        dof = cell_dofs[c, a]
        for i in range(d):
            ul[i, a] = u[i, dof]
    for q in range(nq):
        for i in range(d):
            s = 0.0
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            for a in range(nl):
                v = ul[i, a]
                s += v * phi[q, a]
                g0 += v * dphi[q, a, 0]
                g1 += v * dphi[q, a, 1]
                if d == 3:
                    g2 += v * dphi[q, a, 2]
            uq[q, i] = s
            for k in range(d):  # reference gradient to physical: sum over the reference axes
                t = g0 * Jinv[c, q, 0, k] + g1 * Jinv[c, q, 1, k]
                if d == 3:
                    t += g2 * Jinv[c, q, 2, k]
                gq[q, i, k] = t


@njit(parallel=True)
def reaction_coefficients(u, cell_dofs, phi, dphi, detJw, Jinv):
    """``|det J| w_q d u_i / d x_k`` at every cell's quadrature points, (n_cells, nq, d, d)
    float32 (computed in float64, stored rounded: a Jacobian's term, where 1e-7 relative changes
    only the Newton step's convergence, not its residual), for ``u (d, n_v)``; cell_dofs
    (n_cells, nl) int64, phi (nq, nl), dphi (nq, nl, d) reference tabulation, detJw
    (n_cells, nq), Jinv (n_cells, nq, d, d)."""
    n_cells, nl = cell_dofs.shape
    nq = phi.shape[0]
    d = u.shape[0]
    react = np.empty((n_cells, nq, d, d), dtype=np.float32)
    for c in prange(n_cells):
        ul = np.empty((d, nl))
        uq = np.empty((nq, d))
        gq = np.empty((nq, d, d))
        reaction_at(c, u, cell_dofs, phi, dphi, detJw, Jinv, react, ul, uq, gq)
    return react


@jitable
def reaction_at(c, u, cell_dofs, phi, dphi, detJw, Jinv, react, ul, uq, gq):
    """Cell ``c``'s row of :func:`reaction_coefficients`, ``react[c] (nq, d, d)``, written;
    scratch ``ul (d, nl)``, ``uq (nq, d)``, ``gq (nq, d, d)`` (or larger)."""
    _point_values(c, u, cell_dofs, phi, dphi, Jinv, ul, uq, gq)
    for q in range(phi.shape[0]):
        for i in range(u.shape[0]):
            for k in range(u.shape[0]):
                react[c, q, i, k] = gq[q, i, k] * detJw[c, q]


@jitable
def _test(c, fq, phi, cell_dofs, scale, out):
    """``out[i, dof(c, a)] += scale sum_q phi[q, a] fq[q, i]`` (``fq (nq, d)`` already weighted;
    ``d`` is ``out``'s first axis, so ``fq`` may be a larger scratch array)."""
    nq, nl = phi.shape
    d = out.shape[0]
    for a in range(nl):
        dof = cell_dofs[c, a]
        for i in range(d):
            s = 0.0
            for q in range(nq):
                s += phi[q, a] * fq[q, i]
            out[i, dof] += scale * s


@jitable
def _values(c, w, cell_dofs, phi, wq):
    """Values ``wq (nq, d)`` of ``w (d, n_v)`` at the quadrature points of cell ``c``, overwritten
    (zero DOF values skipped: sparse fields, e.g. a lifting, cost only their non-zeros; ``wq``
    may be a larger scratch array)."""
    nq, nl = phi.shape
    for q in range(nq):
        for k in range(w.shape[0]):
            wq[q, k] = 0.0
    for b in range(nl):
        dof = cell_dofs[c, b]
        for k in range(w.shape[0]):
            wb = w[k, dof]
            if wb != 0.0:
                for q in range(nq):
                    wq[q, k] += phi[q, b] * wb


@njit(parallel=True)
def apply_reaction(cells, react, cell_dofs, phi, w, scale, out):
    """Add ``scale R(u) w`` to ``out``: the Newton term ``R_ik[a, b] = int phi_a phi_b d u_i/d x_k``
    applied without a matrix (:func:`reaction_cell` per cell).

    cells (n_groups, length) int64, -1 = padding, groups DOF-disjoint (they run in parallel, each
    sequentially); react (n_cells, nq, d, d) float32 or float64, ``|det J| w_q d u_i / d x_k``; cell_dofs
    (n_cells, nl) int64; phi (nq, nl); w (d, n_v) float64; out (d, n_v) float64, updated in place.
    """
    n_groups, length = cells.shape
    nq = phi.shape[0]
    d = w.shape[0]
    for g in prange(n_groups):
        wq = np.empty((nq, d))
        fq = np.empty((nq, d))
        for j in range(length):
            c = cells[g, j]
            if c >= 0:
                reaction_cell(c, react, cell_dofs, phi, w, scale, out, wq, fq)


@jitable
def reaction_cell(c, react, cell_dofs, phi, w, scale, out, wq, fq):
    """Add cell ``c``'s part of ``scale R(u) w`` to ``out``: ``out[i, a] += scale sum_q phi_a(q)
    sum_k react[c, q, i, k] w_k(q)``; scratch ``wq``, ``fq (nq, d)`` (or larger). One body for the
    CPU kernel and the GPU's (:mod:`fbmflow.gpu.operators`)."""
    nq = phi.shape[0]
    d = w.shape[0]
    _values(c, w, cell_dofs, phi, wq)
    for q in range(nq):
        for i in range(d):
            s = 0.0
            for k in range(d):
                s += react[c, q, i, k] * wq[q, k]
            fq[q, i] = s
    _test(c, fq, phi, cell_dofs, scale, out)


@njit(parallel=True)
def velocity_coefficients(u, cell_dofs, phi, detJw):
    """``|det J| w_q u_k`` at every cell's quadrature points, (n_cells, nq, d) float64, for
    ``u (d, n_v)``: what :func:`apply_convection` needs of the convecting velocity
    (:func:`velocity_at` per cell)."""
    n_cells = cell_dofs.shape[0]
    nq = phi.shape[0]
    d = u.shape[0]
    conv = np.empty((n_cells, nq, d))
    for c in prange(n_cells):
        velocity_at(c, u, cell_dofs, phi, detJw, conv)
    return conv


@jitable
def velocity_at(c, u, cell_dofs, phi, detJw, conv):
    """Cell ``c``'s row of :func:`velocity_coefficients`, ``conv[c] (nq, d)``, written."""
    _values(c, u, cell_dofs, phi, conv[c])
    for q in range(phi.shape[0]):
        for k in range(u.shape[0]):
            conv[c, q, k] *= detJw[c, q]


@njit(parallel=True)
def apply_cell_operator(cells, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, w, out):
    """Add ``(alpha M + beta L + gamma N(c)) w_i`` to ``out[i]`` for every component, by quadrature
    cell by cell, without a matrix (:func:`cell_operator` per cell). ``w``, ``out`` (d, n_v)
    float64; cells (n_groups, length) int64 in parallel groups of DOF-disjoint cells (-1 =
    padding), each group in order."""
    n_groups, length = cells.shape
    nq, nl = phi.shape
    d = w.shape[0]
    own = conv.shape[0] == 0
    for g in prange(n_groups):
        wl = np.empty((d, nl))
        wq = np.empty((nq, d))
        gq = np.empty((nq, d, d))
        value = np.empty((nq, d))
        flux = np.empty((nq, d, d))
        for j in range(length):
            c = cells[g, j]
            if c >= 0:
                cell_operator(c, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out, wl,
                              wq, gq, value, flux)


@jitable
def cell_operator(c, detJw, Jinv, cell_dofs, phi, dphi, alpha, beta, gamma, conv, own, w, out, wl, wq, gq,
                  value, flux):
    """Add cell ``c``'s part of ``(alpha M + beta L + gamma N(c)) w_i`` to ``out[i]``: ``alpha int
    phi_a w_i + beta int grad phi_a . grad w_i + gamma int phi_a (c . grad) w_i`` by quadrature,
    the convecting velocity ``c`` given by ``conv (n_cells, nq, d)``, ``|det J| w_q c_k``
    (:func:`velocity_coefficients`; not read where ``gamma`` is 0), or ``w`` itself where ``own``
    (``N(w) w``, from the point values: no coefficient array). ``w``, ``out`` (d, n_v) float64;
    scratch ``wl (d, nl)``, ``wq``, ``value (nq, d)``, ``gq``, ``flux (nq, d, d)`` (or larger);
    one body for the CPU kernel and the GPU's (:mod:`fbmflow.gpu.operators`)."""
    nq, nl = phi.shape
    d = w.shape[0]
    _point_values(c, w, cell_dofs, phi, dphi, Jinv, wl, wq, gq)
    for q in range(nq):  # what each point gives the test functions' values and gradients
        weight = detJw[c, q]
        for i in range(d):
            s = alpha * weight * wq[q, i]
            if gamma != 0.0:
                t = 0.0
                if own:
                    for k in range(d):
                        t += weight * wq[q, k] * gq[q, i, k]
                else:
                    for k in range(d):
                        t += conv[c, q, k] * gq[q, i, k]
                s += gamma * t
            value[q, i] = s
            if beta != 0.0:  # beta |det J| w_q grad w_i, to the reference axes
                for ax in range(d):
                    t = 0.0
                    for k in range(d):
                        t += Jinv[c, q, ax, k] * gq[q, i, k]
                    flux[q, i, ax] = beta * weight * t
    _test(c, value, phi, cell_dofs, 1.0, out)
    if beta != 0.0:  # tested with the reference gradients
        for a in range(nl):
            dof = cell_dofs[c, a]
            for i in range(d):
                s = 0.0
                for q in range(nq):
                    for ax in range(d):
                        s += dphi[q, a, ax] * flux[q, i, ax]
                out[i, dof] += s


@njit
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit
def free_components(cell_dofs, free):
    """Connected components of the ``free`` nodes, two free nodes joined where they share a cell
    (``cell_dofs`` (n_cells, nl)): a label per node, the smallest node index of its component, -1
    for nodes that are not free. Union-find joining every cell's free nodes to its first free one
    (the same components as joining every pair), O(n_cells nl): ten Cate level 2 5.5 M unions
    instead of the scalar pattern's 36 M entries."""
    n = free.size
    parent = np.arange(n)
    for c in range(cell_dofs.shape[0]):
        first = -1
        for a in range(cell_dofs.shape[1]):
            j = cell_dofs[c, a]
            if not free[j]:
                continue
            if first < 0:
                first = _root(parent, j)
                continue
            b = _root(parent, j)
            if b < first:
                parent[first] = b
                first = b
            elif b > first:
                parent[b] = first
    labels = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if free[i]:
            labels[i] = _root(parent, i)
    return labels


# -- the velocity block stored once per scalar (fbmflow.fem.velocity_block) -------------------
def _block_apply(indptr, indices, data, d, x, out):
    """``out = diag(S, ..., S) x`` for the scalar CSR ``S (n_v, n_v)`` and ``x, out (d n_v,)``,
    ``d`` 2 or 3: one pass over each row of ``S`` for all components, each component's sum in
    storage order (as the assembled block's row)."""
    n = indptr.shape[0] - 1
    for a in prange(n):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(indptr[a], indptr[a + 1]):
            v = data[k]
            j = indices[k]
            s0 += v * x[j]
            s1 += v * x[n + j]
            if d == 3:
                s2 += v * x[2 * n + j]
        out[a] = s0
        out[n + a] = s1
        if d == 3:
            out[2 * n + a] = s2


block_apply = njit(parallel=True)(_block_apply)
block_apply_serial = njit(_block_apply)


@njit(parallel=True)
def uniform_rows_apply(indices, values, width, x, out):
    """``out = M x`` for a CSR matrix ``M`` with ``width`` entries in every row (its indices and
    values, row after row); rows in parallel, each row's sum in storage order (the result equals
    SciPy's and does not depend on the number of threads)."""
    for r in prange(out.shape[0]):
        s = 0.0
        for j in range(r * width, (r + 1) * width):
            s += values[j] * x[indices[j]]
        out[r] = s


@njit(parallel=True)
def rows_touching(indices, n_rows, width, mask):
    """For every row of a CSR pattern of ``n_rows`` rows with ``width`` entries each (its
    indices, row after row) whether one of its columns is set in ``mask``: (n_rows,) bool."""
    out = np.zeros(n_rows, dtype=np.bool_)
    for r in prange(n_rows):
        for j in range(r * width, (r + 1) * width):
            if mask[indices[j]]:
                out[r] = True
                break
    return out


@njit(parallel=True)
def override_rows(dofs, o_ptr, o_idx, o_val, x, out):
    """``out[dofs[j]] = O[j] . x`` for the CSR rows ``O`` (n_o rows, columns into ``x``; the
    ``dofs`` distinct); rows in parallel, each row's sum in storage order."""
    for j in prange(dofs.shape[0]):
        s = 0.0
        for k in range(o_ptr[j], o_ptr[j + 1]):
            s += o_val[k] * x[o_idx[k]]
        out[dofs[j]] = s


@njit
def shifted_copies(ptr, idx, val, pos, n_v):
    """For every row ``j`` of ``pos (m, d)`` (row numbers into the CSR ``(ptr, idx, val)``, -1
    where absent): whether the rows ``pos[j, i]`` all exist and are row ``pos[j, 0]`` with its
    columns (all below ``n_v``) shifted by ``i n_v``. (m,) bool."""
    m, d = pos.shape
    out = np.zeros(m, dtype=np.bool_)
    for j in range(m):
        first = pos[j, 0]
        if first < 0:
            continue
        start, ln = ptr[first], ptr[first + 1] - ptr[first]
        same = True
        for k in range(ln):
            if idx[start + k] >= n_v:
                same = False
        for i in range(1, d):
            r = pos[j, i]
            if not same or r < 0 or ptr[r + 1] - ptr[r] != ln:
                same = False
                break
            for k in range(ln):
                if idx[ptr[r] + k] != idx[start + k] + i * n_v or val[ptr[r] + k] != val[start + k]:
                    same = False
                    break
        out[j] = same
    return out


@njit
def gather_lengths(rows, indptr, n_v, o_pos, o_ptr):
    """Row pointers (k + 1,) int64 of :func:`gather_rows`'s rows ``rows (k,)``."""
    k = rows.shape[0]
    ptr = np.zeros(k + 1, dtype=np.int64)
    for j in range(k):
        r = rows[j]
        q = o_pos[r]
        ptr[j + 1] = ptr[j] + (o_ptr[q + 1] - o_ptr[q] if q >= 0 else indptr[r % n_v + 1] - indptr[r % n_v])
    return ptr


@njit(parallel=True)
def gather_rows(rows, indptr, indices, data, n_v, o_pos, o_ptr, o_idx, o_val, shift, ptr, idx, val):
    """Write the rows ``rows (k,)`` of ``diag(S, ..., S)`` (scalar CSR ``S``), the rows with
    ``o_pos[r] >= 0`` replaced by row ``o_pos[r]`` of ``O``, into the CSR arrays ``(ptr, idx,
    val)`` (``ptr`` from :func:`gather_lengths`); columns into the whole velocity vector, or,
    where ``shift`` is False, the scalar rows' node columns (``S``'s own). Rows in parallel."""
    for j in prange(rows.shape[0]):
        r = rows[j]
        q = o_pos[r]
        s = ptr[j]
        if q >= 0:
            for t in range(o_ptr[q], o_ptr[q + 1]):
                idx[s] = o_idx[t]
                val[s] = o_val[t]
                s += 1
        else:
            a, off = r % n_v, (r // n_v) * n_v if shift else 0
            for t in range(indptr[a], indptr[a + 1]):
                idx[s] = indices[t] + off
                val[s] = data[t]
                s += 1


@njit(parallel=True)
def continuity_rows(rows, position, width, b_idx, b_val, o_ptr, o_idx, o_val, zero, ptr, idx, val):
    """Write the rows ``rows (k,)`` of a continuity block into the CSR arrays ``(ptr, idx, val)``
    (``ptr`` the rows' pointers): row ``r`` the changed row ``position[r]`` of ``O`` (``o_ptr,
    o_idx, o_val``) where that is ``>= 0``, else the base's (``width`` entries a row, its indices
    and values row after row); the values in the columns set in ``zero`` (bool, or of size 0:
    none) then written as 0.0, the pattern kept. Rows in parallel, each copied as a slice (3.7
    times as fast as an entry-by-entry loop with the mask's test: every 7th row of a 40 x 36 x 48
    box's divergence, 39 k rows, 3.1 against 11.5 ms on 2 cores)."""
    masked = zero.shape[0] > 0
    for j in prange(rows.shape[0]):
        r = rows[j]
        q = position[r]
        s = ptr[j]
        if q >= 0:
            a, b = o_ptr[q], o_ptr[q + 1]
            idx[s:s + b - a] = o_idx[a:b]
            val[s:s + b - a] = o_val[a:b]
        else:
            a = r * width
            idx[s:s + width] = b_idx[a:a + width]
            val[s:s + width] = b_val[a:a + width]
        if masked:
            for t in range(ptr[j], ptr[j + 1]):
                if zero[idx[t]]:
                    val[t] = 0.0


@njit(parallel=True)
def stack_rows(second, pos, a_ptr, a_idx, a_val, b_ptr, b_idx, b_val, ptr, idx, val):
    """Write row ``j`` of the CSR arrays ``(ptr, idx, val)`` (``ptr`` the rows' pointers) as row
    ``pos[j]`` of ``B`` (``b_ptr, b_idx, b_val``) where ``second[j]``, else of ``A``: the rows of
    two CSR matrices taken in any order (SciPy's ``vstack`` and row selection without the
    stacked copy). Rows in parallel, each copied as a slice."""
    for j in prange(pos.shape[0]):
        q, s = pos[j], ptr[j]
        if second[j]:
            a, b = b_ptr[q], b_ptr[q + 1]
            idx[s:s + b - a] = b_idx[a:b]
            val[s:s + b - a] = b_val[a:b]
        else:
            a, b = a_ptr[q], a_ptr[q + 1]
            idx[s:s + b - a] = a_idx[a:b]
            val[s:s + b - a] = a_val[a:b]
