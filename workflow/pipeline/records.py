"""JSON records of the command-line contract (SI inside, mm, um, kHz in the keys).

One place for the keys that several commands print: the geometry, an optimum, and the
damping keys added when a posterior Q(v) is used (``--damping``).
"""

import numpy as np

from workflow.damping.laws import law_parameters
from workflow.models.materials import TARGET_DEFLECTION
from workflow.models.plate import Plate
from workflow.models.response import PlateResponse
from workflow.optimise.damped import (
    QUANTILES,
    damped_deflection,
    required_voltage,
)
from workflow.optimise.problem import Optimum
from workflow.units import KHZ, MM, UM

POSTERIOR_DRAWS = 200
"""Posterior draws behind the intervals of a single evaluation or optimum."""


def geometry_record(plate: Plate) -> dict:
    """The geometry keys of the JSON contract, in mm."""
    return {
        "lambda_mm": float(plate.wavelength) / MM,
        "h_i_mm": float(plate.resonator_thickness) / MM,
        "h_p_mm": float(plate.ceramic_thickness) / MM,
        "b_mm": float(plate.width) / MM,
    }


def optimum_record(optimum: Optimum, **counts) -> dict:
    """The JSON keys of one optimum, with evaluation counts or other extra keys."""
    return {
        **geometry_record(optimum.plate),
        "w_dyn_um": optimum.deflection / UM,
        "f_r_khz": optimum.frequency / KHZ,
        "constraint_active": optimum.constraint_active,
        "status": optimum.status,
        **counts,
    }


def fem_accuracy_record(error) -> dict:
    """The FEM accuracy keys: the relative error estimates of f_r and w_dyn (v_mesh / v_converged - 1),
    the accuracy asked for, whether it was met, and the mesh level (elements per ceramic)."""
    if error is None:
        return {}
    return {
        "f_error_estimate": error.frequency,
        "w_error_estimate": error.deflection,
        "accuracy": error.target,
        "accuracy_met": error.met,
        "mesh_level": error.level,
    }


def fem_coupled_record(result) -> dict:
    """The coupled piezoelectric model's keys: antiresonance [kHz] and effective coupling of the working
    mode, and the clamped capacitance of the whole plate [nF]; empty for the eigenstrain model."""
    if result.antiresonances is None:
        return {}
    return {
        "f_a_khz": result.antiresonance / KHZ,
        "k_eff": result.coupling_factor,
        "clamped_capacitance_nf": result.clamped_capacitance * 1e9,
    }


def damping_record(posterior, response: PlateResponse, draws: int = POSTERIOR_DRAWS) -> dict:
    """JSON keys of a plate with Q(v), from any model's working mode at its drive voltage: the deflection [um]
    with the posterior-median law and its 90 % interval over posterior draws, the Q it settles at, the voltage for the
    target deflection (median law and 90 % interval), and the law used: ``law`` and ``median`` the posterior's median
    law (for a mixture of laws, ``posterior_law`` "stacking", its most frequent law's), which gives ``q``."""
    law, drawn = posterior.median_law(), posterior.draws(draws)
    deflection = float(damped_deflection(response, law))
    w05, _, w95 = np.quantile(damped_deflection(response, drawn), QUANTILES)
    v05, v50, v95 = np.quantile(required_voltage(response, drawn), QUANTILES)
    return {
        "w_dyn_um": deflection / UM,
        "w_dyn_um_p05": w05 / UM,
        "w_dyn_um_p95": w95 / UM,
        "q": float(law.quality_factor(2 * np.pi * float(response.frequency) * deflection)),
        "required_voltage_v": {"target_um": TARGET_DEFLECTION / UM, "p05": v05, "p50": v50, "p95": v95},
        "damping": {"law": law.name, "median": law_parameters(law), "posterior": posterior.source,
                    "posterior_law": posterior.law_name},
    }
