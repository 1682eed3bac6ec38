"""Structured brick mesh of one quarter of the plate (x >= 0, y >= 0).

Element edges follow the ceramic edges, so the ceramic layer is made of whole
elements and the gaps between ceramics (and the free end of the resonator) are empty.
z = 0 is the free face of the ceramic layer, z = h_p the bonded face; a glue layer of the
plate's ``glue_thickness`` (when > 0) sits between ceramic and resonator, under the ceramics
only; the top face of the resonator is at :func:`top_face`.
"""

import math
from dataclasses import dataclass

import numpy as np

from workflow.errors import TactileError
from workflow.models.fem.elements import ReferenceBrick, brick
from workflow.models.fem.settings import FemSettings
from workflow.models.materials import VaryingGlue
from workflow.models.plate import Plate

RESONATOR, CERAMIC, GLUE = 0, 1, 2
"""Material ids of the elements."""
GLUE_UNDER = 3
"""Material id of the bond under ceramic k of a :class:`~workflow.models.materials.VaryingGlue`: GLUE_UNDER + k."""
GLUE_ELEMENTS = 1
"""Elements through the glue layer's thickness (tens of um: one quadratic element) [-]."""
MEMORY_BUDGET = 8 * 2**30
"""Most memory one FEM evaluation may take [bytes] (8 GiB): a mesh estimated above it is refused before
anything is allocated (:func:`check_memory`), and accuracy control stops refining below it."""
BYTES_PER_DOF = 20 * 2**10
"""Peak memory of an evaluation per degree of freedom of quadratic elements [bytes]: measured 15-20 KiB (sparse
factorisation and assembly; 1.1 GiB for 74 000 degrees of freedom, 2.6 GiB for 169 000, 11.8 GiB for 620 000),
rounded up; elements of degree p take p / 2 times as much (:func:`mesh_memory`)."""


class MeshTooLargeError(TactileError):
    """A mesh whose evaluation would take more than :data:`MEMORY_BUDGET`."""


def mesh_memory(plate: Plate, settings: FemSettings) -> tuple[int, int]:
    """(degrees of freedom, estimated peak memory [bytes]) of the evaluation of ``plate`` on ``settings``, from
    the element counts and degrees alone (an upper bound: the full tensor grid of nodes, gaps included, with the
    electric potential as a fourth unknown at every node of the coupled model; the memory per unknown grows with
    the degree, as the couplings per row do)."""
    _, _, counts = _x_counts(plate, settings)
    layers = 2 * settings.elements_per_layer + (GLUE_ELEMENTS if float(plate.glue_thickness) > 0 else 0)
    grid = (int(counts.sum()), settings.elements_across_half_width, layers)
    degrees = brick(settings.element).degrees
    dofs = (4 if settings.piezo == "coupled" else 3) * math.prod(p * n + 1 for p, n in zip(degrees, grid))
    return dofs, int(dofs * BYTES_PER_DOF * max(degrees) / 2)


def check_memory(plate: Plate, settings: FemSettings) -> None:
    """Raise :class:`MeshTooLargeError` if the evaluation of ``plate`` on ``settings`` would exceed :data:`MEMORY_BUDGET`."""
    dofs, memory = mesh_memory(plate, settings)
    if memory > MEMORY_BUDGET:
        raise MeshTooLargeError(
            f"the FEM mesh of this plate ({settings.elements_per_ceramic} {settings.element} elements per ceramic, "
            f"{settings.elements_across_half_width} across the half width: about {dofs} degrees of freedom) would take "
            f"about {memory / 2**30:.1f} GiB, more than the {MEMORY_BUDGET / 2**30:g} GiB budget of one evaluation; "
            "ask for a coarser accuracy, or check the geometry (a very wide or short-wavelength plate)"
        )


@dataclass(frozen=True, eq=False)
class BrickMesh:
    """Bricks on a tensor-product grid, some grid cells removed.

    Attributes
    ----------
    brick : ReferenceBrick
        The element type.
    edges : tuple of 3 arrays
        Element boundaries along x, y, z [m].
    cells : (n, 3) int array
        Grid indices (i_x, i_y, i_z) of the kept elements.
    material : (n,) int array
        RESONATOR, CERAMIC or GLUE per element (GLUE_UNDER + k under ceramic k of a varying bond).
    polarity : (n,) float array
        +1/-1 poling sign of ceramic elements, 0 for the resonator [-].
    node_number : 3D int array
        Node number on the (p_x n_x + 1, p_y n_y + 1, p_z n_z + 1) grid of nodes (p: the brick's degrees), -1 if unused.
    connectivity : (n, n_local) int array
        Node numbers of each element in the order of ``brick.local_nodes``.
    """

    brick: ReferenceBrick
    edges: tuple
    cells: np.ndarray
    material: np.ndarray
    polarity: np.ndarray
    node_number: np.ndarray
    connectivity: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(self.node_number.max()) + 1

    @property
    def n_dofs(self) -> int:
        return 3 * self.n_nodes

    @property
    def sizes(self) -> np.ndarray:
        """Element edge lengths, shape (n, 3) [m]."""
        return np.stack([np.diff(self.edges[axis])[self.cells[:, axis]] for axis in range(3)], axis=1)

    def node_grid_coordinates(self, axis: int) -> np.ndarray:
        """Coordinates of the node grid along one axis (element edges and the nodes between) [m]."""
        edges = self.edges[axis]
        inner = self.brick.node_coordinates(axis)[:-1]
        grid = edges[:-1, None] + np.diff(edges)[:, None] * inner[None, :]
        return np.concatenate([grid.ravel(), edges[-1:]])

    @property
    def coordinates(self) -> np.ndarray:
        """Node coordinates, shape (n_nodes, 3) [m]."""
        grids = np.meshgrid(*(self.node_grid_coordinates(axis) for axis in range(3)), indexing="ij")
        used = self.node_number >= 0
        coordinates = np.empty((self.n_nodes, 3))
        coordinates[self.node_number[used]] = np.stack([grid[used] for grid in grids], axis=1)
        return coordinates


def _subdivide(breakpoints, counts, grading=None) -> np.ndarray:
    """Edges of ``counts[i]`` elements on each segment [breakpoints[i], breakpoints[i+1]].

    ``grading[i]`` is (c_left, c_right) in [0, 1): elements shrink towards a graded end by the
    factor (1 - c) / (1 + c) relative to the mean size (the map t -> t - c sin(2 pi t)/(2 pi) for
    both ends, t +- c sin(pi t)/pi for one); None or (0, 0) is uniform.
    """
    pieces = []
    for index, (a, b, n) in enumerate(zip(breakpoints[:-1], breakpoints[1:], counts)):
        t = np.linspace(0.0, 1.0, n + 1)[:-1]
        left, right = (0.0, 0.0) if grading is None else grading[index]
        if left and right:
            t = t - left * np.sin(2 * np.pi * t) / (2 * np.pi)
        elif left or right:
            t = t + (right - left) * np.sin(np.pi * t) / np.pi
        pieces.append(a + (b - a) * t)
    return np.concatenate(pieces + [breakpoints[-1:]])


def x_segments(plate: Plate):
    """Breakpoints along x of the quarter and which segments carry a ceramic.

    Returns
    -------
    breakpoints : array
        0, ceramic and gap edges, L/2 [m].
    ceramic_index : int array
        For each segment, the index into ``plate.ceramic_centres`` of its ceramic, -1 for a gap or the free end.
    """
    centres = np.asarray(plate.ceramic_centres, dtype=float).ravel()
    half_length = float(plate.ceramic_length) / 2
    breakpoints, ceramic_index = [0.0], []
    for index in np.flatnonzero(centres >= 0):
        if centres[index] > 0:
            breakpoints.append(centres[index] - half_length)
            ceramic_index.append(-1)
        breakpoints.append(centres[index] + half_length)
        ceramic_index.append(index)
    breakpoints.append(float(plate.length) / 2)
    ceramic_index.append(-1)
    return np.array(breakpoints), np.array(ceramic_index)


def _x_counts(plate: Plate, settings: FemSettings):
    """(breakpoints, ceramic index, element count) of the segments along x (:func:`x_segments`)."""
    breakpoints, ceramic_index = x_segments(plate)
    lengths = np.diff(breakpoints)
    element_length = float(plate.ceramic_length) / settings.elements_per_ceramic
    counts = np.where(
        ceramic_index >= 0,
        np.maximum(1, np.round(lengths / element_length)),
        settings.elements_per_gap,
    ).astype(int)
    counts[-1] = max(1, int(np.ceil(lengths[-1] / element_length - 0.25)))
    return breakpoints, ceramic_index, counts


def quarter_plate_mesh(plate: Plate, settings: FemSettings) -> BrickMesh:
    """The structured mesh of the quarter plate for ``settings``.

    Raises
    ------
    MeshTooLargeError
        If its evaluation would exceed :data:`MEMORY_BUDGET` (checked before anything is allocated).
    """
    check_memory(plate, settings)
    breakpoints, ceramic_index, counts = _x_counts(plate, settings)
    free_end = len(counts) - 1
    grade = settings.grading
    is_ceramic = ceramic_index >= 0
    grading = [
        (grade if breakpoints[i] > 0 else 0.0, grade) if is_ceramic[i] else (grade if i == free_end else 0.0, 0.0)
        for i in range(len(counts))
    ]
    x_edges = _subdivide(breakpoints, counts, grading)
    segment_of_x_cell = np.repeat(np.arange(len(counts)), counts)

    h_p, h_i, h_g = float(plate.ceramic_thickness), float(plate.resonator_thickness), float(plate.glue_thickness)
    n_layer = settings.elements_per_layer
    n_glue = GLUE_ELEMENTS if h_g > 0 else 0
    if n_glue:
        z_edges = _subdivide(
            np.array([0.0, h_p, h_p + h_g, h_p + h_g + h_i]),
            [n_layer, n_glue, n_layer],
            [(0.0, grade), (0.0, 0.0), (grade, 0.0)],
        )
    else:
        z_edges = _subdivide(np.array([0.0, h_p, h_p + h_i]), [n_layer, n_layer], [(0.0, grade), (grade, 0.0)])
    y_edges = np.linspace(0.0, float(plate.width) / 2, settings.elements_across_half_width + 1)

    grid_shape = (len(x_edges) - 1, len(y_edges) - 1, len(z_edges) - 1)
    cells = np.stack(np.meshgrid(*(np.arange(n) for n in grid_shape), indexing="ij"), axis=-1).reshape(-1, 3)
    cell_ceramic = ceramic_index[segment_of_x_cell[cells[:, 0]]]
    layer = np.where(cells[:, 2] < n_layer, CERAMIC, np.where(cells[:, 2] < n_layer + n_glue, GLUE, RESONATOR))
    keep = (layer == RESONATOR) | (cell_ceramic >= 0)
    cells, cell_ceramic, material = cells[keep], cell_ceramic[keep], layer[keep]
    if isinstance(plate.glue, VaryingGlue):
        material = np.where(material == GLUE, GLUE_UNDER + cell_ceramic, material)
    polarity = np.where(material == CERAMIC, np.asarray(plate.polarities)[cell_ceramic], 0).astype(float)

    return brick_mesh(brick(settings.element), (x_edges, y_edges, z_edges), cells, material, polarity)


def brick_mesh(element: ReferenceBrick, edges: tuple, cells, material, polarity) -> BrickMesh:
    """A :class:`BrickMesh` of the kept ``cells`` of a tensor grid, its nodes numbered.

    Parameters
    ----------
    element : ReferenceBrick
    edges : tuple of 3 arrays
        Element boundaries along x, y, z [m].
    cells : (n, 3) int array
        Grid indices of the kept elements.
    material, polarity : (n,) arrays
        Material id and poling sign per element.
    """
    grid_shape = tuple(len(axis_edges) - 1 for axis_edges in edges)
    degrees = np.asarray(element.degrees)
    grid_nodes = degrees * cells[:, None, :] + element.local_nodes[None]  # (n, n_local, 3)
    node_shape = tuple(p * n + 1 for p, n in zip(element.degrees, grid_shape))
    flat = np.ravel_multi_index(tuple(grid_nodes.reshape(-1, 3).T), node_shape)
    used, inverse = np.unique(flat, return_inverse=True)
    node_number = np.full(int(np.prod(node_shape)), -1)
    node_number[used] = np.arange(len(used))
    return BrickMesh(
        brick=element,
        edges=tuple(edges),
        cells=cells,
        material=material,
        polarity=polarity,
        node_number=node_number.reshape(node_shape),
        connectivity=inverse.reshape(len(cells), element.n_nodes),
    )


def top_face(plate: Plate) -> float:
    """Height of the resonator's top face, where the deflection is measured: h_p + glue + h_i [m]."""
    return float(plate.total_thickness) + float(plate.glue_thickness)


def symmetry_dofs(mesh: BrickMesh) -> np.ndarray:
    """Constrained dofs of the symmetry planes: u_x on x = 0 and u_y on y = 0."""
    on_x0 = mesh.node_number[0][mesh.node_number[0] >= 0]
    on_y0 = mesh.node_number[:, 0][mesh.node_number[:, 0] >= 0]
    return np.concatenate([3 * on_x0, 3 * on_y0 + 1])
