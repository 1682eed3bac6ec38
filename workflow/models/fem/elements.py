"""Quadratic brick elements on axis-aligned boxes: 27-node Lagrange and 20-node serendipity.

A reference brick is the unit cube with nodes on the 3 x 3 x 3 grid {0, 1/2, 1}^3 (all 27
for Lagrange, those with at most one coordinate 1/2 for serendipity) and a polynomial space
given by its monomial exponents.  Element integrals on a box of edge lengths h follow from
unit-cube integrals by scaling, so they are exact and computed once per element type.
Local degree of freedom 3 a + component.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.polynomial.legendre import leggauss

from workflow.models.materials import voigt_index


VOIGT = voigt_index()
"""Voigt index of each tensor index pair (i, j), shape (3, 3)."""


@dataclass(frozen=True, eq=False)
class ReferenceBrick:
    """A nodal quadratic brick on the unit cube.

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

    @property
    def n_nodes(self) -> int:
        return len(self.local_nodes)

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


def _gradient_scale(sizes) -> np.ndarray:
    """V / (h_k h_l) of boxes with edge lengths ``sizes`` (m, 3), shape (m, 3, 3) [m]."""
    sizes = np.atleast_2d(sizes)
    return np.prod(sizes, axis=1)[:, None, None] / (sizes[:, :, None] * sizes[:, None, :])


def _grid(max_count: int, value: int) -> np.ndarray:
    """Points of {0, 1, 2}^3 with at most ``max_count`` coordinates equal to ``value``."""
    grid = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[(grid == value).sum(axis=1) <= max_count]


LAGRANGE_27 = ReferenceBrick("lagrange27", local_nodes=_grid(3, 1), exponents=_grid(3, 2))
"""Triquadratic Lagrange brick: all 27 nodes, monomials x^a y^b z^c with a, b, c <= 2."""

SERENDIPITY_20 = ReferenceBrick("serendipity20", local_nodes=_grid(1, 1), exponents=_grid(1, 2))
"""20-node serendipity brick: corner and edge nodes, monomials with a, b, c <= 2 and at most one 2."""

BRICKS = {brick.name: brick for brick in (LAGRANGE_27, SERENDIPITY_20)}
"""The available element types by name."""
