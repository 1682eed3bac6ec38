"""The reproduction table: each figure quoted from the source paper beside ours.

:func:`reproduce` takes the results of ``tactile run`` (keyed by step) and computes our
value for every paper figure it can; figures whose step did not run are left out.
"""

from dataclasses import dataclass
from typing import Dict, List, Optional

import numpy as np

from workflow.models import analytical, materials
from workflow.models.plate import ORIGINAL_PLATE
from workflow.pipeline.paper import FIGURES, PaperFigure
from workflow.units import KHZ, MM, UM


@dataclass(frozen=True)
class Reproduction:
    """A paper figure and ours.

    Attributes
    ----------
    paper : PaperFigure
    ours : float
        Our value in the paper figure's unit.
    how : str
        What produced our value.
    """

    paper: PaperFigure
    ours: float
    how: str

    @property
    def difference(self) -> float:
        """ours - paper, in the figure's unit."""
        return self.ours - self.paper.value

    @property
    def relative_difference(self) -> Optional[float]:
        """(ours - paper) / paper [-], or None for a zero paper value."""
        return None if self.paper.value == 0 else self.difference / self.paper.value


def reproduce(results: Dict[str, object], voltage: float = materials.DESIGN_VOLTAGE) -> List[Reproduction]:
    """Our value of every paper figure the ``results`` allow, in the order of :data:`FIGURES`."""
    ours = {
        "analytical_w": (
            analytical.dynamic_deflection(ORIGINAL_PLATE, voltage, materials.PLATE_Q) / UM,
            "beam model, original plate, Q = 54",
        ),
        "analytical_f": (analytical.resonance_frequency(ORIGINAL_PLATE) / KHZ, "beam model, original plate"),
        "literal_w": (
            analytical.dynamic_deflection(ORIGINAL_PLATE, voltage, materials.PLATE_Q, calibration=1.0) / UM,
            "beam formula without the calibration",
        ),
    }
    if "damping_fit" in results:
        from workflow.optimise.damped import damped_deflection

        law = results["damping_fit"].best.posterior().median_law()
        deflection = float(damped_deflection(ORIGINAL_PLATE, voltage, law))
        velocity = 2 * np.pi * float(analytical.resonance_frequency(ORIGINAL_PLATE)) * deflection
        ours["working_q"] = (float(law.quality_factor(velocity)), "fitted Q(v) at the original plate's working point")
        ours["working_v"] = (velocity, "beam model with the fitted Q(v), 15 V")
    fem = results.get("fem_original")
    if fem is not None:
        ours["fem_f"] = (fem.frequency / KHZ, "our FEM, default mesh")
        ours["fem_w"] = (fem.deflection / UM, "our FEM, default mesh")
    optima = results.get("fem_optima")
    if optima is not None:
        # The paper's counts are for its original ceramic (1 mm); prefer that h_p when it was designed.
        hp = min(optima, key=lambda thickness: abs(thickness - ORIGINAL_PLATE.ceramic_thickness))
        record, label = optima[hp], f"h_p = {hp / MM:g} mm"
        ours["space_mapping_evaluations"] = (record.space_mapping.fine_evaluations, f"space mapping, {label}")
        if record.direct is not None:
            ours["fem_nlopt_evaluations"] = (record.direct.fine_evaluations, f"direct NLopt, {label}")
            direct, mapped = record.direct.optimum.plate, record.space_mapping.optimum.plate
            distance = np.hypot(
                direct.wavelength - mapped.wavelength, direct.resonator_thickness - mapped.resonator_thickness
            )
            ours["space_mapping_distance"] = (distance / MM, f"space mapping vs direct NLopt, {label}")
    return [Reproduction(FIGURES[key], float(value), how) for key in FIGURES if key in ours for value, how in [ours[key]]]
