"""A compressed-sparse-column matrix in numpy alone: what a safe bound (core.cones) asks of a
program's constraint matrix, for the verifier, which loads no scipy. A dense matrix times it sums
each column's products one after another in the order its entries are stored, as scipy.sparse's
product does, so a bound computed over it is the bound computed over scipy's matrix of the same
entries, to the last bit (tests/core/test_csc.py compares them).

It is read as scipy's is (``data``, ``indices``, ``indptr``, ``shape``, ``nnz``, ``tocsc``,
``abs``, ``!= 0``, ``astype``), which is how core.cones tells a sparse matrix from a dense one."""

from __future__ import annotations

import numpy as np


class CscMatrix:
    __array_ufunc__ = None  # ``dense @ matrix``: numpy leaves the product to __rmatmul__

    def __init__(self, arrays: tuple, shape: tuple[int, int]):
        data, indices, indptr = arrays
        self.data = np.asarray(data)
        self.indices = np.asarray(indices, dtype=np.int64)
        self.indptr = np.asarray(indptr, dtype=np.int64)
        self.shape = (int(shape[0]), int(shape[1]))
        if len(self.indptr) != self.shape[1] + 1 or not len(self.indices) == len(self.data) == self.indptr[-1]:
            raise ValueError("a CSC matrix's indptr has one entry per column and one more, ending at its nnz")

    @classmethod
    def from_triplets(cls, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> tuple[CscMatrix, np.ndarray]:
        """The pattern of entries at (rows, cols), none repeated, each column's rows ascending (as
        scipy's conversion from triplets orders them); returns it with 1..nnz as data and the
        order: ``data[order]`` lays values given in the triplets' order out in the matrix's."""
        rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        order = np.lexsort((rows, cols))
        indptr = np.zeros(shape[1] + 1, dtype=np.int64)
        np.add.at(indptr, cols + 1, 1)
        return cls((np.arange(1, len(rows) + 1, dtype=float)[order], rows[order], np.cumsum(indptr)), shape), order

    @property
    def nnz(self) -> int:
        return int(self.indptr[-1])  # stored entries, explicit zeros included (as scipy counts them)

    def tocsc(self) -> CscMatrix:
        return self

    def copy(self) -> CscMatrix:
        return CscMatrix((self.data.copy(), self.indices.copy(), self.indptr.copy()), self.shape)

    def sort_indices(self) -> None:
        """Each column's rows ascending, in place (a stable sort: equal rows keep their order)."""
        columns = np.repeat(np.arange(self.shape[1]), np.diff(self.indptr))
        order = np.lexsort((self.indices, columns))
        self.data, self.indices = self.data[order], self.indices[order]

    def astype(self, dtype) -> CscMatrix:
        return self._with_data(self.data.astype(dtype))

    def __abs__(self) -> CscMatrix:
        return self._with_data(np.abs(self.data))

    def __ne__(self, other):
        if not (np.isscalar(other) and other == 0):
            return NotImplemented
        return self._with_data(self.data != 0)  # explicit zeros read False

    def _with_data(self, data: np.ndarray) -> CscMatrix:
        """The same pattern (and its layout by column length) with other values."""
        matrix = CscMatrix((data, self.indices, self.indptr), self.shape)
        matrix._by_length = getattr(self, "_by_length", None)
        return matrix

    __hash__ = None

    def toarray(self) -> np.ndarray:
        dense = np.zeros(self.shape, dtype=self.data.dtype)
        columns = np.repeat(np.arange(self.shape[1]), np.diff(self.indptr))
        dense[self.indices, columns] = self.data
        return dense

    def __rmatmul__(self, other) -> np.ndarray:
        """``other @ self`` for a dense ``other`` (rows,) or (p, rows): column j's entry is
        ``0 + a_1 x_1 + a_2 x_2 + ...`` over its stored entries in order, each product rounded,
        then each sum (scipy.sparse's loop), summed for the columns of one length at once."""
        other = np.asarray(other)
        vector = other.ndim == 1
        x = other[None] if vector else other
        dtype = np.result_type(x.dtype, self.data.dtype, np.float64)
        out = np.zeros((x.shape[0], self.shape[1]), dtype=dtype)
        for columns, at in self._columns_by_length():
            products = np.zeros((x.shape[0], at.shape[0] + 1, len(columns)), dtype=dtype)
            products[:, 1:] = self.data[at].astype(dtype) * x[:, self.indices[at]]
            out[:, columns] = np.cumsum(products, axis=1)[:, -1]  # an accumulation: one term after another
        return out[0] if vector else out

    def _columns_by_length(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(columns, positions (length, columns) of their entries in data) for each length."""
        if getattr(self, "_by_length", None) is None:
            lengths = np.diff(self.indptr)
            self._by_length = [(columns, self.indptr[columns][None] + np.arange(length)[:, None])
                               for length in np.unique(lengths[lengths > 0])
                               for columns in [np.flatnonzero(lengths == length)]]
        return self._by_length
