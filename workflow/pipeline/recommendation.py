"""The design to build, per h_p: the report's opening section, as data.

The geometry is the FEM optimum (space mapping, constant Q) where the FEM ran, the beam
optimum with Q(v) otherwise; the numbers at that geometry use the fitted Q(v): the
deflection at the design voltage and the voltage for the target deflection, each as the
5/50/95 % quantiles over posterior draws, the margin to the frequency limit and, with the
FEM, the nearest mode that mixes in a transverse shape.
"""

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np

from workflow.models import analytical
from workflow.models.plate import Plate
from workflow.optimise.damped import (
    QUANTILES,
    damped_deflection,
    required_voltage,
)
from workflow.optimise.maps import TRANSVERSE_THRESHOLD
from workflow.optimise.problem import FREQUENCY_SLACK, DesignProblem
from workflow.pipeline.design_models import DESIGN_MODELS, BeamDesignModel, FemDesignModel



@dataclass(frozen=True)
class RecommendedDesign:
    """The plate to build for one h_p and how it performs with the fitted Q(v).

    Attributes
    ----------
    plate : Plate
        Geometry to build [m].
    model : str
        The name of the design model (:data:`~workflow.pipeline.design_models.DESIGN_MODELS`) behind the numbers:
        "fem" (the FEM optimum by space mapping, numbers from the FEM at that geometry) or "analytical" (the beam
        optimum with Q(v), numbers from the beam model).
    problem : DesignProblem
        Design voltage [V] and frequency limit [Hz].
    target : float
        Deflection to reach [m].
    frequency : float
        Working mode's frequency [Hz].
    deflection : tuple of float
        Deflection at the design voltage with Q(v): 5, 50, 95 % over posterior draws [m].
    required_voltage : tuple of float
        Voltage for ``target`` with Q(v): 5, 50, 95 % over posterior draws [V].
    working_indicator : float or None
        Transverse indicator of the working mode [-] (FEM only).
    nearest_transverse : ModeResult or None
        The other computed mode nearest in frequency whose transverse indicator exceeds
        :data:`TRANSVERSE_THRESHOLD` (None: no such mode, or the beam model).
    computed_modes : int
        Modes the FEM computed at this geometry (0 for the beam model).
    constant_q_ratio : float or None
        FEM optimum's deflection over the beam optimum's, both with constant Q [-].
    beam_required_voltage : float or None
        For a FEM design: the beam model's voltage for ``target`` at its own optimum with Q(v)
        (median over posterior draws) [V].
    frequency_error : float or None
        For a FEM design: estimated relative discretisation error of ``frequency`` [-]
        (``FemResult.error``; None on a fixed mesh, whose error is not estimated).
    antiresonance : float or None
        For the coupled piezoelectric FEM: the working mode's open-circuit frequency f_a [Hz].
    admittance : tuple of arrays or None
        For the coupled piezoelectric FEM: frequencies [Hz] around f_r and f_a and the whole plate's
        electrical admittance there, Y = i omega Q_e / V with the plate's Q [S] (complex).
    """

    plate: Plate
    model: str
    problem: DesignProblem
    target: float
    frequency: float
    deflection: Tuple[float, float, float]
    required_voltage: Tuple[float, float, float]
    working_indicator: Optional[float] = None
    nearest_transverse: Optional[object] = None
    computed_modes: int = 0
    constant_q_ratio: Optional[float] = None
    beam_required_voltage: Optional[float] = None
    frequency_error: Optional[float] = None
    antiresonance: Optional[float] = None
    admittance: Optional[tuple] = None

    @property
    def frequency_margin(self) -> float:
        """Working frequency minus the frequency limit [Hz]."""
        return self.frequency - self.problem.min_frequency

    @property
    def working_velocity(self) -> float:
        """Antinode velocity amplitude at the design voltage with Q(v), v = 2 pi f_r w (median) [m/s]."""
        return 2 * np.pi * self.frequency * self.deflection[1]

    @property
    def transverse_distance(self) -> Optional[float]:
        """Nearest transverse-mixing mode's frequency minus the working one [Hz], or None."""
        return None if self.nearest_transverse is None else self.nearest_transverse.frequency - self.frequency

    @property
    def working_mode_mixed(self) -> bool:
        """Whether the working mode itself has a transverse indicator above the threshold."""
        return self.working_indicator is not None and self.working_indicator > TRANSVERSE_THRESHOLD

    @property
    def reaches_target(self) -> bool:
        """Whether the median voltage for the target deflection is within the design voltage."""
        return self.required_voltage[1] <= self.problem.voltage

    @property
    def above_frequency_limit(self) -> bool:
        """Whether the working frequency is at or above the limit (within :data:`FREQUENCY_SLACK`)."""
        return self.frequency_margin >= -FREQUENCY_SLACK * self.problem.min_frequency

    @property
    def meets_goal(self) -> bool:
        """Target deflection at the design voltage (median) and a working frequency at or above the limit."""
        return self.reaches_target and self.above_frequency_limit


@dataclass(frozen=True)
class Recommendation:
    """The recommended design of every h_p.

    Attributes
    ----------
    designs : dict
        h_p [m] -> :class:`RecommendedDesign`.
    original : RecommendedDesign or None
        The original plate with the FEM, for reference.
    law : str
        The fitted Q(v) law for people (:attr:`~workflow.damping.posterior.DampingPosterior.description`).
    draws : int
        Posterior draws behind the quantiles.
    """

    designs: Dict[float, RecommendedDesign]
    original: Optional[RecommendedDesign]
    law: str
    draws: int

    def margin_within_mesh_error(self, design: RecommendedDesign) -> bool:
        """Whether a FEM design's frequency margin is smaller than its estimated discretisation error
        (or unknown: a FEM design on a fixed mesh)."""
        if not DESIGN_MODELS[design.model].discretised:
            return False
        error = design.frequency_error
        return error is None or design.frequency_margin < abs(error) * design.frequency


def quantiles(values) -> Tuple[float, float, float]:
    """The 5, 50, 95 % quantiles of ``values``."""
    return tuple(float(q) for q in np.quantile(values, QUANTILES))


def nearest_transverse_mode(modes, working):
    """The mode of ``modes`` other than ``working`` nearest to it in frequency whose transverse
    indicator exceeds :data:`TRANSVERSE_THRESHOLD`, or None."""
    mixing = [m for m in modes if m is not working and m.transverse_indicator > TRANSVERSE_THRESHOLD]
    return min(mixing, key=lambda m: abs(m.frequency - working.frequency), default=None)


def fem_recommendation(result, plate: Plate, problem: DesignProblem, draws, target: float,
                       constant_q_ratio: Optional[float] = None,
                       beam_required_voltage: Optional[float] = None) -> RecommendedDesign:
    """The FEM design at ``plate`` with Q(v).

    Parameters
    ----------
    result : workflow.models.fem.FemResult
        The FEM at ``plate`` driven at ``problem.voltage``.
    plate : Plate
    problem : DesignProblem
    draws : Q(v) law
        Posterior draws as one law with (n,) parameters.
    target : float
        Deflection to reach [m].
    constant_q_ratio : float, optional
        FEM over beam optimum deflection with constant Q [-].
    beam_required_voltage : float, optional
        The beam model's voltage for ``target`` at its own optimum with Q(v) [V].
    """
    return RecommendedDesign(
        plate=plate,
        model=FemDesignModel.name,
        problem=problem,
        target=target,
        frequency=result.frequency,
        deflection=quantiles(damped_deflection(result, draws)),
        required_voltage=quantiles(required_voltage(result, draws, target)),
        working_indicator=result.best.transverse_indicator,
        nearest_transverse=nearest_transverse_mode(result.modes, result.best),
        computed_modes=len(result.modes),
        constant_q_ratio=constant_q_ratio,
        beam_required_voltage=beam_required_voltage,
        frequency_error=None if result.error is None else result.error.frequency,
        **_electrical(result),
    )


ADMITTANCE_POINTS = 600
"""Frequencies of an admittance curve [-]."""


def _electrical(result) -> dict:
    """Antiresonance and admittance curve of a coupled FEM result (none for the eigenstrain model).

    The curve spans the working mode's resonance and antiresonance with a margin of 3 % of f_r.
    """
    if getattr(result, "antiresonances", None) is None:
        return {}
    low, high = result.frequency, result.antiresonance
    frequencies = np.linspace(low - 0.03 * low, high + 0.03 * low, ADMITTANCE_POINTS)
    return {"antiresonance": high, "admittance": (frequencies, result.admittance(frequencies))}


def beam_recommendation(plate: Plate, problem: DesignProblem, draws, target: float) -> RecommendedDesign:
    """The beam-model design at ``plate`` with Q(v) (``draws``: posterior draws as one law)."""
    response = analytical.beam_response(plate, problem.voltage)
    return RecommendedDesign(
        plate=plate,
        model=BeamDesignModel.name,
        problem=problem,
        target=target,
        frequency=float(response.frequency),
        deflection=quantiles(damped_deflection(response, draws)),
        required_voltage=quantiles(required_voltage(response, draws, target)),
    )
