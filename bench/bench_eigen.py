"""Eigen solve of a refined level: ARPACK (shift-invert Lanczos) against the block Krylov space the code uses.

For the original plate, the h_p = 1 mm FEM optimum and P2, the modes of one level start the eigen solve of the
next (degrees 3 -> 4 by default) on one PARDISO/SuperLU factorisation of K - sigma M: ARPACK from the lower modes
combined into one vector (the path before 2026-11-27), and :func:`~workflow.models.fem.modes.block_krylov_modes`
from the lower modes as a block.  Prints one JSON object: per plate the time and the solve calls of each, their
ratio, and how far the block method's six eigenvalues and modes are from ARPACK's.  docs/fem.md, "Speed".

    python bench/bench_eigen.py [--levels 3 4]
"""

import argparse
import json
import time

import numpy as np

from workflow.models import analytical
from workflow.models.fem import modes as modes_module
from workflow.models.fem.accuracy import mesh_for_level
from workflow.models.fem.evaluate import discretise, evaluate_on_mesh
from workflow.models.fem.prolongation import start_block
from workflow.models.fem.solvers import factorise
from workflow.models.plate import ORIGINAL_PLATE
from workflow.units import MM

PLATES = {
    "original": {},
    "hp1_optimum": {"wavelength": 21.515 * MM, "resonator_thickness": 0.916 * MM, "ceramic_thickness": 1.0 * MM,
                    "width": 49 * MM},
    "P2": {"wavelength": 15.66 * MM, "resonator_thickness": 0.5 * MM, "ceramic_thickness": 0.5 * MM, "width": 49 * MM},
}
"""The plates, as changes of the original plate [m] (as in bench/bench_fem.py)."""


def compared(plate, lower_level: int, level: int) -> dict:
    """ARPACK and the block method on one factorisation of ``plate`` at ``level``, started from ``lower_level``."""
    lower = evaluate_on_mesh(plate, 54.0, 15.0, mesh_for_level(plate, lower_level)).solution
    mesh, system, _ = discretise(plate, 15.0, mesh_for_level(plate, level))
    shift = (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2
    factor = factorise(system.shifted(shift))
    calls = {"n": 0}

    def counted(rhs):
        calls["n"] += 1
        return factor.solve(rhs)

    start = start_block(lower, mesh, system.free_dofs)
    figures = {"n_dofs": int(system.mass.shape[0])}
    results = {}
    for name, first in (("arpack", start @ np.linspace(1.0, 2.0, start.shape[1])), ("block_krylov", start)):
        calls["n"] = 0
        began = time.perf_counter()
        results[name] = modes_module.shift_invert_modes(system, shift, counted, 6, first)
        figures[name] = {"s": time.perf_counter() - began, "solve_calls": calls["n"]}
    arpack, block = results["arpack"], results["block_krylov"]
    match = np.abs(np.einsum("im,im->m", block.vectors, system.mass @ arpack.vectors))
    figures["arpack_over_block"] = figures["arpack"]["s"] / figures["block_krylov"]["s"]
    figures["max_eigenvalue_rel_diff"] = float(np.max(np.abs(block.eigenvalues / arpack.eigenvalues - 1)))
    figures["max_mode_mismatch"] = float(np.max(np.abs(match - 1)))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs=2, default=(3, 4), metavar=("LOWER", "LEVEL"))
    args = parser.parse_args()
    compared(ORIGINAL_PLATE, 2, 3)  # warm-up: MKL, the element types
    print(json.dumps({name: compared(ORIGINAL_PLATE.with_(**changes), *args.levels) for name, changes in PLATES.items()}))


if __name__ == "__main__":
    main()
