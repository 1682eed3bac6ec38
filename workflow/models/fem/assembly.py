"""Vectorised assembly of stiffness, mass and piezo load on a :class:`BrickMesh`.

Element matrices depend only on the element's box size and material, so they are computed
once per distinct (size, material).  The plain path scatters them with one COO assembly
(:func:`scatter_matrices`); the fast path of an evaluation (:func:`assemble_system`) sums them
into the reduced matrices through a :class:`ReducedPattern`, which depends only on the mesh's
topology (element counts and type, not the dimensions) and is cached per topology.
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import scipy.sparse as sp

from workflow.models.fem.mesh import CERAMIC, GLUE, GLUE_UNDER, RESONATOR, BrickMesh, symmetry_dofs
from workflow.models.fem.structures import read_only
from workflow.models.materials import VaryingGlue
from workflow.models.plate import Plate


@dataclass(frozen=True, eq=False)
class PlateSystem:
    """Reduced (symmetry-constrained) system K u = F, mass M, and the map back to all dofs.

    Attributes
    ----------
    stiffness, mass : scipy.sparse.csc_matrix
        K [N/m] and M [kg] on the free dofs.
    load : array
        Piezo load F for the drive voltage [N].
    free_dofs : int array
        Global dof number of each free dof.
    diagonal_entries : int array or None
        Where the stiffness's diagonal lies in its ``data``, when the mass is diagonal (spectral elements):
        :meth:`shifted` then keeps the stiffness's structure.
    """

    stiffness: sp.csc_matrix
    mass: sp.csc_matrix
    load: np.ndarray
    free_dofs: np.ndarray
    diagonal_entries: np.ndarray | None = None

    def shifted(self, shift: float) -> sp.csc_matrix:
        """K - shift M [N/m]; on the stiffness's own (shared, read-only) structure when the mass is diagonal."""
        if self.diagonal_entries is None:
            return (self.stiffness - shift * self.mass).tocsc()
        data = self.stiffness.data.copy()
        data[self.diagonal_entries] -= shift * self.mass.diagonal()
        return on_pattern(data, self.stiffness.indices, self.stiffness.indptr, self.stiffness.shape)


def on_pattern(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, shape: tuple) -> sp.csc_matrix:
    """A CSC matrix on a pattern's structure, marked canonical (its rows sorted, no duplicates: scipy need not check
    the 20-30 million entries of a degree-4 matrix again before each factorisation)."""
    matrix = sp.csc_matrix((data, indices, indptr), shape=shape)
    matrix.has_canonical_format = True
    return matrix


def _materials(plate: Plate):
    varying = {GLUE_UNDER + k: plate.glue.under_ceramic(k) for k in range(plate.n_ceramics)
               } if isinstance(plate.glue, VaryingGlue) else {}
    return {RESONATOR: plate.resonator, CERAMIC: plate.ceramic, GLUE: plate.glue, **varying}


def element_dofs(mesh: BrickMesh) -> np.ndarray:
    """Global dofs of each element, shape (n, 3 n_local), local dof 3 a + component."""
    return (3 * mesh.connectivity[:, :, None] + np.arange(3)).reshape(len(mesh.cells), -1)


def element_types(mesh: BrickMesh, plate: Plate):
    """The distinct element matrices of a mesh (one per box size and material) and each element's type.

    Returns
    -------
    stiffness, mass : (n_types, 3 n_local, 3 n_local) arrays
        [N/m], [kg].
    which : (n,) int array
        Type of each element.
    """
    keys = np.column_stack([mesh.sizes, mesh.material])
    unique_keys, which = np.unique(np.round(keys, 15), axis=0, return_inverse=True)
    n_local = 3 * mesh.brick.n_nodes
    stiffness = np.empty((len(unique_keys), n_local, n_local))
    mass = np.empty_like(stiffness)
    for material_id, material in _materials(plate).items():
        rows = unique_keys[:, 3] == material_id
        stiffness[rows] = mesh.brick.box_stiffness(unique_keys[rows, :3], material.stiffness_matrix())
        mass[rows] = mesh.brick.box_mass(unique_keys[rows, :3], material.density)
    return stiffness, mass, which.ravel()


def element_matrices(mesh: BrickMesh, plate: Plate):
    """Stiffness and mass of every element, each of shape (n, 3 n_local, 3 n_local) [N/m], [kg]."""
    stiffness, mass, which = element_types(mesh, plate)
    return stiffness[which], mass[which]


def scatter_matrices(mesh: BrickMesh, *locals_) -> tuple:
    """Global matrices (all dofs) summed from element matrices, each of shape (n, 3 n_local, 3 n_local)."""
    dofs = element_dofs(mesh)
    n_local = dofs.shape[1]
    rows = np.repeat(dofs, n_local, axis=1).ravel()
    cols = np.tile(dofs, (1, n_local)).ravel()
    shape = (mesh.n_dofs, mesh.n_dofs)
    return tuple(sp.coo_matrix((local.ravel(), (rows, cols)), shape=shape).tocsc() for local in locals_)


def assemble_matrices(mesh: BrickMesh, plate: Plate):
    """Global stiffness and mass (all dofs), shape (n_dofs, n_dofs) [N/m], [kg]."""
    return scatter_matrices(mesh, *element_matrices(mesh, plate))


def assemble_piezo_load(mesh: BrickMesh, plate: Plate, voltage: float) -> np.ndarray:
    """Load of the converse effect of a uniform field E_z = polarity V / h_p in each ceramic [N].

    The eigenstress is sigma* = e^T E (e the ceramic's piezo stress constants); for the paper's
    record, e = c^E d, it is the in-plane isotropic eigenstrain d31 V / h_p.
    """
    ceramic = mesh.material == CERAMIC
    field = voltage / float(plate.ceramic_thickness) * mesh.polarity[ceramic]
    stress = field[:, None] * plate.ceramic.piezo_matrix()[2][None, :]
    local = mesh.brick.box_prestress_load(mesh.sizes[ceramic], stress)
    return np.bincount(element_dofs(mesh)[ceramic].ravel(), weights=local.ravel(), minlength=mesh.n_dofs)


def free_dofs(mesh: BrickMesh) -> np.ndarray:
    """The dofs left free by the symmetry constraints, ascending."""
    return np.setdiff1d(np.arange(mesh.n_dofs), symmetry_dofs(mesh))


def reduce_system(mesh: BrickMesh, stiffness, mass, load) -> PlateSystem:
    """Apply the symmetry constraints by removing the constrained dofs."""
    free = free_dofs(mesh)
    return PlateSystem(
        stiffness=stiffness[free][:, free].tocsc(),
        mass=mass[free][:, free].tocsc(),
        load=load[free],
        free_dofs=free,
    )


PATTERN_CACHE_SIZE = 6
"""Sparsity patterns kept in memory, one per mesh topology (about 140 MB at 73 000 dofs) [-]."""


@dataclass(frozen=True, eq=False)
class ReducedPattern:
    """Sparsity of the reduced stiffness and mass of a mesh topology, and where element entries are summed.

    The entries couple nodes in 3 x 3 blocks: element node pair (a, b) of every element adds
    its block to one *slot* (a pair of global nodes, n_slots in all).  The stiffness is the slots'
    blocks on the free dofs; the mass, component-diagonal (M_e = kron(m_e, I_3)), their diagonals.

    Attributes
    ----------
    n_free : int
        Free dofs [-].
    indptr, indices : int arrays
        CSC structure of the stiffness on the free dofs (with rows sorted; by symmetry also its CSR structure).
    diagonal_entries : (n_free,) int array
        Position of each diagonal entry in the stiffness's data.
    element_slots : (n_elements, n_local, n_local) int array
        Slot of each element node pair.
    stiffness_entries : (nnz,) int array
        Index of each stiffness entry in the (n_slots, 3, 3) block sums.
    n_slots : int
        Node pairs [-].
    """

    n_free: int
    indptr: np.ndarray
    indices: np.ndarray
    diagonal_entries: np.ndarray
    element_slots: np.ndarray
    stiffness_entries: np.ndarray
    n_slots: int

    @cached_property
    def mass_structure(self) -> tuple:
        """(indptr, indices, slot of each entry) of the consistent mass on the free dofs: the stiffness's entries
        that couple equal components (made when first asked: the spectral elements' lumped mass does not need it)."""
        same = np.flatnonzero(self.stiffness_entries % 9 % 4 == 0)  # i == j: 3 i + j in (0, 4, 8)
        indptr = np.searchsorted(same, self.indptr).astype(np.int32)
        return read_only(indptr, self.indices[same], self.stiffness_entries[same] // 9)

    def stiffness(self, types, which) -> sp.csc_matrix:
        """Reduced stiffness [N/m] from the distinct element matrices ``types`` (n_types, 3 n_local, 3 n_local) and each element's type ``which``."""
        n_local = self.element_slots.shape[1]
        local = np.reshape(types, (len(types), n_local, 3, n_local, 3)).transpose(0, 1, 3, 2, 4)
        blocks = _type_summation(self, np.ascontiguousarray(which, dtype=np.int64).tobytes()) @ local.reshape(-1, 9)
        return on_pattern(blocks.ravel()[self.stiffness_entries], self.indices, self.indptr, (self.n_free,) * 2)

    def mass(self, types, which) -> sp.csc_matrix:
        """Reduced mass [kg] from the distinct component-diagonal element matrices (as :meth:`stiffness`)."""
        n_local = self.element_slots.shape[1]
        local = np.reshape(types, (len(types), n_local, 3, n_local, 3))[:, :, 0, :, 0]
        blocks = np.bincount(self.element_slots.ravel(), weights=local[which].ravel(), minlength=self.n_slots)
        indptr, indices, entries = self.mass_structure
        return on_pattern(blocks[entries], indices, indptr, (self.n_free,) * 2)


def reduced_pattern(mesh: BrickMesh, free: np.ndarray) -> ReducedPattern:
    """The :class:`ReducedPattern` of a mesh with free dofs ``free`` (cached per topology)."""
    connectivity = np.ascontiguousarray(mesh.connectivity, dtype=np.int64)
    local_nodes = np.ascontiguousarray(mesh.brick.local_nodes, dtype=np.int64)
    free = np.ascontiguousarray(free, dtype=np.int64)
    return _cached_pattern(connectivity.tobytes(), local_nodes.tobytes(), mesh.n_nodes, free.tobytes())


def node_pairs(connectivity: np.ndarray, local_nodes: np.ndarray, n_nodes: int) -> tuple:
    """The node pairs (slots) that elements couple, sorted by row node then column node, without sorting the
    element pairs.

    A pair is named by its row node and the grid offset of its column node, which is the same in every element that
    holds the pair (the offset of local node j from local node i on the element's node grid), so a table over
    (node, offset) finds the slots in one pass over the element pairs (sorting them, :func:`numpy.unique`, took
    twice as long at degree 4).

    Parameters
    ----------
    connectivity : (n, n_local) int array
        Node numbers of each element (numbered along the node grid, as :func:`~workflow.models.fem.mesh.brick_mesh`
        does; any other numbering only costs a sort of the pairs).
    local_nodes : (n_local, 3) int array
        Position of each local node on the element's node grid.
    n_nodes : int

    Returns
    -------
    rows, cols : (n_slots,) int arrays
        Nodes (A, B) of each slot.
    slots : (n, n_local, n_local) int array
        Slot of each element's node pair (i, j): (connectivity[e, i], connectivity[e, j]).
    transposed : (n_slots,) int array
        Slot of (B, A) for each slot (A, B).
    """
    n_local = len(local_nodes)
    span = local_nodes.max(axis=0) - local_nodes.min(axis=0)
    width = 2 * span + 1
    n_offsets = int(np.prod(width))
    offsets = local_nodes[None, :, :] - local_nodes[:, None, :] + span  # (i, j): where j lies seen from i
    offset_index = np.ravel_multi_index(tuple(offsets.reshape(-1, 3).T), width).reshape(n_local, n_local)
    keys = connectivity[:, :, None] * n_offsets + offset_index
    used = np.zeros(n_nodes * n_offsets, dtype=bool)
    used[keys.ravel()] = True
    present = np.flatnonzero(used)
    del used
    table = np.empty(n_nodes * n_offsets, dtype=np.int32)  # only the present keys' entries are written and read
    table[present] = np.arange(len(present), dtype=np.int32)
    slots = table[keys]
    rows, offset = np.divmod(present, n_offsets)
    cols = np.empty(len(present), dtype=np.int64)
    cols[slots.ravel()] = np.broadcast_to(connectivity[:, None, :], keys.shape).ravel()
    transposed = table[cols * n_offsets + (n_offsets - 1 - offset)]  # the mirrored offset
    if np.any((np.diff(rows) == 0) & (np.diff(cols) < 0)):  # a numbering not along the grid: sort the slots
        order = np.argsort(rows * n_nodes + cols, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        rows, cols, slots, transposed = rows[order], cols[order], rank[slots], rank[transposed[order]]
    return rows, cols, slots, transposed


@lru_cache(maxsize=PATTERN_CACHE_SIZE)
def _cached_pattern(connectivity: bytes, local_nodes: bytes, n_nodes: int, free: bytes) -> ReducedPattern:
    local_nodes = np.frombuffer(local_nodes, dtype=np.int64).reshape(-1, 3)
    connectivity = np.frombuffer(connectivity, dtype=np.int64).reshape(-1, len(local_nodes))
    n_local = len(local_nodes)
    free = np.frombuffer(free, dtype=np.int64)
    rows, cols, slots, transposed = node_pairs(connectivity, local_nodes, n_nodes)
    is_free = np.zeros(3 * n_nodes, dtype=bool)
    is_free[free] = True
    is_free = is_free.reshape(n_nodes, 3)
    number = np.full(3 * n_nodes, -1, dtype=np.int32)
    number[free] = np.arange(len(free), dtype=np.int32)
    # items: the free dofs of each slot's column node A, slot by slot; the column (B, j) lists the items of row B
    slot_free = is_free[cols]
    flat = np.flatnonzero(slot_free).astype(np.int32)  # 3 slot + component of each item
    item_slot = flat // 3
    item_component = flat - 3 * item_slot
    item_row = number[3 * cols.astype(np.int32)[item_slot] + item_component]
    item_block = 9 * transposed.astype(np.int32)[item_slot] + 3 * item_component
    item_node = rows[item_slot]
    row_width = np.bincount(item_node, minlength=n_nodes)
    item_start = np.concatenate([[0], np.cumsum(row_width)[:-1]])
    column_node, column_component = np.divmod(free, 3)
    lengths = row_width[column_node]
    indptr = np.concatenate([[0], np.cumsum(lengths)])
    item = np.repeat((item_start[column_node] - indptr[:-1]).astype(np.int32), lengths)
    item += np.arange(indptr[-1], dtype=np.int32)
    stiffness_entries = item_block[item] + np.repeat(column_component.astype(np.int32), lengths)
    # the diagonal entry of column (B, j): the item of component j of slot (B, B) among the items of row B
    first_item = np.concatenate([[0], np.cumsum(slot_free.sum(axis=1))[:-1]])
    own = np.flatnonzero(rows == cols)
    own_slot = np.empty(n_nodes, dtype=np.int64)
    own_slot[rows[own]] = own
    rank = np.cumsum(is_free, axis=1) - 1  # of each free component among its node's free components
    diagonal = first_item[own_slot[column_node]] + rank[column_node, column_component] - item_start[column_node]
    return ReducedPattern(*read_only(
        len(free), indptr.astype(np.int32), item_row[item], indptr[:-1] + diagonal,
        slots.reshape(connectivity.shape + (n_local,)).astype(np.int32), stiffness_entries, len(rows),
    ))


SUMMATIONS = 4
"""Type summations kept in memory (:func:`_type_summation`; about 40 MB each at degree 4) [-]."""


@lru_cache(maxsize=SUMMATIONS)
def _type_summation(pattern: ReducedPattern, which: bytes) -> sp.csr_matrix:
    """How many times each node pair (a, b) of each element type is summed into each slot, shape
    (n_slots, n_types n_local^2) [-]: the stiffness's slot blocks are this matrix times the types' (a, b) blocks.

    It depends on the topology and on which elements share a type (``which``, int64 bytes), not on the dimensions,
    so the neighbouring geometries of a search or a map reuse it; the product costs a tenth of summing the elements'
    entries one by one.
    """
    which = np.frombuffer(which, dtype=np.int64)
    n_local = pattern.element_slots.shape[1]
    pairs = n_local * n_local
    columns = (which[:, None] * pairs + np.arange(pairs)).ravel()
    ones = np.ones(len(columns))
    return sp.csr_matrix((ones, (pattern.element_slots.ravel(), columns)),
                         shape=(pattern.n_slots, (int(which.max()) + 1) * pairs))


def lumped_mass(mesh: BrickMesh, types, which, free) -> sp.csc_matrix:
    """The diagonal reduced mass [kg] of elements whose mass matrices ``types`` are diagonal (spectral bricks)."""
    diagonals = np.diagonal(types, axis1=1, axis2=2)[which]  # (n_elements, 3 n_local)
    nodal = np.bincount(element_dofs(mesh).ravel(), weights=diagonals.ravel(), minlength=mesh.n_dofs)
    return sp.diags(nodal[free], format="csc")


def reduced_matrices(mesh: BrickMesh, free: np.ndarray, stiffness_types, mass_types, which) -> tuple:
    """(K, M) on the free dofs from distinct element matrices ``*_types`` (n_types, 3 n_local, 3 n_local) and each
    element's type ``which``, summed through the topology's cached :class:`ReducedPattern` [N/m], [kg] (or the
    derivatives of both when the types are derivatives of element matrices)."""
    pattern = reduced_pattern(mesh, free)
    mass = lumped_mass(mesh, mass_types, which, free) if mesh.brick.lumped else pattern.mass(mass_types, which)
    return pattern.stiffness(stiffness_types, which), mass


def assemble_system(mesh: BrickMesh, plate: Plate, voltage: float) -> PlateSystem:
    """K, M and F of the quarter plate with its symmetry constraints (the fast, pattern-cached path).

    Equal to :func:`reduce_system` of :func:`assemble_matrices` (to rounding; the mass without the
    explicit zeros between different components).
    """
    free = free_dofs(mesh)
    stiffness, mass = reduced_matrices(mesh, free, *element_types(mesh, plate))
    return PlateSystem(
        stiffness=stiffness,
        mass=mass,
        load=assemble_piezo_load(mesh, plate, voltage)[free],
        free_dofs=free,
        diagonal_entries=reduced_pattern(mesh, free).diagonal_entries if mesh.brick.lumped else None,
    )
