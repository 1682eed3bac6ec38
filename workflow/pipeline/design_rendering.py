"""The design note's rendering section: what each recommended design renders, and what it asks of the amplifier."""

from dataclasses import dataclass

import numpy as np

from workflow.damping.envelope import EnvelopeModel
from workflow.rendering.synthesis import search_periods, tuned_carrier

DESIGN_NOTE_SPEEDS = (0.05, 0.1, 0.2)
"""Finger speeds of the design note's renderable grating periods [m/s]."""


def design_envelope(design, law, softening: float) -> EnvelopeModel:
    """The envelope model of a recommended design: its working frequency, the gain its median deflection at the
    design voltage implies with Q(v) at that amplitude (w = Q(v) g V), ``law`` and ``softening``."""
    deflection, frequency = design.deflection[1], design.frequency
    q = float(law.quality_factor(2 * np.pi * frequency * deflection))
    return EnvelopeModel(frequency, deflection / (q * design.problem.voltage), law, softening)


@dataclass(frozen=True)
class ElectricalLoad:
    """The amplifier's load of a design at its working amplitude (SI).

    Attributes
    ----------
    frequency : float
        The coupled model's resonance [Hz].
    q : float
        Q(v) at the working amplitude [-].
    voltage : float
        Drive amplitude for the working deflection [V peak].
    admittance : float
        |Y| at the resonance with that Q [S].
    current : float
        |Y| V, the current amplitude [A].
    power : float
        Re(Y) V^2 / 2, the real power [W].
    apparent_power : float
        |Y| V^2 / 2 [VA].
    peak_current : float
        Bound on the current of a pre-compensated rise to the voltage limit [A].
    voltage_limit : float
        [V peak]
    """

    frequency: float
    q: float
    voltage: float
    admittance: float
    current: float
    power: float
    apparent_power: float
    peak_current: float
    voltage_limit: float


def electrical_load(result, law, deflection: float, voltage: float, voltage_limit: float) -> ElectricalLoad:
    """The amplifier's load at the working amplitude, from the coupled FEM's admittance with Q(v) there.

    At the working deflection ``deflection`` [m] (reached with ``voltage`` [V peak]) the plate's
    Q is Q(v), v = 2 pi f_r w; the admittance at the coupled model's resonance f_r with that Q,
    Y = G + iB, gives the current amplitude |Y| V, the real power G V^2 / 2 and the apparent
    power |Y| V^2 / 2.  A pre-compensated drive reaches ``voltage_limit`` during a rise while the
    motional current stays that of the working amplitude at most: its peak current is at most
    |Y_C| V_limit + |Y - Y_C| V, Y_C = i omega (C_S + residual) the blocked (clamped) part.
    """
    frequency = float(result.frequency)
    q = float(law.quality_factor(2 * np.pi * frequency * deflection))
    admittance = complex(result.admittance(frequency, q))
    blocked = 2j * np.pi * frequency * (result.clamped_capacitance + result.charge_residual)
    return ElectricalLoad(
        frequency=frequency,
        q=q,
        voltage=voltage,
        admittance=abs(admittance),
        current=abs(admittance) * voltage,
        power=admittance.real * voltage**2 / 2,
        apparent_power=abs(admittance) * voltage**2 / 2,
        peak_current=abs(blocked) * voltage_limit + abs(admittance - blocked) * voltage,
        voltage_limit=voltage_limit,
    )


@dataclass(frozen=True)
class DesignRendering:
    """What a recommended design renders and what it draws: the error of gratings against their period, and the
    amplifier's load.

    Attributes
    ----------
    model : EnvelopeModel
        Carrier tuned to the high level.
    levels : tuple
        The gratings' (low, high) deflection amplitudes [m].
    voltage_limit : float
        [V peak across the ceramics]
    search : PeriodSearch
    electrical : ElectricalLoad
        :func:`electrical_load` at the target deflection.
    """

    model: EnvelopeModel
    levels: tuple
    voltage_limit: float
    search: object
    electrical: ElectricalLoad

    def periods(self, target: float, speeds=DESIGN_NOTE_SPEEDS) -> dict:
        """Speed [m/s] -> {"precompensated": (period [m], how), "plain": (period, how)}."""
        return {speed: {name: self.search.smallest_period(speed, target, plain) for name, plain in
                        (("precompensated", False), ("plain", True))} for speed in speeds}

    def time_constants(self) -> tuple:
        """Envelope time constants at the low and high level [s]."""
        to_velocity = 2 * np.pi * float(self.model.carrier)
        return tuple(float(self.model.time_constant(to_velocity * level)) for level in self.levels)


def design_rendering(design, law, softening: float, voltage_limit: float, coupled_result, levels: tuple) -> DesignRendering:
    """:class:`DesignRendering` of a recommended design: gratings between ``levels`` (low, high) [m], 50 % duty,
    within ``voltage_limit`` [V]; the electrical load from ``coupled_result`` (the coupled FEM at its geometry)
    at the design's target deflection and the voltage it needs."""
    model = design_envelope(design, law, softening)
    model = model.with_carrier(tuned_carrier(model, levels[1]))
    search = search_periods(model, *levels, voltage_limit)
    electrical = electrical_load(coupled_result, law, design.target, design.required_voltage[1], voltage_limit)
    return DesignRendering(model, levels, voltage_limit, search, electrical)
