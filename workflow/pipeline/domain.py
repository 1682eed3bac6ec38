"""The run configuration's sections as domain objects: the plate, the design problems, the simulated bench,
the built plate's deviations, the FEM settings and the run's FEM model.

The steps of ``tactile run`` (:mod:`workflow.pipeline.steps`) and its loop (:mod:`workflow.pipeline.loop`) read
their settings through these functions, so each configuration key is turned into a domain value in one place.
"""

from typing import Dict, Optional

from workflow.errors import TactileError
from workflow.optimise.problem import DesignProblem
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM, UM


def build_plate(config: dict):
    """The original plate made of the [design] section's ceramic, resonator and bond."""
    from workflow.models import materials
    from workflow.models.plate import ORIGINAL_PLATE

    design = config["design"]
    try:
        return ORIGINAL_PLATE.with_(
            ceramic=materials.ceramic(design["ceramic"]),
            resonator=materials.resonator(design["resonator"]),
            glue_thickness=design["glue_um"] * UM,
        )
    except TactileError as error:
        raise TactileError(f"configuration [design]: {error}") from None


def design_problems(config: dict, thicknesses_mm=None) -> Dict[float, DesignProblem]:
    """One :class:`DesignProblem` per h_p (default: those of the [design] section), keyed by h_p [m]."""
    design = config["design"]
    thicknesses_mm = design["ceramic_thicknesses_mm"] if thicknesses_mm is None else thicknesses_mm
    return {
        thickness * MM: DesignProblem(
            ceramic_thickness=thickness * MM,
            width=design["width_mm"] * MM,
            voltage=design["voltage_v"],
            min_frequency=design["min_frequency_khz"] * KHZ,
            min_resonator_thickness=design["hi_min_mm"] * MM,
            max_resonator_thickness=design["hi_max_mm"] * MM,
            wavelength_range=(design["wavelength_min_mm"] * MM, design["wavelength_max_mm"] * MM),
            build=build_plate(config),
        )
        for thickness in thicknesses_mm
    }


def bench_settings(config: dict):
    """The simulated bench of the [simulator] section (original plate)."""
    from instruments.simulator.bench import default_bench_settings
    from instruments.simulator.physics import default_law

    simulator = config["simulator"]
    law = default_law(low_velocity_q=simulator["low_velocity_q"], working_q=simulator["working_q"])
    return default_bench_settings(
        law=law,
        drift_rate=simulator["drift_hz_per_s"],
        softening=simulator["softening_s2_m2"],
        amplifier_gain=simulator["amplifier_gain"],
        ceramic_voltage_limit=simulator["ceramic_voltage_limit_v"],
        relative_noise=simulator["relative_noise"],
        floor_fraction=simulator["floor_fraction"],
        phase_noise=simulator["phase_noise_deg"],
        seed=config["campaign"]["seed"],
    )


def built_plate_deviations(config: dict):
    """The hidden deviations of the simulated built plate: the ``built_*`` keys of the [simulator] section."""
    from workflow.models.builtplate import SIMULATED_DEVIATIONS, deviations_from_settings

    simulator = config["simulator"]
    return deviations_from_settings({s.name: simulator[s.config_key] for s in SIMULATED_DEVIATIONS})


def fem_settings(config: dict, key: str = "accuracy"):
    """The FEM settings of the [fem] section: the accuracy ``key`` (``accuracy`` for designs,
    ``survey_accuracy`` for maps and the width sweep), or the fixed mesh of the mesh keys when it is 0."""
    from workflow.models.fem import FemSettings
    from workflow.models.fem.accuracy import FemAccuracy

    names = FemSettings().as_dict()
    mesh = FemSettings(**{name: config["fem"][name] for name in names})
    target = config["fem"][key]
    return FemAccuracy(target=target, n_modes=mesh.n_modes, piezo=mesh.piezo) if target > 0 else mesh


def fem_model(context: RunContext, q: Optional[float] = None, accuracy: str = "accuracy", settings=None):
    """The cached, parallel FEM plate model of the run at its Q (or ``q``) and voltage.

    ``accuracy``: the [fem] key of its target; ``settings``: an accuracy or mesh instead of the [fem] section's
    (a calibration's, the coupled model's).
    """
    from workflow.optimise.fem_model import FemModel

    design = context.config["design"]
    return FemModel(
        q=design["q"] if q is None else q,
        voltage=design["voltage_v"],
        settings=fem_settings(context.config, accuracy) if settings is None else settings,
        cache=context.cache,
        scheduler=context.scheduler,
        progress=True,
    )
