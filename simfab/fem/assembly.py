"""Fixed-pattern sparse assembly of per-element Hessian blocks.

The Hessian of an FEM energy on ``n`` vertices in ``dim`` dimensions is an ``(n*dim, n*dim)``
matrix made of dense ``dim x dim`` blocks, one per pair of vertices sharing an element. The
pattern depends only on the connectivity, so it is built once; every Newton iteration only
computes the values, added into ``csr.data`` through a precomputed map from each entry of each
element block to its position there (``element_slots``; the Neo-Hookean kernel adds straight
into it, :meth:`HessianPattern.assemble` is the numpy equivalent).

Dof numbering: vertex ``v``, axis ``a`` -> row ``v*dim + a``. Within a row, columns are sorted.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp


class HessianPattern:
    """CSR structure of the vertex-pair block pattern of a mesh.

    Args:
        elements: (m, k) int vertex indices per element (k = dim + 1 for simplices)
        n_vertices: n
        dim: 2 or 3 (block size)

    Attributes:
        shape: (n*dim, n*dim)
        nnz: number of stored entries
        indptr, indices: CSR structure (int32), columns sorted within rows
        element_slots: (m, k*dim, k*dim) int64, position in ``data`` of each element-block entry
    """

    def __init__(self, elements: np.ndarray, n_vertices: int, dim: int):
        elements = np.asarray(elements, dtype=np.int64)
        m, k = elements.shape
        self.dim = int(dim)
        self.n_vertices = int(n_vertices)
        n, d = self.n_vertices, self.dim
        # vertex-level adjacency (with the diagonal), as a sorted CSR
        rows = np.repeat(elements, k, axis=1).ravel()
        cols = np.tile(elements, (1, k)).ravel()
        diag = np.arange(n)
        vadj = sp.csr_matrix((np.ones(rows.size + n, dtype=np.int32), (np.concatenate([rows, diag]),
                                                                      np.concatenate([cols, diag]))), shape=(n, n))
        vadj.sum_duplicates()
        vadj.sort_indices()
        self._vptr = vadj.indptr.astype(np.int64)
        self._vidx = vadj.indices.astype(np.int64)
        deg = np.diff(self._vptr)
        # dof-level CSR: row (v, a) holds d entries for each neighbour w of v
        row_len = np.repeat(deg * d, d)
        self.indptr = np.concatenate([[0], np.cumsum(row_len)]).astype(np.int64)
        nbr_cols = (self._vidx[:, None] * d + np.arange(d)[None, :]).ravel()  # per vertex row, all neighbour dofs
        self.nnz = int(self.indptr[-1])
        # row (v, a) copies vertex v's neighbour dofs nbr_cols[vptr[v]*d : vptr[v+1]*d]
        src_start = np.repeat(self._vptr[:-1] * d, d)
        self.indices = np.repeat(src_start - self.indptr[:-1], row_len) + np.arange(self.nnz)
        self.indices = nbr_cols[self.indices]
        self.shape = (n * d, n * d)
        if self.nnz < 2**31 - 1:
            self.indptr = self.indptr.astype(np.int32)
            self.indices = self.indices.astype(np.int32)
        # slots of element blocks: entry ((i, a), (j, b)) of element e
        ei = np.repeat(elements, k, axis=1)  # (m, k*k): row vertex
        ej = np.tile(elements, (1, k))  # (m, k*k): col vertex
        base = self._pair_slots(ei.ravel(), ej.ravel()).reshape(m, k, k, d, d)
        # reorder to (m, i, a, j, b) -> element block index (i*d + a, j*d + b)
        self.element_slots = np.ascontiguousarray(base.transpose(0, 1, 3, 2, 4)).reshape(m, k * d, k * d)

    # -- slots -------------------------------------------------------------------------
    def _pair_pos(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Position of neighbour ``cols[i]`` in vertex ``rows[i]``'s sorted neighbour list, -1 if absent."""
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        # search in the concatenated neighbour lists: key = row * n + col is sorted
        keys = np.repeat(np.arange(self.n_vertices, dtype=np.int64), np.diff(self._vptr)) * self.n_vertices + self._vidx
        q = rows * self.n_vertices + cols
        at = np.searchsorted(keys, q)
        ok = (at < keys.size) & (keys[np.minimum(at, keys.size - 1)] == q)
        return np.where(ok, at - self._vptr[rows], -1)

    def _pair_slots(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        pos = self._pair_pos(rows, cols)
        if np.any(pos < 0):
            bad = int(np.flatnonzero(pos < 0)[0])
            raise ValueError(f"vertex pair ({int(rows[bad])}, {int(cols[bad])}) is not in the Hessian pattern")
        d = self.dim
        rows = np.asarray(rows, dtype=np.int64)
        deg = np.diff(self._vptr)[rows]
        # row (v, a) starts at indptr[v*d + a] = indptr[v*d] + a * deg * d
        start = np.asarray(self.indptr, dtype=np.int64)[rows * d]
        a = np.arange(d)[None, :, None]
        b = np.arange(d)[None, None, :]
        return start[:, None, None] + a * (deg * d)[:, None, None] + (pos * d)[:, None, None] + b

    def block_slots(self, rows, cols) -> np.ndarray:
        """Indices into ``csr.data`` of the ``dim x dim`` blocks of vertex pairs.

        Args:
            rows, cols: (k,) vertex indices. Returns (k, dim, dim) int64: entry [i, a, b] is the
        position of H[rows[i]*dim + a, cols[i]*dim + b]. Raises ValueError if a pair does not share
        an element (and is not a diagonal pair).
        """
        rows = np.atleast_1d(np.asarray(rows, dtype=np.int64))
        cols = np.atleast_1d(np.asarray(cols, dtype=np.int64))
        if rows.shape != cols.shape or rows.ndim != 1:
            raise ValueError("rows and cols must be 1-D arrays of equal length")
        if rows.size and (min(rows.min(), cols.min()) < 0 or max(rows.max(), cols.max()) >= self.n_vertices):
            raise ValueError("vertex index out of range")
        return self._pair_slots(rows, cols)

    # -- assembly ----------------------------------------------------------------------
    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """CSR matrix with this pattern and the given ``data`` (nnz,) (not copied).

        Every such matrix of float64 values shares one set of index arrays (scipy's constructor
        converts and checks them on each call, and a solver that sees the same arrays again knows
        the pattern without comparing it); they must not be modified in place."""
        data = np.asarray(data)
        template = self.__dict__.get("_template")
        if template is None:
            template = sp.csr_matrix((np.zeros(self.nnz), self.indices, self.indptr), shape=self.shape)
            template.has_canonical_format  # (computed once: sorted and unique, whatever the values)
            self._template = template
        if data.dtype != np.float64 or data.shape != (self.nnz,):
            return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape, copy=False)
        H = copy.copy(template)
        H.data = data
        return H

    def assemble(self, element_blocks: np.ndarray) -> sp.csr_matrix:
        """Assemble element blocks (m, (dim+1)*dim, (dim+1)*dim) into a CSR matrix of this pattern.

        Block rows/cols are ordered (local vertex i, axis a) -> i*dim + a.
        """
        blocks = np.asarray(element_blocks, dtype=np.float64)
        if blocks.shape != self.element_slots.shape:
            raise ValueError(f"element_blocks has shape {blocks.shape}, expected {self.element_slots.shape}")
        return self.matrix(np.bincount(self.element_slots.ravel(), weights=blocks.ravel(), minlength=self.nnz))
