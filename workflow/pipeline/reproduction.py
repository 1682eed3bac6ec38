"""The reproduction table: each figure of the source paper (:mod:`workflow.pipeline.paper`) beside ours.

:func:`reproduce` takes the results of ``tactile run`` (its ``RunResults``) and computes our
value for every paper figure it can; figures whose step did not run are left out.  Each row
says what kind of comparison it is: a *validation* (our value is computed without the paper's
figure) or a *consistency check* (our value is set by an input taken from the paper, so
agreement only shows that the chain returns what went in).
"""

from dataclasses import dataclass
from typing import List, Optional

import numpy as np

from workflow.models import analytical, materials
from workflow.models.plate import ORIGINAL_PLATE
from workflow.pipeline.paper import FIGURES, PaperFigure
from workflow.units import KHZ, MM, UM

VALIDATION = "validation"
"""Our value is computed without the paper's figure: agreement tests our models and code."""
CONSISTENCY_CHECK = "consistency check"
"""Our value is set by an input taken from the paper: agreement checks the round trip only."""


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
    kind : str
        :data:`VALIDATION` or :data:`CONSISTENCY_CHECK`.
    """

    paper: PaperFigure
    ours: float
    how: str
    kind: str

    @property
    def difference(self) -> float:
        """ours - paper, in the figure's unit."""
        return self.ours - self.paper.value

    @property
    def relative_difference(self) -> Optional[float]:
        """(ours - paper) / paper [-], or None for a zero paper value."""
        return None if self.paper.value == 0 else self.difference / self.paper.value


def reproduce(
    results, voltage: float = materials.DESIGN_VOLTAGE, simulated_campaign: bool = True
) -> List[Reproduction]:
    """Our value of every paper figure the ``results`` allow, in the order of :data:`FIGURES`.

    Parameters
    ----------
    results : RunResults
        Results of ``tactile run``'s steps.
    voltage : float
        Design voltage [V peak].
    simulated_campaign : bool
        Whether the fitted logs come from the bench simulator, which generates them with the
        paper's Q = 54 at the original working point (the Q(v) rows are then consistency checks).
    """
    campaign = CONSISTENCY_CHECK if simulated_campaign else VALIDATION
    ours = {
        "analytical_w": (
            analytical.dynamic_deflection(ORIGINAL_PLATE, voltage, materials.PLATE_Q) / UM,
            "beam model, original plate, Q = 54; its calibration is fitted to this figure",
            CONSISTENCY_CHECK,
        ),
        "analytical_f": (analytical.resonance_frequency(ORIGINAL_PLATE) / KHZ, "beam model, original plate", VALIDATION),
        "literal_w": (
            analytical.dynamic_deflection(ORIGINAL_PLATE, voltage, materials.PLATE_Q, calibration=1.0) / UM,
            "beam formula without the calibration",
            VALIDATION,
        ),
    }
    if results.damping_fit is not None:
        from workflow.optimise.damped import damped_deflection

        law = results.damping_fit.answer.median_law()
        deflection = float(damped_deflection(analytical.beam_response(ORIGINAL_PLATE, voltage), law))
        velocity = 2 * np.pi * float(analytical.resonance_frequency(ORIGINAL_PLATE)) * deflection
        source = "the simulated campaign (generated with Q = 54 at this point)" if simulated_campaign else "the given logs"
        ours["working_q"] = (
            float(law.quality_factor(velocity)),
            f"Q(v) fitted to {source}, at the original plate's working point",
            campaign,
        )
        ours["working_v"] = (velocity, f"calibrated beam model, 15 V, with the Q(v) fitted to {source}", campaign)
    fem = results.fem_original
    if fem is not None:
        ours["fem_f"] = (fem.frequency / KHZ, "our FEM, default mesh", VALIDATION)
        ours["fem_w"] = (fem.deflection / UM, "our FEM, default mesh", VALIDATION)
    optima = results.fem_optima
    if optima:
        # The paper's counts are for its original ceramic (1 mm); prefer that h_p when it was designed.
        hp = min(optima, key=lambda thickness: abs(thickness - ORIGINAL_PLATE.ceramic_thickness))
        record, label = optima[hp], f"h_p = {hp / MM:g} mm"
        ours["space_mapping_evaluations"] = (record.space_mapping.fine_evaluations, f"space mapping, {label}", VALIDATION)
        if record.direct is not None:
            ours["fem_nlopt_evaluations"] = (record.direct.fine_evaluations, f"direct NLopt, {label}", VALIDATION)
            direct, mapped = record.direct.optimum.plate, record.space_mapping.optimum.plate
            distance = np.hypot(
                direct.wavelength - mapped.wavelength, direct.resonator_thickness - mapped.resonator_thickness
            )
            ours["space_mapping_distance"] = (distance / MM, f"space mapping vs direct NLopt, {label}", VALIDATION)
    return [Reproduction(FIGURES[key], float(ours[key][0]), *ours[key][1:]) for key in FIGURES if key in ours]
