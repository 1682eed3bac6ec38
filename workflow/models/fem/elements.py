"""Brick elements on axis-aligned boxes: tensor-product Lagrange of any degree per axis, and 20-node serendipity.

A reference brick is the unit cube with nodes on a grid of (p_x + 1) x (p_y + 1) x (p_z + 1)
points.  The tensor-product Lagrange brick of degrees (p_x, p_y, p_z) has all of them, placed at
the Gauss-Lobatto points of each axis (equally spaced for p <= 2: degrees (2, 2, 2) is the
27-node triquadratic brick), and its element integrals are Kronecker products of exact 1D
integrals.  The 20-node serendipity brick keeps the nodes of the 3 x 3 x 3 grid with at most one
mid-edge coordinate and spans its monomials.  Element integrals on a box of edge lengths h follow
from unit-cube integrals by scaling, so they are exact and computed once per element type.
Local degree of freedom 3 a + component.
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.polynomial.legendre import leggauss

from workflow.models.materials import voigt_index


VOIGT = voigt_index()
"""Voigt index of each tensor index pair (i, j), shape (3, 3)."""


class ReferenceBrick:
    """A nodal brick on the unit cube: what the element integrals need.

    Subclasses give ``name``, ``degrees`` (the node grid has ``degrees[axis] + 1`` points per axis),
    ``local_nodes`` ((n, 3) int array: each node's position on that grid), ``node_coordinates(axis)``
    (the grid's reference coordinates in [0, 1]) and the unit-cube integrals ``gradient_products``
    R_kl = int d_k phi_a d_l phi_b (3, 3, n, n), ``mass`` int phi_a phi_b (n, n), ``gradient_means``
    int d_k phi_a (3, n) and ``shape(points)`` (m, n).  ``lumped``: whether ``mass`` is diagonal.
    """

    lumped = False

    @property
    def n_nodes(self) -> int:
        return len(self.local_nodes)

    def elasticity_blocks(self, stiffness) -> np.ndarray:
        """Unit-cube stiffness parts B_kl with K_e = sum_kl V / (h_k h_l) B_kl; shape (3, 3, 3n, 3n) [Pa].

        From a(u, v) = int C_ikjl d_l u_j d_k v_i: B_kl = kron(R_kl, C_kl) with (C_kl)_ij = C_ikjl.

        Parameters
        ----------
        stiffness : (6, 6) array
            Voigt stiffness C (xx, yy, zz, yz, xz, xy) [Pa].
        """
        tensor = np.asarray(stiffness)[VOIGT[:, :, None, None], VOIGT[None, None, :, :]]  # C_ikjl
        return np.stack(
            [np.stack([np.kron(self.gradient_products[k, m], tensor[:, k, :, m]) for m in range(3)]) for k in range(3)]
        )

    def box_stiffness(self, sizes, stiffness) -> np.ndarray:
        """Stiffness matrices of boxes with edge lengths ``sizes`` (m, 3) [m]; shape (m, 3n, 3n) [N/m].

        Parameters
        ----------
        stiffness : (6, 6) array
            Voigt stiffness of the material [Pa].
        """
        return np.einsum("mkl,klij->mij", _gradient_scale(sizes), self.elasticity_blocks(stiffness))

    def box_piezo_coupling(self, sizes, piezo_stress) -> np.ndarray:
        """K_u phi of boxes: int e_kij d_j v_i d_k psi, shape (m, 3n, n) [C/m^2 m = C/m].

        Parameters
        ----------
        sizes : (m, 3) array
            Box edge lengths [m].
        piezo_stress : (3, 6) array
            e [C/m^2] (Voigt columns).
        """
        tensor = np.asarray(piezo_stress)[:, VOIGT]  # e_kij
        blocks = np.stack(
            [
                np.stack([np.kron(self.gradient_products[j, k], tensor[k, :, j][:, None]) for k in range(3)])
                for j in range(3)
            ]
        )
        return np.einsum("mjk,jkab->mab", _gradient_scale(sizes), blocks)

    def box_permittivity(self, sizes, permittivity) -> np.ndarray:
        """K_phi phi of boxes: int eps_jk d_j psi d_k phi, shape (m, n, n) [F].

        Parameters
        ----------
        permittivity : (3, 3) array
            eps^S [F/m].
        """
        blocks = np.asarray(permittivity)[:, :, None, None] * self.gradient_products
        return np.einsum("mjk,jkab->mab", _gradient_scale(sizes), blocks)

    def box_mass(self, sizes, density) -> np.ndarray:
        """Consistent mass matrices; shape (m, 3n, 3n) [kg]."""
        volume = np.prod(np.atleast_2d(sizes), axis=1)
        return density * volume[:, None, None] * np.kron(self.mass, np.eye(3))[None]

    def box_prestress_load(self, sizes, stress) -> np.ndarray:
        """Nodal forces of a uniform eigenstress per box, f_(a,i) = int sigma*_ij d_j phi_a; shape (m, 3n) [N].

        Parameters
        ----------
        sizes : (m, 3) array
            Box edge lengths [m].
        stress : (m, 6) array
            sigma* in Voigt order per box [Pa] (for a piezo-ceramic, e^T E; for an eigenstrain, C eps*).
        """
        sizes = np.atleast_2d(sizes)
        volume = np.prod(sizes, axis=1)
        tensor = np.asarray(stress, dtype=float)[:, VOIGT]  # (m, 3, 3)
        per_axis = (volume[:, None] / sizes)[:, :, None] * self.gradient_means[None]  # (m, 3 axes j, n)
        return np.einsum("mij,mja->mai", tensor, per_axis).reshape(len(sizes), 3 * self.n_nodes)


@dataclass(frozen=True, eq=False)
class MonomialBrick(ReferenceBrick):
    """A nodal quadratic brick on the unit cube spanning given monomials (nodes on {0, 1/2, 1}^3).

    Attributes
    ----------
    name : str
    local_nodes : (n, 3) int array
        Node positions on the grid {0, 1, 2}^3 (half-units of the cube).
    exponents : (n, 3) int array
        Monomial exponents spanning the polynomial space.
    """

    name: str
    local_nodes: np.ndarray
    exponents: np.ndarray
    degrees: tuple = (2, 2, 2)

    def node_coordinates(self, axis: int) -> np.ndarray:
        """Reference coordinates of the node grid along ``axis``: 0, 1/2, 1."""
        return np.linspace(0.0, 1.0, self.degrees[axis] + 1)

    @cached_property
    def _coefficients(self) -> np.ndarray:
        """Monomial coefficients of the nodal shape functions, shape (n_monomials, n_nodes)."""
        return np.linalg.inv(self._monomials(self.local_nodes / 2.0))

    def _monomials(self, points) -> np.ndarray:
        return np.prod(np.asarray(points)[:, None, :] ** self.exponents[None], axis=-1)

    def shape(self, points) -> np.ndarray:
        """Shape functions at reference points (m, 3) in [0, 1]^3, shape (m, n_nodes) [-]."""
        return self._monomials(points) @ self._coefficients

    def shape_gradient(self, points) -> np.ndarray:
        """Reference gradients of the shape functions, shape (3, m, n_nodes) [-]."""
        points = np.asarray(points)[:, None, :]
        gradients = []
        for axis in range(3):
            lowered = self.exponents.copy()
            factor = lowered[:, axis].astype(float)
            lowered[:, axis] = np.maximum(lowered[:, axis] - 1, 0)
            gradients.append((factor * np.prod(points**lowered[None], axis=-1)) @ self._coefficients)
        return np.stack(gradients)

    @cached_property
    def _quadrature(self):
        """3-point Gauss rule per axis on [0, 1]^3 (exact: degree <= 5 per variable)."""
        nodes, weights = leggauss(3)
        nodes, weights = (nodes + 1) / 2, weights / 2
        grid = np.stack(np.meshgrid(nodes, nodes, nodes, indexing="ij"), axis=-1).reshape(-1, 3)
        return grid, np.prod(np.stack(np.meshgrid(weights, weights, weights, indexing="ij"), -1).reshape(-1, 3), 1)

    @cached_property
    def gradient_products(self) -> np.ndarray:
        """R_kl = int_cube d_k phi_a d_l phi_b, shape (3, 3, n, n) [-]."""
        points, weights = self._quadrature
        gradient = self.shape_gradient(points)
        return np.einsum("q,kqa,lqb->klab", weights, gradient, gradient)

    @cached_property
    def mass(self) -> np.ndarray:
        """int_cube phi_a phi_b, shape (n, n) [-]."""
        points, weights = self._quadrature
        values = self.shape(points)
        return np.einsum("q,qa,qb->ab", weights, values, values)

    @cached_property
    def gradient_means(self) -> np.ndarray:
        """int_cube d_k phi_a, shape (3, n) [-]."""
        points, weights = self._quadrature
        return np.einsum("q,kqa->ka", weights, self.shape_gradient(points))


def lobatto_points(degree: int) -> np.ndarray:
    """The degree + 1 Gauss-Lobatto points on [0, 1] (ends and the roots of P'_degree), ascending."""
    if degree == 1:
        return np.array([0.0, 1.0])
    interior = np.polynomial.legendre.Legendre.basis(degree).deriv().roots()
    return np.concatenate([[0.0], (np.sort(interior.real) + 1) / 2, [1.0]])


@dataclass(frozen=True)
class Lagrange1D:
    """The Lagrange polynomials of the Gauss-Lobatto points of one degree on [0, 1], and their exact integrals.

    Attributes
    ----------
    degree : int
    """

    degree: int

    @cached_property
    def nodes(self) -> np.ndarray:
        return lobatto_points(self.degree)

    @cached_property
    def _coefficients(self) -> np.ndarray:
        """Monomial coefficients (centred at 1/2) of the nodal polynomials, shape (degree + 1, degree + 1)."""
        return np.linalg.inv(np.vander(self.nodes - 0.5, self.degree + 1, increasing=True))

    def values(self, t) -> np.ndarray:
        """l_a(t), shape (len(t), degree + 1) [-]."""
        return np.vander(np.asarray(t, dtype=float) - 0.5, self.degree + 1, increasing=True) @ self._coefficients

    def derivatives(self, t) -> np.ndarray:
        """l_a'(t), shape (len(t), degree + 1) [-]."""
        powers = np.vander(np.asarray(t, dtype=float) - 0.5, self.degree + 1, increasing=True)
        scaled = np.zeros_like(powers)
        scaled[:, 1:] = powers[:, :-1] * np.arange(1, self.degree + 1)
        return scaled @ self._coefficients

    @cached_property
    def _quadrature(self):
        """Gauss rule exact for the products (degree 2p) [-]."""
        points, weights = leggauss(self.degree + 1)
        return (points + 1) / 2, weights / 2

    @cached_property
    def lobatto_weights(self) -> np.ndarray:
        """Weights of the Gauss-Lobatto rule on the nodes (exact to degree 2p - 1) [-]."""
        if self.degree == 1:
            return np.array([0.5, 0.5])
        legendre = np.polynomial.legendre.Legendre.basis(self.degree)(2 * self.nodes - 1)
        return 1.0 / (self.degree * (self.degree + 1) * legendre**2)

    @cached_property
    def integrals(self) -> dict:
        """``mass`` int l_a l_b, ``stiffness`` int l_a' l_b', ``mixed`` int l_a' l_b, ``mean`` int l_a' [-]."""
        t, w = self._quadrature
        value, slope = self.values(t), self.derivatives(t)
        return {
            "mass": np.einsum("q,qa,qb->ab", w, value, value),
            "stiffness": np.einsum("q,qa,qb->ab", w, slope, slope),
            "mixed": np.einsum("q,qa,qb->ab", w, slope, value),
            "mean": w @ slope,
        }


@dataclass(frozen=True, eq=False)
class TensorBrick(ReferenceBrick):
    """Tensor-product Lagrange brick of degrees (p_x, p_y, p_z) on Gauss-Lobatto nodes.

    Local node a = (i, j, k) in C order (k fastest); its shape function is l_i(x) l_j(y) l_k(z), and
    every unit-cube integral is a Kronecker product of 1D integrals, exact to rounding.  A *spectral*
    brick integrates its mass with the nodes' own Gauss-Lobatto rule, so the mass is diagonal (the
    spectral-element method; its frequencies differ from the consistent mass's by far less than the
    discretisation error at p >= 3, docs/fem.md).

    Attributes
    ----------
    degrees : tuple of 3 int
        Polynomial degree along x, y, z [-].
    lumped : bool
        Diagonal Gauss-Lobatto mass (spectral) instead of the exact (consistent) one.
    """

    degrees: tuple
    lumped: bool = False

    @property
    def name(self) -> str:
        if self.degrees == (2, 2, 2) and not self.lumped:
            return "lagrange27"
        return ("spectral-" if self.lumped else "lagrange-") + "-".join(map(str, self.degrees))

    @cached_property
    def axes(self) -> tuple:
        return tuple(Lagrange1D(p) for p in self.degrees)

    @cached_property
    def local_nodes(self) -> np.ndarray:
        grids = np.meshgrid(*(np.arange(p + 1) for p in self.degrees), indexing="ij")
        return np.stack(grids, axis=-1).reshape(-1, 3)

    def node_coordinates(self, axis: int) -> np.ndarray:
        """Reference coordinates of the node grid along ``axis`` (Gauss-Lobatto points) [-]."""
        return self.axes[axis].nodes

    def shape(self, points) -> np.ndarray:
        """Shape functions at reference points (m, 3) in [0, 1]^3, shape (m, n_nodes) [-]."""
        points = np.atleast_2d(points)
        x, y, z = (axis.values(points[:, i]) for i, axis in enumerate(self.axes))
        return np.einsum("mi,mj,mk->mijk", x, y, z).reshape(len(points), -1)

    def _kron(self, pick) -> np.ndarray:
        """Kronecker product over the axes of ``pick(axis) -> 1D integral matrix``."""
        x, y, z = (pick(axis) for axis in range(3))
        return np.kron(x, np.kron(y, z))

    @cached_property
    def gradient_products(self) -> np.ndarray:
        """R_kl = int_cube d_k phi_a d_l phi_b, shape (3, 3, n, n) [-]."""

        def factor(k, l, axis):
            one = self.axes[axis].integrals
            if axis == k == l:
                return one["stiffness"]
            if axis == k:
                return one["mixed"]
            if axis == l:
                return one["mixed"].T
            return one["mass"]

        return np.stack([np.stack([self._kron(lambda axis: factor(k, l, axis)) for l in range(3)]) for k in range(3)])

    @cached_property
    def mass(self) -> np.ndarray:
        """int_cube phi_a phi_b, shape (n, n) [-] (diagonal by the nodes' Gauss-Lobatto rule when ``lumped``)."""
        if self.lumped:
            return self._kron(lambda axis: np.diag(self.axes[axis].lobatto_weights))
        return self._kron(lambda axis: self.axes[axis].integrals["mass"])

    @cached_property
    def gradient_means(self) -> np.ndarray:
        """int_cube d_k phi_a, shape (3, n) [-]."""
        def factor(k, axis):
            one = self.axes[axis].integrals
            return one["mean"] if axis == k else one["mass"].sum(axis=0)

        return np.stack([self._kron(lambda axis: factor(k, axis)[None, :])[0] for k in range(3)])


def _gradient_scale(sizes) -> np.ndarray:
    """V / (h_k h_l) of boxes with edge lengths ``sizes`` (m, 3), shape (m, 3, 3) [m]."""
    sizes = np.atleast_2d(sizes)
    return np.prod(sizes, axis=1)[:, None, None] / (sizes[:, :, None] * sizes[:, None, :])


def _grid(max_count: int, value: int) -> np.ndarray:
    """Points of {0, 1, 2}^3 with at most ``max_count`` coordinates equal to ``value``."""
    grid = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[(grid == value).sum(axis=1) <= max_count]


LAGRANGE_27 = TensorBrick((2, 2, 2))
"""Triquadratic Lagrange brick: all 27 nodes, monomials x^a y^b z^c with a, b, c <= 2."""

SERENDIPITY_20 = MonomialBrick("serendipity20", local_nodes=_grid(1, 1), exponents=_grid(1, 2))
"""20-node serendipity brick: corner and edge nodes, monomials with a, b, c <= 2 and at most one 2."""

BRICKS = {brick.name: brick for brick in (LAGRANGE_27, SERENDIPITY_20)}
"""The quadratic element types by name (any tensor-product degrees: :func:`brick`)."""
MAX_DEGREE = 6
"""Highest polynomial degree per axis of a tensor-product brick [-]."""


@lru_cache(maxsize=None)
def tensor_brick(degrees: tuple, lumped: bool = False) -> TensorBrick:
    """The (cached) tensor-product Lagrange brick of ``degrees`` (p_x, p_y, p_z), each from 1 to :data:`MAX_DEGREE`."""
    return TensorBrick(tuple(int(p) for p in degrees), lumped)


def brick(name: str) -> ReferenceBrick:
    """The element type ``name``: "lagrange27", "serendipity20", or "lagrange-PX-PY-PZ" / "spectral-PX-PY-PZ"
    (tensor-product degrees along x, y, z; spectral: Gauss-Lobatto-lumped mass)."""
    if name in BRICKS:
        return BRICKS[name]
    parts = name.split("-")
    if (len(parts) == 4 and parts[0] in ("lagrange", "spectral")
            and all(p.isdigit() and 1 <= int(p) <= MAX_DEGREE for p in parts[1:])):
        return tensor_brick(tuple(int(p) for p in parts[1:]), parts[0] == "spectral")
    raise KeyError(name)
