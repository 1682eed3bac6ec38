"""JSON records of the command-line contract: the design commands' typed results serialised, units applied here
(SI inside; mm, um, kHz, V in the keys, docs/cli.md).

One place for the keys that several commands print: the geometry, an evaluation, an optimum, the FEM's accuracy and
electrical keys, and the keys added when a posterior Q(v) is used (``--damping``).  Nothing here computes physics.
"""

from workflow.damping.laws import law_parameters
from workflow.models.plate import Plate
from workflow.optimise.damped import QOfV
from workflow.optimise.maps import WidthSweep
from workflow.optimise.problem import DesignProblem, Optimum
from workflow.pipeline.design_models import DesignOptimum, Evaluation
from workflow.units import KHZ, MM, UM


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


def point_record(optimum: Optimum) -> dict:
    """The optimum marked on a map: lambda and h_i [mm], deflection [um], resonance [kHz]."""
    return {
        "lambda_mm": float(optimum.plate.wavelength) / MM,
        "h_i_mm": float(optimum.plate.resonator_thickness) / MM,
        "w_dyn_um": optimum.deflection / UM,
        "f_r_khz": optimum.frequency / KHZ,
    }


def grid_record(model: str, problem: DesignProblem, grids) -> dict:
    """The keys of a map (docs/cli.md): the model, h_p and b [mm], the axes [mm] and the grids of w_dyn [um] and f_r
    [kHz] indexed [lambda, h_i]; ``grids`` a :class:`~workflow.optimise.maps.DesignMap` or
    :class:`~workflow.optimise.damped.DampedMaps`."""
    return {
        "model": model,
        "h_p_mm": round(problem.ceramic_thickness / MM, 9),  # as given: no rounding noise of the mm -> m -> mm trip
        "b_mm": round(problem.width / MM, 9),
        "lambda_mm": (grids.wavelength / MM).tolist(),
        "h_i_mm": (grids.resonator_thickness / MM).tolist(),
        "w_dyn_um": (grids.deflection / UM).tolist(),
        "f_r_khz": (grids.frequency / KHZ).tolist(),
    }


def width_sweep_record(sweep: WidthSweep) -> dict:
    """A width sweep's keys: b [mm], w_dyn [um], f_r [kHz] and whether the working mode is transverse-mixed."""
    return {
        "b_mm": (sweep.width / MM).tolist(),
        "w_dyn_um": (sweep.deflection / UM).tolist(),
        "f_r_khz": (sweep.frequency / KHZ).tolist(),
        "transverse": sweep.transverse.tolist(),
    }


def fem_accuracy_record(error) -> dict:
    """The FEM accuracy keys: the relative error estimates of f_r and w_dyn (v_mesh / v_converged - 1),
    the accuracy asked for, whether it was met, and the mesh level (its elements' polynomial degree)."""
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


def q_of_v_record(values: QOfV) -> dict:
    """The ``--damping`` keys: the deflection [um] with the posterior-median law and its 90 % interval over posterior
    draws, the Q it settles at, the voltage for the target deflection (90 % interval), and the law used: ``law`` and
    ``median`` the posterior's median law (for a mixture of laws, ``posterior_law`` "stacking", its most frequent
    law's), which gives ``q``."""
    v05, v50, v95 = values.required_voltage
    return {
        "w_dyn_um": values.deflection / UM,
        "w_dyn_um_p05": values.deflection_interval[0] / UM,
        "w_dyn_um_p95": values.deflection_interval[1] / UM,
        "q": values.quality_factor,
        "required_voltage_v": {"target_um": values.target / UM, "p05": v05, "p50": v50, "p95": v95},
        "damping": {"law": values.law.name, "median": law_parameters(values.law), "posterior": values.posterior.source,
                    "posterior_law": values.posterior.law_name},
    }


def evaluation_record(evaluation: Evaluation) -> dict:
    """``tactile evaluate``'s keys: the model, geometry, Q, voltage, deflection and resonance; the FEM's accuracy,
    electrical keys and modes; the Q(v) keys."""
    record = {"model": evaluation.model, **geometry_record(evaluation.plate), "q": evaluation.q,
              "voltage_v": evaluation.voltage, "w_dyn_um": evaluation.deflection / UM,
              "f_r_khz": evaluation.frequency / KHZ}
    result = evaluation.fem
    if result is not None:
        record.update(fem_accuracy_record(result.error), **fem_coupled_record(result), modes=[
            {"f_khz": m.frequency / KHZ, "w_um": m.deflection / UM, "transverse": m.transverse_indicator}
            for m in result.modes])
    if evaluation.q_of_v is not None:
        record.update(q_of_v_record(evaluation.q_of_v))
    return record


def design_optimum_record(found: DesignOptimum) -> dict:
    """``tactile optimize``'s keys of one optimum: geometry, deflection, resonance, the evaluation counts, the FEM's
    accurate check and the Q(v) keys."""
    search = found.fem_search
    counts = {"coarse_evaluations": found.coarse_evaluations}
    if search is not None:
        counts = {"method": search.method, "fine_evaluations": search.fine_evaluations, **counts}
        if search.error is not None:
            counts.update(fem_accuracy_record(search.error), verified=search.verified,
                          verification_evaluations=search.verification_evaluations)
    record = optimum_record(found.optimum, **counts)
    if found.q_of_v is not None:
        record.update(q_of_v_record(found.q_of_v))
    return record
