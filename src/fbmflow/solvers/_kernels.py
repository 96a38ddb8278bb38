"""Numba kernels of the Vanka smoothers (cell-wise local saddle-point corrections) and of the
direct solver (a matrix scattered into a wider sparsity pattern).

Layout (see :mod:`fbmflow.fem.space`): ``n_v`` scalar Q2 DOFs, velocity unknown ``(i, r)`` at
``i n_v + r``, pressure DOF ``(c, m)`` at ``n_u + c (d + 1) + m``. The velocity block ``A`` is
a CSR whose row ``(i, r)`` holds component ``k``'s columns at
``i nb nnz + nb indptr[r] + k len_r + off`` (``off`` the position in the scalar row), with
``nb = d`` blocks per row for the coupled (Newton) block and ``nb = 1`` for the block-diagonal
(Stokes, Oseen) one, which only has ``k = i`` (stored at ``k -> 0``). ``B`` rows
come from a CSR copy ``(b_indptr, b_indices, b_data)`` (n_u x n_p); the cell-local rows of ``B^T``
from ``bt`` with entry ``B^T[(c, m), (i, a)]`` at ``(c (d+1) + m) d nl + i nl + rank[c, a]``.
Every kernel is checked against a NumPy reference in ``tests/solvers/test_vanka.py``.
"""
import numpy as np

from .._jit import jitable, njit, prange


@njit
def _local_residual(c, b, x, d, nb, n_v, n_u, indptr, indices, a_data, b_indptr, b_indices,
                    b_data, bt, rank, cell_dofs, pblock, r):
    """Residual ``b - K x`` restricted to the DOFs of cell ``c`` into ``r (d nl + d + 1,)``."""
    nl = cell_dofs.shape[1]
    npl = d + 1
    nnz = indptr[-1]
    for i in range(d):
        for a in range(nl):
            dof = cell_dofs[c, a]
            row = i * n_v + dof
            start = indptr[dof]
            ln = indptr[dof + 1] - start
            s = b[row]
            for k in range(d):
                if nb == 1 and k != i:
                    continue
                base = i * nb * nnz + nb * start + (k if nb > 1 else 0) * ln
                for off in range(ln):
                    s -= a_data[base + off] * x[k * n_v + indices[start + off]]
            for j in range(b_indptr[row], b_indptr[row + 1]):
                s -= b_data[j] * x[n_u + b_indices[j]]
            r[i * nl + a] = s
    for m in range(npl):
        s = b[n_u + c * npl + m]
        base = (c * npl + m) * d * nl
        for i in range(d):
            for a in range(nl):
                s -= bt[base + i * nl + rank[c, a]] * x[i * n_v + cell_dofs[c, a]]
        for q in range(npl):
            s -= pblock[c, m, q] * x[n_u + c * npl + q]
        r[d * nl + m] = s


@njit
def _diagonal_correction(c, r, out, d, n_v, bt, rank, cell_dofs, diag_inv, schur_inv):
    """The diagonal Vanka correction of cell ``c`` from its residual ``r`` into ``out``."""
    nl = cell_dofs.shape[1]
    npl = d + 1
    rhs = np.zeros(npl)
    for m in range(npl):
        s = -r[d * nl + m]
        base = (c * npl + m) * d * nl
        for i in range(d):
            for a in range(nl):
                s += bt[base + i * nl + rank[c, a]] * diag_inv[i * n_v + cell_dofs[c, a]] * r[i * nl + a]
        rhs[m] = s
    for m in range(npl):
        s = 0.0
        for q in range(npl):
            s += schur_inv[c, m, q] * rhs[q]
        out[d * nl + m] = s
    for i in range(d):
        for a in range(nl):
            s = r[i * nl + a]
            for m in range(npl):
                s -= bt[(c * npl + m) * d * nl + i * nl + rank[c, a]] * out[d * nl + m]
            out[i * nl + a] = diag_inv[i * n_v + cell_dofs[c, a]] * s


@njit(parallel=True)
def vanka_diagonal(gptr, order, b, x, omega, d, nb, n_v, indptr, indices, a_data, b_indptr, b_indices,
                   b_data, bt, rank, cell_dofs, pblock, diag_inv, schur_inv):
    """Diagonal Vanka over the cells ``order[gptr[g]:gptr[g + 1]]`` of every group ``g``: the
    groups in parallel, each group's cells in order, each correction added (times ``omega``)
    to ``x`` before the next cell's residual is taken (groups as in :func:`vanka_sweep_groups`).

    The local system ``[[D_c, B_c], [B_c^T, C_c]]`` with ``D_c`` the diagonal of ``A`` and
    ``C_c = pblock[c]`` is solved through its Schur complement ``S_c = B_c^T D_c^-1 B_c + C_c``
    (``schur_inv (n_cells, d+1, d+1)``, a pseudo-inverse where ``S_c`` is singular):
    ``dp = S^-1 (B^T D^-1 r_u - r_p)``, ``du = D^-1 (r_u - B dp)``. ``diag_inv (n_u,)``.
    """
    nl = cell_dofs.shape[1]
    npl = d + 1
    n_u = d * n_v
    nloc = d * nl + npl
    for g in prange(gptr.shape[0] - 1):
        r = np.empty(nloc)
        out = np.empty(nloc)
        for e in range(gptr[g], gptr[g + 1]):
            c = order[e]
            _local_residual(c, b, x, d, nb, n_v, n_u, indptr, indices, a_data, b_indptr, b_indices,
                            b_data, bt, rank, cell_dofs, pblock, r)
            _diagonal_correction(c, r, out, d, n_v, bt, rank, cell_dofs, diag_inv, schur_inv)
            _apply(c, out, omega, d, n_v, n_u, cell_dofs, x)


@njit
def _solve_dense(K, r, out):
    """Solve ``K y = r`` by LU with partial pivoting (``K`` and ``r`` overwritten); a pivot below
    ``1e-13 max|K|`` (a locally singular pressure mode) gives that unknown zero."""
    piv = np.empty(K.shape[0], dtype=np.int32)
    _lu_factor(K, piv, 1e-13)
    _lu_solve(K, piv, r, out)


@njit(parallel=True)
def vanka_full(gptr, order, b, x, omega, d, nb, n_v, indptr, indices, a_data, b_indptr, b_indices, b_data,
               bt, rank, cell_dofs, pblock, offsets):
    """Full Vanka: the cell's whole local saddle-point block ``[[A_cc, B_c], [B_c^T, 0]]``
    (velocity block read through the row offsets ``offsets (n_cells, nl, nl)``,
    ``FlowSpace.offsets``) solved by LU; cells
    and groups as in :func:`vanka_diagonal`."""
    nl = cell_dofs.shape[1]
    npl = d + 1
    n_u = d * n_v
    nloc = d * nl + npl
    nnz = indptr[-1]
    for g in prange(gptr.shape[0] - 1):
        r = np.empty(nloc)
        out = np.empty(nloc)
        K = np.empty((nloc, nloc))
        for e in range(gptr[g], gptr[g + 1]):
            c = order[e]
            _local_residual(c, b, x, d, nb, n_v, n_u, indptr, indices, a_data, b_indptr, b_indices,
                            b_data, bt, rank, cell_dofs, pblock, r)
            K[:] = 0.0
            for a in range(nl):
                dof = cell_dofs[c, a]
                start = indptr[dof]
                ln = indptr[dof + 1] - start
                for i in range(d):
                    base = i * nb * nnz + nb * start
                    for k in range(d):
                        if nb == 1 and k != i:
                            continue
                        kk = k if nb > 1 else 0
                        for bb in range(nl):
                            K[i * nl + a, k * nl + bb] = a_data[base + kk * ln + offsets[c, a, bb]]
                    for m in range(npl):
                        v = bt[(c * npl + m) * d * nl + i * nl + rank[c, a]]
                        K[i * nl + a, d * nl + m] = v
                        K[d * nl + m, i * nl + a] = v
            for m in range(npl):
                for q in range(npl):
                    K[d * nl + m, d * nl + q] = pblock[c, m, q]
            _solve_dense(K, r, out)
            _apply(c, out, omega, d, n_v, n_u, cell_dofs, x)


@njit
def _apply(c, delta, omega, d, n_v, n_u, cell_dofs, x):
    """``x += omega * delta`` on the DOFs of cell ``c``."""
    nl = cell_dofs.shape[1]
    npl = d + 1
    for i in range(d):
        for a in range(nl):
            x[i * n_v + cell_dofs[c, a]] += omega * delta[i * nl + a]
    for m in range(npl):
        x[n_u + c * npl + m] += omega * delta[d * nl + m]


@njit(parallel=True)
def schur_diagonal(bt, rank, cell_dofs, diag_inv, d, n_v):
    """``S_c = B_c^T D_c^-1 B_c`` for every cell: (n_cells, d + 1, d + 1) float64."""
    n_cells, nl = cell_dofs.shape
    npl = d + 1
    S = np.zeros((n_cells, npl, npl))
    for c in prange(n_cells):
        for m in range(npl):
            for q in range(npl):
                s = 0.0
                for i in range(d):
                    for a in range(nl):
                        pos = i * nl + rank[c, a]
                        s += (bt[(c * npl + m) * d * nl + pos] * diag_inv[i * n_v + cell_dofs[c, a]]
                              * bt[(c * npl + q) * d * nl + pos])
                S[c, m, q] = s
    return S


@njit
def scatter_into_pattern(indptr, indices, data, p_indptr, p_indices, out):
    """Write CSR matrix ``(indptr, indices, data)`` into ``out``, the data array of the CSR
    pattern ``(p_indptr, p_indices)`` of the same shape (zero where the matrix has no entry;
    duplicate entries are summed). Column indices sorted within rows in both. Returns False,
    leaving ``out`` partly written, when an entry of the matrix is not in the pattern."""
    out[:] = 0.0
    for i in range(len(indptr) - 1):
        q, end = p_indptr[i], p_indptr[i + 1]
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            while q < end and p_indices[q] < j:
                q += 1
            if q == end or p_indices[q] != j:
                return False
            out[q] += data[k]
    return True


# -- Vanka on general CSR blocks: patches of one cell, local factors stored -------------------
@jitable(inline=False)
def _lu_factor(K, piv, rel=1e-13):
    """LU with partial pivoting of ``K (n, n)`` in place (unit lower part below the diagonal),
    row swaps in ``piv (n,)``. A pivot below ``rel max|K|`` (a locally singular pressure mode)
    is set to zero with no multipliers below it: :func:`_lu_solve` gives that unknown zero."""
    n = K.shape[0]
    scale = 0.0
    for i in range(n):
        for j in range(n):
            scale = max(scale, abs(K[i, j]))
    tol = rel * scale
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(K[i, k]) > abs(K[p, k]):
                p = i
        piv[k] = p
        if p != k:
            for j in range(n):
                K[k, j], K[p, j] = K[p, j], K[k, j]
        if abs(K[k, k]) <= tol:
            K[k, k] = 0.0
            for i in range(k + 1, n):
                K[i, k] = 0.0
            continue
        inv = 1.0 / K[k, k]
        for i in range(k + 1, n):
            f = K[i, k] * inv
            K[i, k] = f
            if f != 0.0:
                for j in range(k + 1, n):
                    K[i, j] -= f * K[k, j]


@jitable(inline=False)
def _lu_solve(LU, piv, r, out):
    """Solve with the factors of :func:`_lu_factor`; ``r`` is overwritten, the result goes to
    ``out`` (zero for the unknowns of zeroed pivots). Both substitutions run along the rows of
    ``LU`` (contiguous; twice as fast as the column-oriented forward sweep, measured)."""
    n = LU.shape[0]
    for k in range(n):  # the row swaps first: the multipliers moved with later swaps
        p = piv[k]
        if p != k:
            r[k], r[p] = r[p], r[k]
    for i in range(1, n):
        s = 0.0
        for k in range(i):
            s += LU[i, k] * r[k]
        r[i] -= s
    for k in range(n - 1, -1, -1):
        if LU[k, k] == 0.0:
            out[k] = 0.0
            continue
        s = 0.0
        for j in range(k + 1, n):
            s += LU[k, j] * out[j]
        out[k] = (r[k] - s) / LU[k, k]


@njit
def _copy_row(src_ptr, src_idx, src_val, q, offset, idx, val, pos):
    for j in range(src_ptr[q], src_ptr[q + 1]):
        idx[pos] = offset + src_idx[j]
        val[pos] = src_val[j]
        pos += 1
    return pos


@njit(parallel=True)
def merge_blocks(a_ptr, a_idx, a_val, g_ptr, g_idx, g_val, d_ptr, d_idx, d_val, c_ptr, c_idx, c_val,
                 keep_u, ptr, idx, val):
    """The CSR arrays ``idx`` and ``val`` of ``K = [[A, G], [D, C]]`` from those of its blocks
    (``A`` (n_u, n_u), ``G`` (n_u, n_p), ``D`` (n_p, n_u), ``C`` (n_p, n_p)), filled in place
    at the row pointers ``ptr (n_u + n_p + 1,)`` (the rows' lengths summed: a kept velocity row
    ``A``'s and ``G``'s, a pressure row ``D``'s and ``C``'s); row by row, left block first, rows
    in parallel. Velocity rows with ``keep_u`` (n_u,) False stay empty."""
    n_u, n_p = a_ptr.shape[0] - 1, d_ptr.shape[0] - 1
    for q in prange(n_u + n_p):
        if q < n_u:
            if keep_u[q]:
                pos = _copy_row(a_ptr, a_idx, a_val, q, 0, idx, val, ptr[q])
                _copy_row(g_ptr, g_idx, g_val, q, n_u, idx, val, pos)
        else:
            pos = _copy_row(d_ptr, d_idx, d_val, q - n_u, 0, idx, val, ptr[q])
            _copy_row(c_ptr, c_idx, c_val, q - n_u, n_u, idx, val, pos)


@njit(parallel=True)
def patch_max(ptr, dofs, values):
    """The largest of ``values`` over each patch's unknowns ``dofs[ptr[k]:ptr[k + 1]]`` (patches
    not empty), (n_patches,) of ``values``' dtype; patches in parallel."""
    m = ptr.shape[0] - 1
    out = np.empty(m, dtype=values.dtype)
    for k in prange(m):
        best = values[dofs[ptr[k]]]
        for j in range(ptr[k] + 1, ptr[k + 1]):
            best = max(best, values[dofs[j]])
        out[k] = best
    return out


@njit
def regular_nodes(a_ptr, a_idx, a_val, n_v, d):
    """Nodes whose ``d`` velocity rows of the CSR block ``A`` (n_u, n_u, component-blocked, sorted
    columns) are one scalar row: row ``(i, a)`` has the entries of row ``(0, a)`` in the columns
    shifted by ``i n_v``. (n_v,) bool."""
    out = np.ones(n_v, dtype=np.bool_)
    for a in range(n_v):
        start, ln = a_ptr[a], a_ptr[a + 1] - a_ptr[a]
        for i in range(1, d):
            r = i * n_v + a
            if a_ptr[r + 1] - a_ptr[r] != ln:
                out[a] = False
                break
            for k in range(ln):
                if (a_idx[a_ptr[r] + k] != a_idx[start + k] + i * n_v
                        or a_val[a_ptr[r] + k] != a_val[start + k]):
                    out[a] = False
                    break
            if not out[a]:
                break
        if out[a]:
            for k in range(ln):  # component 0 only: a block-diagonal row
                if a_idx[start + k] >= n_v:
                    out[a] = False
                    break
    return out



@njit
def crossing_rows(ptr, idx, val, rows, n_v):
    """Whether each of the CSR rows (k,) of a velocity block (columns component-blocked,
    ``(i, a)`` at ``i n_v + a``) that stand for the velocity rows ``rows`` (k,) holds a non-zero
    in another component's columns. (k,) bool."""
    out = np.zeros(rows.shape[0], dtype=np.bool_)
    for r in range(rows.shape[0]):
        own = rows[r] // n_v
        for j in range(ptr[r], ptr[r + 1]):
            if val[j] != 0.0 and idx[j] // n_v != own:
                out[r] = True
                break
    return out

# A factored Vanka operator ("op" below) is the saddle-point matrix in four parts, none of them
# a copy of the system's blocks:
#   held (n_v,) bool, the nodes whose d velocity rows are one scalar row held in
#   (s_ptr, s_idx, s_val): node a's row a, node columns (the scalar operator of a VelocityBlock,
#   or the component-0 rows of an assembled block, shared);
#   their pressure-gradient rows, read from the divergence in its cell-local pattern
#   (nc_ptr, nc_cell, nc_rank, gt): node a lies in the cells nc_cell[nc_ptr[a]:nc_ptr[a + 1]], at
#   position nc_rank among each one's nodes in ascending order, and ``B[(i, a), c (d + 1) + m] =
#   gt[c, m, i nl + nc_rank]`` (gt (n_cells, d + 1, d nl): the divergence's values, a view);
#   the continuity rows (the system's B^T, velocity columns): row r is row d_pos[r] of the CSR
#   (d_ptr, d_idx, d_val) where d_pos[r] >= 0 (a row that differs from the divergence: a wall's
#   zeroed columns, a cut cell, a continued pressure), else the divergence's, the values
#   gt[c, m, :] and the columns b_idx[r w:(r + 1) w] of row r = c (d + 1) + m (w = d nl);
#   (k_ptr, k_idx, k_val): every other row of K (the velocity rows of the other nodes, A and G,
#   and the pressure block's rows), global columns. Velocity row (i, a) is i n_v + a.
@jitable(inline=False)
def _gradient_dot(node, i, x, n_u, nc_ptr, nc_cell, nc_rank, gt):
    """``(B p)[(i, node)]`` for a held node, ``p = x[n_u:]``, from the divergence's cells."""
    npl, w = gt.shape[1], gt.shape[2]
    nl = w // (npl - 1)
    s = 0.0
    for j in range(nc_ptr[node], nc_ptr[node + 1]):
        c = nc_cell[j]
        col = i * nl + nc_rank[j]
        for m in range(npl):
            s += gt[c, m, col] * x[n_u + c * npl + m]
    return s


@njit(parallel=True)
def gradient_rows(rows, indptr, n_v, nc_ptr, nc_cell, nc_rank, gt, zero, indices, data):
    """Rows ``rows`` (k,) of ``B`` from the divergence in its cell-local pattern (the operator's
    layout above: ``B[(i, a), c (d + 1) + m] = gt[c, m, i nl + nc_rank]``) into the CSR arrays
    ``(indptr (k + 1,) int64, indices, data)`` of ``B[rows]``, ``indptr`` given (``d + 1``
    entries per cell of the row's node), columns ascending; the rows where ``zero (n_u,)`` bool
    is True keep their pattern with zero values. Rows in parallel."""
    npl, w = gt.shape[1], gt.shape[2]
    nl = w // (npl - 1)
    for r in prange(rows.shape[0]):
        u = rows[r]
        i, a = u // n_v, u % n_v
        k = indptr[r]
        for j in range(nc_ptr[a], nc_ptr[a + 1]):
            c = nc_cell[j]
            col = i * nl + nc_rank[j]
            for m in range(npl):
                indices[k] = c * npl + m
                data[k] = 0.0 if zero[u] else gt[c, m, col]
                k += 1


@jitable(inline=False)
def _continuity_dot(row, x, gt, d_pos, d_ptr, d_idx, d_val, b_idx):
    """``(B^T x)[row]``, the continuity row as the operator holds it (see above)."""
    s = 0.0
    o = d_pos[row]
    if o >= 0:
        for j in range(d_ptr[o], d_ptr[o + 1]):
            s += d_val[j] * x[d_idx[j]]
        return s
    npl, w = gt.shape[1], gt.shape[2]
    c, m = row // npl, row % npl
    for j in range(w):
        s += gt[c, m, j] * x[b_idx[row * w + j]]
    return s


@jitable(inline=False)
def _row_product(q, x, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt,
                 d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val):
    """``(K x)[q]``."""
    s = 0.0
    if q < n_u and regular[q % n_v]:
        a, off = q % n_v, q - q % n_v
        for j in range(s_ptr[a], s_ptr[a + 1]):
            s += s_val[j] * x[off + s_idx[j]]
        s += _gradient_dot(a, q // n_v, x, n_u, nc_ptr, nc_cell, nc_rank, gt)
    else:
        for j in range(k_ptr[q], k_ptr[q + 1]):
            s += k_val[j] * x[k_idx[j]]
        if q >= n_u:
            s += _continuity_dot(q - n_u, x, gt, d_pos, d_ptr, d_idx, d_val, b_idx)
    return s


@jitable(inline=False)
def _bisect(S, q):
    """The position of ``q`` in the ascending ``S``, -1 where it is not there."""
    lo, hi = 0, S.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if S[mid] < q:
            lo = mid + 1
        else:
            hi = mid
    if lo < S.shape[0] and S[lo] == q:
        return lo
    return -1


@jitable(inline=False)
def _position(S, loc, q):
    """The position of unknown ``q`` in the patch ``S`` (ascending), -1 outside: ``loc[q]`` where
    ``loc`` maps every unknown (the CPU's threads, one map each), by bisection where ``loc`` is
    None (the GPU's threads, one per patch, hold no map of every unknown). The choice is made
    when the caller compiles: a test of the map's length in the loop made the CPU's gather 2.7
    times slower."""
    if loc is None:
        return _bisect(S, q)
    return loc[q]


@jitable(inline=False)
def _gather_block(S, loc, K, n_v, n_u, op):
    """``K[S, S]`` into ``K (n, n)`` float64 (:func:`_position` with ``loc``; ``op`` the
    operator's 16 arrays, see above)."""
    (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr,
     k_idx, k_val) = op
    n = S.shape[0]
    npl, w = gt.shape[1], gt.shape[2]
    nl = w // (npl - 1)
    for a in range(n):
        for b in range(n):
            K[a, b] = 0.0
    for a in range(n):
        q = S[a]
        if q < n_u and regular[q % n_v]:
            node, off = q % n_v, q - q % n_v
            for j in range(s_ptr[node], s_ptr[node + 1]):
                col = _position(S, loc, off + s_idx[j])
                if col >= 0:
                    K[a, col] += s_val[j]
            i = q // n_v
            for j in range(nc_ptr[node], nc_ptr[node + 1]):
                c = nc_cell[j]
                for m in range(npl):
                    col = _position(S, loc, n_u + c * npl + m)
                    if col >= 0:
                        K[a, col] += gt[c, m, i * nl + nc_rank[j]]
        else:
            for j in range(k_ptr[q], k_ptr[q + 1]):
                col = _position(S, loc, k_idx[j])
                if col >= 0:
                    K[a, col] += k_val[j]
            if q >= n_u:
                row = q - n_u
                o = d_pos[row]
                if o >= 0:
                    for j in range(d_ptr[o], d_ptr[o + 1]):
                        col = _position(S, loc, d_idx[j])
                        if col >= 0:
                            K[a, col] += d_val[j]
                else:
                    for j in range(w):
                        col = _position(S, loc, b_idx[row * w + j])
                        if col >= 0:
                            K[a, col] += gt[row // npl, row % npl, j]


@jitable(inline=False)
def _inverse(K, piv, inv, rel, e, col):
    """``inv = K^-1`` through :func:`_lu_factor` with pivot tolerance ``rel`` (``K``
    overwritten; the unknowns of zeroed pivots get zero rows and columns; ``e``, ``col`` work of
    ``K``'s size at least)."""
    n = K.shape[0]
    _lu_factor(K, piv, rel)
    for j in range(n):
        for i in range(n):
            e[i] = 0.0
        e[j] = 1.0
        _lu_solve(K, piv, e[:n], col[:n])
        for i in range(n):
            inv[i, j] = col[i]


@jitable(inline=False)
def factor_patch(k, patches, op, schur_tol, loc, work, A, Ainv, Y, Sc, Sinv, p_work, e, col):
    """Patch ``k``'s local factors into ``store`` (see :func:`vanka_factor`; the CPU's set-up and
    the GPU's, :mod:`fbmflow.gpu`, run this body). ``patches``, ``op``: the tuples of
    :func:`vanka_patch`; ``loc``: int32 map of every unknown to -1 (restored on return) or
    None (:func:`_position`); work arrays, float64 unless said: ``work (width, width)``, ``A
    (nl, nl)``, ``Ainv (d, nl, nl)``, ``Y (d nl, d + 1)``, ``Sc``, ``Sinv (d + 1, d + 1)``,
    ``p_work`` int32 and ``e``, ``col`` (width,)."""
    ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u = patches
    npl = d + 1
    nu = d * nl
    S = dofs[ptr[k]:ptr[k + 1]]
    nk = S.shape[0]
    if loc is not None:
        for a in range(nk):
            loc[S[a]] = a
    K = work[:nk, :nk]
    _gather_block(S, loc, K, n_v, n_u, op)
    if loc is not None:
        for a in range(nk):
            loc[S[a]] = -1
    base = lu_ptr[k]
    nb = blocks[k]
    if nb == 0:
        _lu_factor(K, piv[ptr[k]:ptr[k + 1]], 1e-13)
        for a in range(nk):
            for b in range(nk):
                store[base + a * nk + b] = K[a, b]
        return
    for i in range(nb):
        for a in range(nl):
            for b in range(nl):
                A[a, b] = K[i * nl + a, i * nl + b]
        _inverse(A, p_work[:nl], Ainv[i], 1e-13, e, col)
    for i in range(d):
        Ai = Ainv[i if nb > 1 else 0]
        for a in range(nl):
            for mm in range(npl):
                s = 0.0
                for b in range(nl):
                    s += Ai[a, b] * K[i * nl + b, nu + mm]
                Y[i * nl + a, mm] = s
    for mm in range(npl):
        for q in range(npl):
            s = K[nu + mm, nu + q]
            for j in range(nu):
                s -= K[nu + mm, j] * Y[j, q]
            Sc[mm, q] = s
    _inverse(Sc, p_work[:npl], Sinv, schur_tol, e, col)
    pos = base
    for i in range(nb):
        for a in range(nl):
            for b in range(nl):
                store[pos] = Ainv[i, a, b]
                pos += 1
    for j in range(nu):
        for mm in range(npl):
            store[pos] = Y[j, mm]
            pos += 1
    if not d_read[k]:
        for mm in range(npl):
            for j in range(nu):
                store[pos] = K[nu + mm, j]
                pos += 1
    for mm in range(npl):
        for q in range(npl):
            store[pos] = Sinv[mm, q]
            pos += 1


@njit(parallel=True)
def vanka_factor(store, lu_ptr, piv, ptr, dofs, blocks, d_read, nl, d, n_chunks, width, schur_tol, n_v,
                 n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val,
                 b_idx, k_ptr, k_idx, k_val):
    """Local factors of the patches ``S_k = dofs[ptr[k]:ptr[k+1]]`` (ascending) of a factored
    Vanka operator (see above), computed in float64 and stored in ``store`` (float64 or float32,
    patch ``k``'s at ``lu_ptr[k]``), filled in place with ``piv`` (int32, patch ``k``'s at
    ``ptr[k]``), by :func:`factor_patch` in ``n_chunks`` chunks of patches in parallel:

    * ``blocks[k]`` 0: the LU factors of ``K[S, S]`` (:func:`_lu_factor`), ``n_k^2`` values;
    * ``blocks[k]`` 1 or ``d``, a cell (``S`` = its ``nl`` nodes per component, then its
      ``d + 1`` pressures) whose velocity rows couple no two components within the cell:
      ``K[S, S] = [[diag(A_0, .., A_{d-1}), B], [D, C]]`` with the component blocks ``A_i``
      (nl, nl) is solved through its Schur complement. Stored are the ``blocks[k]`` inverses
      ``A_i^-1`` (one, ``A_0^-1``, where all components share one scalar block: the cell's nodes
      are regular; ``d`` where some rows differ, e.g. a symmetry plane's unit rows), then
      ``Y = diag(A_i^-1) B`` (d nl, d + 1), ``D`` (d + 1, d nl) unless ``d_read[k]`` (then
      the solve reads ``D`` from the continuity rows, :func:`continuity_in_patch_order`) and
      ``(C - D Y)^-1`` (d + 1, d + 1), the last through :func:`_inverse` with the pivot tolerance
      ``schur_tol``: a pressure mode that the cell's free velocities barely see (a cell with one
      free node among constrained ones) is left uncorrected, as an orphaned one, rather than
      amplifying the rounding of stored single-precision factors.
    """
    m = ptr.shape[0] - 1
    npl = d + 1
    patches = (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u)
    op = (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx,
          k_ptr, k_idx, k_val)
    for t in prange(n_chunks):
        loc = np.full(k_ptr.shape[0] - 1, -1, dtype=np.int32)  # global -> local position in the patch
        work = np.empty((width, width))
        A = np.empty((nl, nl))
        Ainv = np.empty((d, nl, nl))
        Y = np.empty((d * nl, npl))
        Sc = np.empty((npl, npl))
        Sinv = np.empty((npl, npl))
        p_work = np.empty(width, dtype=np.int32)
        e = np.empty(width)
        col = np.empty(width)
        for k in range(t * m // n_chunks, (t + 1) * m // n_chunks):
            factor_patch(k, patches, op, schur_tol, loc, work, A, Ainv, Y, Sc, Sinv, p_work, e, col)


@njit(parallel=True)
def continuity_in_patch_order(ptr, dofs, blocks, nu, npl, n_u, d_pos, d_ptr, d_idx, b_idx):
    """Whether each Schur patch's (``blocks[k] > 0``) continuity rows, those of its pressures
    ``dofs[ptr[k] + nu:]`` (the operator's, see above: rows of the CSR ``(d_ptr, d_idx)`` where
    ``d_pos`` says so, else the divergence's with the columns ``b_idx``), hold exactly its
    velocities ``dofs[ptr[k]:ptr[k] + nu]``, in that order (a cell's rows of the divergence in
    its cell-local pattern, the patch's nodes in ascending order): its ``D`` is then those
    rows' values. (n_patches,) bool; patches in parallel."""
    m = ptr.shape[0] - 1
    out = np.zeros(m, dtype=np.bool_)
    for k in prange(m):
        if blocks[k] <= 0 or ptr[k + 1] - ptr[k] != nu + npl:
            continue
        ok = True
        for mm in range(npl):
            row = dofs[ptr[k] + nu + mm] - n_u
            if mm > 0 and row != dofs[ptr[k] + nu] - n_u + mm:
                ok = False
                break
            o = d_pos[row]
            if o >= 0:
                if d_ptr[o + 1] - d_ptr[o] != nu:
                    ok = False
                    break
                for j in range(nu):
                    if d_idx[d_ptr[o] + j] != dofs[ptr[k] + j]:
                        ok = False
                        break
            else:
                for j in range(nu):
                    if b_idx[row * nu + j] != dofs[ptr[k] + j]:
                        ok = False
                        break
            if not ok:
                break
        out[k] = ok
    return out


@jitable(inline=False, fastmath=True)
def _lu_solve_stored(store, base, n, piv, r, w, out):
    """:func:`_lu_solve` with the factors ``LU (n, n)`` stored row by row at ``store[base:]``, in
    the storage precision of ``store`` (``w`` work of that dtype; ``r`` float64, overwritten;
    the result goes to ``out``)."""
    for k in range(n):
        p = piv[k]
        if p != k:
            r[k], r[p] = r[p], r[k]
    for i in range(n):
        w[i] = r[i]
    for i in range(1, n):
        s = w[0] - w[0]  # a zero of the storage dtype
        row = base + i * n
        for k in range(i):
            s += store[row + k] * w[k]
        w[i] -= s
    for k in range(n - 1, -1, -1):
        row = base + k * n
        if store[row + k] == 0.0:
            w[k] = 0.0
            continue
        s = w[0] - w[0]
        for j in range(k + 1, n):
            s += store[row + j] * w[j]
        w[k] = (w[k] - s) / store[row + k]
    for i in range(n):
        out[i] = w[i]


@jitable(inline=False, fastmath=True)
def _schur_solve(store, base, nb, nl, d, r, w, out, p_row, gt, d_pos, d_ptr, d_val):
    """The correction of a Schur patch with ``nb`` stored component inverses (see
    :func:`vanka_factor`) from its residual ``r`` (d nl + d + 1,) float64 into ``out``; ``w``
    float64 work, (d nl + d + 1,). Accumulated in float64 whatever the storage: the continuity
    rows ``r_p - D z`` cancel. ``p_row``: the first of the patch's continuity rows (the
    operator's, ``gt, d_pos, d_ptr, d_val``, see above) where ``D`` is read from them (in the
    patch's order), -1 where it is stored."""
    npl = d + 1
    nu = d * nl
    y0 = base + nb * nl * nl
    d0 = y0 + nu * npl
    s0 = d0 + npl * nu if p_row < 0 else d0
    for i in range(d):  # z = diag(A_i^-1) r_u into w[:nu]
        inv = base + (i if nb > 1 else 0) * nl * nl
        for a in range(nl):
            s = 0.0
            row = inv + a * nl
            for b in range(nl):
                s += store[row + b] * r[i * nl + b]
            w[i * nl + a] = s
    for mm in range(npl):  # t = r_p - D z into w[nu:]
        s = 0.0
        if p_row < 0:
            for j in range(nu):
                s += store[d0 + mm * nu + j] * w[j]
        else:
            row = p_row + mm
            o = d_pos[row]
            if o >= 0:
                first = d_ptr[o]
                for j in range(nu):
                    s += d_val[first + j] * w[j]
            else:
                for j in range(nu):
                    s += gt[row // npl, mm, j] * w[j]
        w[nu + mm] = r[nu + mm] - s
    for mm in range(npl):  # p = (C - D Y)^-1 t
        s = 0.0
        for q in range(npl):
            s += store[s0 + mm * npl + q] * w[nu + q]
        out[nu + mm] = s
    for j in range(nu):  # u = z - Y p
        s = w[j]
        for mm in range(npl):
            s -= store[y0 + j * npl + mm] * out[nu + mm]
        out[j] = s


@jitable
def vanka_residual(k, lane, lanes, b, x, patches, op, r):
    """Rows ``lane, lane + lanes, ...`` of patch ``k``'s residual ``(b - K x)[S]`` into ``r`` (a
    Schur patch: its nodes ``lane, lane + lanes, ...``, each node's ``d`` rows, then so its
    pressure rows); ``lanes`` threads that share a patch (the GPU's) take one ``lane`` each, the
    CPU all (0, 1). ``patches``, ``op``: as :func:`vanka_patch` takes them."""
    ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u = patches
    (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr,
     k_idx, k_val) = op
    nu = d * nl
    npl = d + 1
    S = dofs[ptr[k]:ptr[k + 1]]
    nk = S.shape[0]
    if blocks[k] > 0:  # a Schur patch: the scalar row of a regular node serves its d components
        for a in range(lane, nl, lanes):
            node = S[a]
            if not regular[node]:
                for i in range(d):
                    q = S[i * nl + a]
                    r[i * nl + a] = b[q] - _row_product(q, x, n_v, n_u, regular, s_ptr, s_idx, s_val,
                                                        nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx,
                                                        d_val, b_idx, k_ptr, k_idx, k_val)
                continue
            for i in range(d):
                r[i * nl + a] = 0.0
            for j in range(s_ptr[node], s_ptr[node + 1]):
                v = s_val[j]
                col = s_idx[j]
                for i in range(d):
                    r[i * nl + a] += v * x[i * n_v + col]
            for j in range(nc_ptr[node], nc_ptr[node + 1]):  # the gradient, cell by cell
                c = nc_cell[j]
                rank = nc_rank[j]
                for m in range(npl):
                    pm = x[n_u + c * npl + m]
                    for i in range(d):
                        r[i * nl + a] += gt[c, m, i * nl + rank] * pm
            for i in range(d):
                r[i * nl + a] = b[i * n_v + node] - r[i * nl + a]
        first = nu
    else:
        first = 0
    for a in range(first + lane, nk, lanes):
        r[a] = b[S[a]] - _row_product(S[a], x, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell,
                                      nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val)


@jitable
def vanka_solve(k, patches, op, r, w, w64, out):
    """Patch ``k``'s correction before its damping, ``out = K[S, S]^-1 r`` (its stored factors:
    LU, or a Schur patch's blocks), with the work ``w`` (the factors' dtype) and ``w64``."""
    ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u = patches
    gt, d_pos, d_ptr, d_val = op[7], op[8], op[9], op[11]
    nb = blocks[k]
    if nb > 0:
        p_row = dofs[ptr[k] + d * nl] - n_u if d_read[k] else -1  # its first pressure row
        _schur_solve(store, lu_ptr[k], nb, nl, d, r, w64, out, p_row, gt, d_pos, d_ptr, d_val)
    else:
        _lu_solve_stored(store, lu_ptr[k], ptr[k + 1] - ptr[k], piv[ptr[k]:ptr[k + 1]], r, w, out)


@jitable
def vanka_update(k, lane, lanes, x, omega, patches, out):
    """``x[S[a]] += omega out[a]`` for patch ``k``'s entries ``a = lane, lane + lanes, ...``."""
    ptr, dofs = patches[0], patches[1]
    first = ptr[k]
    for a in range(lane, ptr[k + 1] - first, lanes):
        x[dofs[first + a]] += omega * out[a]


@jitable(inline=False)
def vanka_patch(k, b, x, omega, patches, op, r, w, w64, out):
    """Add ``omega`` times patch ``k``'s correction ``K[S, S]^-1 (b - K x)[S]`` to ``x`` (the CPU's
    sweeps run this body; the GPU's its three parts, :func:`vanka_residual`, :func:`vanka_solve`
    and :func:`vanka_update`, a patch's rows shared among several threads). ``patches``: the
    tuple ``(ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u)``, ``op`` the
    operator's 16 arrays (see above; tuples: an inlined call takes at most 30 arguments); ``r``,
    ``w64``, ``out`` float64 and ``w`` of the storage dtype, work of the patch's size at least.
    The parts are inlined here (one thread: ``lanes`` 1 known when compiled), so that the CPU's
    sweeps run the one body they ran before the parts were split for the GPU."""
    vanka_residual(k, 0, 1, b, x, patches, op, r)
    vanka_solve(k, patches, op, r, w, w64, out)
    vanka_update(k, 0, 1, x, omega, patches, out)


@njit
def _update_in_order(order, start, end, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d,
                     width, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos,
                     d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val):
    """Block Gauss-Seidel over the patches ``order[start:end]`` in that order (:func:`vanka_patch`):
    each correction is added to ``x`` before the next patch's residual is taken."""
    r = np.empty(width)
    w = np.empty(width, dtype=store.dtype)
    w64 = np.empty(width)
    out = np.empty(width)
    patches = (ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, n_v, n_u)
    op = (regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx,
          k_ptr, k_idx, k_val)
    for e in range(start, end):
        vanka_patch(order[e], b, x, omega, patches, op, r, w, w64, out)


@njit(parallel=True)
def vanka_sweep_groups(gptr, order, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d,
                       width, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos,
                       d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val):
    """Groups of patches ``order[gptr[g]:gptr[g + 1]]`` in parallel, each group in order
    (:func:`_update_in_order`). The groups must not touch a DOF that another group reads or
    writes (:func:`fbmflow.solvers.ordering.slab_phases`); then the result does not depend on
    the number of threads."""
    for g in prange(gptr.shape[0] - 1):
        _update_in_order(order, gptr[g], gptr[g + 1], b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks,
                         d_read, nl, d, width, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell,
                         nc_rank, gt, d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val)


@njit
def vanka_sweep_sequential(patches, b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read, nl, d, width,
                           n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt, d_pos, d_ptr,
                           d_idx, d_val, b_idx, k_ptr, k_idx, k_val):
    """Block Gauss-Seidel over ``patches (m,)`` in order (patches may share DOFs)."""
    _update_in_order(patches, 0, patches.shape[0], b, x, omega, ptr, dofs, lu_ptr, store, piv, blocks, d_read,
                     nl, d, width, n_v, n_u, regular, s_ptr, s_idx, s_val, nc_ptr, nc_cell, nc_rank, gt,
                     d_pos, d_ptr, d_idx, d_val, b_idx, k_ptr, k_idx, k_val)


@njit(parallel=True)
def row_reach(k_ptr, k_idx, points, periods, row_offset, col_offset, out):
    """``out[row_offset + row]`` raised to the largest ``|points[col_offset + k_idx[j], a] -
    points[row_offset + row, a]|`` over the entries ``j`` of every row of the CSR pattern ``(k_ptr,
    k_idx)`` and the axes ``a`` (the difference taken modulo ``periods[a]``, into
    ``[-periods[a]/2, periods[a]/2)``, where ``periods[a] > 0``); rows in parallel."""
    dim = points.shape[1]
    for row in prange(k_ptr.shape[0] - 1):
        q = row_offset + row
        reach = out[q]
        for j in range(k_ptr[row], k_ptr[row + 1]):
            c = col_offset + k_idx[j]
            for a in range(dim):
                diff = points[c, a] - points[q, a]
                if periods[a] > 0:
                    diff = (diff + periods[a] // 2) % periods[a] - periods[a] // 2
                reach = max(reach, abs(diff))
        out[q] = reach


@njit
def greedy_colours(indptr, indices):
    """Colours of the vertices of the graph ``(indptr, indices)`` (CSR adjacency, symmetric, no
    self-loops), greedily in vertex order: each vertex takes the smallest colour none of its
    earlier neighbours has; (m,) int64."""
    m = indptr.shape[0] - 1
    colour = np.full(m, -1, dtype=np.int64)
    mark = np.full(m + 1, -1, dtype=np.int64)
    for i in range(m):
        for j in range(indptr[i], indptr[i + 1]):
            c = colour[indices[j]]
            if c >= 0:
                mark[c] = i
        c = 0
        while mark[c] == i:
            c += 1
        colour[i] = c
    return colour
