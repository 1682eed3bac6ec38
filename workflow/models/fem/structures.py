"""Sparsity structures shared between evaluations, recognised by their memory.

The assembly's patterns (:mod:`~workflow.models.fem.assembly`) are read-only arrays shared by every matrix of
one mesh topology; what is derived from a structure alone (its upper triangle, PARDISO's analysis, the layout of
a block matrix) is made once per structure and found again by the memory of its arrays, not by their values.
"""

import hashlib
import weakref
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp


def owner(array: np.ndarray) -> np.ndarray:
    """The array that owns the memory of ``array`` (itself, or the base of its views)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array


def memory(array: np.ndarray) -> tuple:
    """(weak reference to the owner, first byte, length, dtype) of a read-only array."""
    return weakref.ref(owner(array)), array.__array_interface__["data"][0], array.size, array.dtype


def same_memory(held: tuple, array: np.ndarray) -> bool:
    """Whether ``array`` is the read-only array described by ``held`` (:func:`memory`), its owner still alive."""
    held_owner, start, size, dtype = held
    return (held_owner() is owner(array) and start == array.__array_interface__["data"][0] and size == array.size
            and dtype == array.dtype and not array.flags.writeable)


def shared(matrix) -> bool:
    """Whether a compressed sparse matrix's structure is read-only (shared between evaluations)."""
    return not matrix.indices.flags.writeable and not matrix.indptr.flags.writeable


BLOCK_LAYOUTS = 4
"""Block-matrix layouts kept, one per structure of the blocks [-]."""
_block_layouts: OrderedDict = OrderedDict()


def _structure_key(matrix: sp.csc_matrix):
    """What identifies a block's structure: the memory of shared arrays (found again without reading them), else a
    digest of the arrays' contents."""
    if shared(matrix):
        return ("shared", matrix.shape, id(owner(matrix.indptr)), matrix.indptr.__array_interface__["data"][0],
                id(owner(matrix.indices)), matrix.indices.__array_interface__["data"][0], matrix.nnz)
    digest = hashlib.blake2b(matrix.indptr.tobytes(), digest_size=16)
    digest.update(matrix.indices.tobytes())
    return ("content", matrix.shape, digest.hexdigest())


def shared_block_matrix(blocks: list) -> sp.csc_matrix:
    """``scipy.sparse.bmat(blocks, format="csc")`` on a read-only structure shared by every call whose blocks have
    the same structures, so that what is derived from it (:mod:`~workflow.models.fem.solvers`) is made once.

    Parameters
    ----------
    blocks : list of lists of sparse matrices (or None)
        Each in canonical CSC form (sorted indices, no duplicates) or convertible to it.
    """
    blocks = [[None if block is None else _canonical(block) for block in row] for row in blocks]
    present = [block for row in blocks for block in row if block is not None]
    key = tuple(_structure_key(block) for block in present)
    layout = _block_layouts.get(key)
    if layout is not None and all(ref() is not None for ref in layout[3]):
        _block_layouts.move_to_end(key)
    else:
        layout = _layout(blocks, present)
        _block_layouts[key] = layout
        while len(_block_layouts) > BLOCK_LAYOUTS:
            _block_layouts.popitem(last=False)
    indptr, indices, order, _, shape = layout
    data = np.concatenate([block.data for block in present])[order]
    return sp.csc_matrix((data, indices, indptr), shape=shape)


def _canonical(block) -> sp.csc_matrix:
    block = sp.csc_matrix(block)
    if not block.has_canonical_format:
        block = block.copy()
        block.sum_duplicates()
    return block


def _layout(blocks: list, present: list) -> tuple:
    """(indptr, indices, order, owners, shape): the block matrix's structure (read-only) and where each of its entries
    is in the blocks' concatenated data; ``owners`` (weak references) keep a layout of shared blocks from outliving
    their arrays, whose addresses are its key."""
    offsets = np.cumsum([0] + [block.nnz for block in present])
    coded, position = [], iter(range(len(present)))
    for row in blocks:
        coded_row = []
        for block in row:
            if block is None:
                coded_row.append(None)
                continue
            index = next(position)
            positions = np.arange(offsets[index], offsets[index + 1], dtype=float) + 1  # exact below 2^53
            coded_row.append(sp.csc_matrix((positions, block.indices, block.indptr), shape=block.shape))
        coded.append(coded_row)
    whole = sp.bmat(coded, format="csc")
    whole.sum_duplicates()
    order = whole.data.astype(np.int64) - 1
    indptr, indices = whole.indptr.copy(), whole.indices.copy()
    for array in (indptr, indices, order):
        array.flags.writeable = False
    owners = tuple(weakref.ref(owner(block.indices)) for block in present if shared(block))
    return indptr, indices, order, owners, whole.shape
