"""Benchmark of the beam model and its optimisation; prints one JSON object.

The vectorised evaluation is compared, in the same run, with a per-geometry Python
loop over the same model (the reference), so the ratio is meaningful on a noisy machine.

    python bench/bench_analytical.py
"""

import json

import numpy as np
from timing import best_time

from workflow.models import analytical, materials
from workflow.models.plate import Plate
from workflow.optimise.problem import DesignProblem, optimise_analytical


def evaluate(plates):
    return analytical.dynamic_deflection(plates, 15.0, 54.0), analytical.resonance_frequency(plates)


def main():
    rng = np.random.default_rng(0)
    n = 1_000_000
    plates = Plate(rng.uniform(15e-3, 40e-3, n), rng.uniform(0.5e-3, 3e-3, n), 1e-3)
    vectorised = best_time(lambda: evaluate(plates), 5)
    n_loop = 2000
    singles = [Plate(float(w), float(h), 1e-3) for w, h in zip(plates.wavelength[:n_loop], plates.resonator_thickness[:n_loop])]
    loop = best_time(lambda: [evaluate(p) for p in singles], 3) / n_loop * n
    problems = [DesignProblem(t) for t in materials.CERAMIC_THICKNESSES]
    optimisation = {
        f"{p.ceramic_thickness * 1e3:g}": best_time(lambda p=p: optimise_analytical(p), 20) for p in problems
    }
    print(
        json.dumps(
            {
                "geometries": n,
                "vectorised_s": vectorised,
                "geometries_per_s": n / vectorised,
                "loop_reference_s_extrapolated": loop,
                "speedup_vs_loop": loop / vectorised,
                "optimisation_s_by_hp_mm": optimisation,
                "optimisation_max_s": max(optimisation.values()),
                "targets": {"geometries_per_s": 1e6, "optimisation_s": 0.05},
            }
        )
    )


if __name__ == "__main__":
    main()
