"""Sparsity structures shared between evaluations, recognised by their memory.

The assembly's patterns (:mod:`~workflow.models.fem.assembly`) are read-only arrays shared by every matrix of
one mesh topology; what is derived from a structure alone (its upper triangle, PARDISO's analysis, the layout of
a block matrix) is made once per structure and found again by the memory of its arrays, not by their values.
"""

import hashlib
import weakref

import numpy as np
import scipy.sparse as sp


def owner(array: np.ndarray) -> np.ndarray:
    """The array that owns the memory of ``array`` (itself, or the base of its views)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array


def read_only(*values) -> tuple:
    """``values`` with their arrays made read-only (shared structures: never to be changed in place)."""
    for value in values:
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return values


def shared(matrix) -> bool:
    """Whether a compressed sparse matrix's structure is read-only (shared between evaluations)."""
    return not matrix.indices.flags.writeable and not matrix.indptr.flags.writeable


def _memory(array: np.ndarray) -> tuple:
    """(weak reference to the owner, first byte, length, dtype) of an array."""
    return weakref.ref(owner(array)), array.__array_interface__["data"][0], array.size, array.dtype


def describe(matrix) -> tuple:
    """What identifies a compressed sparse matrix's structure: the memory of its arrays when they are read-only
    (shared: found again without reading them), else a digest of their contents."""
    if shared(matrix):
        return ("shared", matrix.shape, _memory(matrix.indptr), _memory(matrix.indices))
    digest = hashlib.blake2b(matrix.indptr.tobytes(), digest_size=16)
    digest.update(matrix.indices.tobytes())
    return ("content", matrix.shape, digest.hexdigest())


def _same(held: tuple, query: tuple) -> bool:
    """Whether two :func:`describe` results name one structure (shared arrays: the same memory, its owner alive)."""
    if held[:2] != query[:2]:
        return False
    if held[0] == "content":
        return held[2] == query[2]
    return all(a[0]() is not None and a[0]() is b[0]() and a[1:] == b[1:] for a, b in zip(held[2:], query[2:]))


class StructureCache:
    """What was derived from sparsity structures, found again by their :func:`describe` (the most recent first)."""

    def __init__(self, size: int):
        self.size, self.entries = size, []

    def get(self, structures: tuple):
        """The value kept for these structures (one :func:`describe` each), or None."""
        for index, (held, value) in enumerate(self.entries):
            if len(held) == len(structures) and all(map(_same, held, structures)):
                self.entries.insert(0, self.entries.pop(index))
                return value
        return None

    def put(self, structures: tuple, value):
        """Keep ``value`` for these structures (the oldest beyond :attr:`size` dropped); returns it."""
        self.entries.insert(0, (structures, value))
        del self.entries[self.size:]
        return value


BLOCK_LAYOUTS = 4
"""Block-matrix layouts kept, one per structure of the blocks [-]."""
_block_layouts = StructureCache(BLOCK_LAYOUTS)


def canonical(matrix) -> sp.csc_matrix:
    """``matrix`` as CSC with sorted indices and no duplicates (a copy where they had to change: the arrays may be
    shared and read-only)."""
    matrix = matrix.tocsc() if sp.issparse(matrix) else sp.csc_matrix(matrix)  # a CSC matrix itself, its flags kept
    if not matrix.has_canonical_format:
        matrix = matrix.copy()
        matrix.sum_duplicates()
    return matrix


def shared_block_matrix(blocks: list) -> sp.csc_matrix:
    """``scipy.sparse.bmat(blocks, format="csc")`` on a read-only structure shared by every call whose blocks have
    the same structures, so that what is derived from it (:mod:`~workflow.models.fem.solvers`) is made once.

    Parameters
    ----------
    blocks : list of lists of sparse matrices (or None)
    """
    blocks = [[None if block is None else canonical(block) for block in row] for row in blocks]
    present = [block for row in blocks for block in row if block is not None]
    key = tuple(map(describe, present))
    indptr, indices, order, shape = _block_layouts.get(key) or _block_layouts.put(key, _layout(blocks, present))
    data = np.concatenate([block.data for block in present])[order]
    return sp.csc_matrix((data, indices, indptr), shape=shape)


def _layout(blocks: list, present: list) -> tuple:
    """(indptr, indices, order, shape): the block matrix's structure (read-only) and where each of its entries is in
    the blocks' concatenated data (found by assembling the blocks with their entries' positions as values)."""
    offsets = np.cumsum([0] + [block.nnz for block in present])
    ranges = iter(zip(offsets[:-1], offsets[1:]))

    def positions(block):
        if block is None:
            return None
        start, stop = next(ranges)  # the blocks in row order, as in ``present``
        return sp.csc_matrix((np.arange(start, stop, dtype=float) + 1, block.indices, block.indptr), shape=block.shape)

    whole = sp.bmat([[positions(block) for block in row] for row in blocks], format="csc")
    whole.sum_duplicates()
    order = whole.data.astype(np.int64) - 1  # exact: positions below 2^53
    return (*read_only(whole.indptr.copy(), whole.indices.copy(), order), whole.shape)
