"""Responses around the working mode: the frequency response and the switch-on transient.

Both reuse the modal data of a :class:`FemResult` (no new solve).  In time, structural
damping has no exact equivalent; the working mode is given the viscous damping ratio
zeta = 1/(2Q), which has the same loss at resonance, so its envelope rises with the time
constant tau = 1/(zeta omega_r) = Q/(pi f_r).
"""

from dataclasses import dataclass

import numpy as np

from workflow.models.fem.result import FemResult
from workflow.models.fem.probes import mean_deflection


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """Mean |w| over the 44 probes against drive frequency.

    Attributes
    ----------
    frequency : array
        Drive frequency [Hz].
    deflection : array
        Mean |w| over the probes [m].
    mode_frequencies : array
        Eigenfrequencies of the evaluated modes [Hz].
    working_frequency : float
        Frequency of the best mode [Hz].
    q : float
        Quality factor [-].
    """

    frequency: np.ndarray
    deflection: np.ndarray
    mode_frequencies: np.ndarray
    working_frequency: float
    q: float


def frequency_response(result: FemResult, q: float, frequencies=None, half_span: float = 0.05, n_points: int = 801):
    """|w|(f) around the working mode, from the stored modal data.

    Parameters
    ----------
    result : FemResult
    q : float
        Quality factor [-].
    frequencies : array, optional
        Drive frequencies [Hz]; default ``n_points`` over f_r (1 +- ``half_span``).
    """
    if frequencies is None:
        frequencies = result.frequency * np.linspace(1 - half_span, 1 + half_span, n_points)
    frequencies = np.asarray(frequencies, dtype=float)
    deflection = mean_deflection(result.probe_model.response(frequencies, q))
    mode_frequencies = np.array([mode.frequency for mode in result.modes])
    return FrequencyResponse(frequencies, deflection, mode_frequencies, result.frequency, float(q))


@dataclass(frozen=True, eq=False)
class TransientResponse:
    """Working-mode deflection after a sine at f_r is switched on at t = 0.

    Attributes
    ----------
    time : array
        [s].
    deflection : array
        Mean-probe deflection signal w(t) [m] (steady amplitude = ``steady_amplitude``).
    envelope : array
        Instantaneous amplitude sqrt(w^2 + (dw/dt / omega)^2) [m].
    steady_amplitude : float
        Steady-state amplitude: the FEM deflection at resonance [m].
    time_constant : float
        Rise time constant fitted to the envelope, A(t) = A_ss (1 - exp(-t/tau)) [s].
    expected_time_constant : float
        Q / (pi f_r) [s].
    frequency : float
        Drive and modal frequency [Hz].
    """

    time: np.ndarray
    deflection: np.ndarray
    envelope: np.ndarray
    steady_amplitude: float
    time_constant: float
    expected_time_constant: float
    frequency: float


def switch_on_response(time, natural_frequency, drive_frequency, q):
    """Unit-steady-amplitude response of x'' + 2 zeta w_n x' + w_n^2 x ~ sin(w t), x(0) = x'(0) = 0.

    Parameters
    ----------
    time : array
        [s].
    natural_frequency, drive_frequency : float
        f_n and f of the drive [Hz].
    q : float
        Quality factor, zeta = 1/(2Q) [-].

    Returns
    -------
    displacement, velocity : arrays
        x(t) [-] and dx/dt [1/s], scaled so the steady amplitude is 1.
    """
    omega_n, omega = 2 * np.pi * natural_frequency, 2 * np.pi * drive_frequency
    zeta = 1 / (2 * q)
    omega_d = omega_n * np.sqrt(1 - zeta**2)
    receptance = 1 / (omega_n**2 - omega**2 + 2j * zeta * omega_n * omega)
    steady = receptance / abs(receptance)
    c = -steady.imag
    d = (-omega * steady.real + zeta * omega_n * c) / omega_d
    decay = np.exp(-zeta * omega_n * time)
    phase = np.exp(1j * omega * time)
    displacement = (steady * phase).imag + decay * (c * np.cos(omega_d * time) + d * np.sin(omega_d * time))
    velocity = (1j * omega * steady * phase).imag + decay * (
        (-zeta * omega_n * c + omega_d * d) * np.cos(omega_d * time) + (-zeta * omega_n * d - omega_d * c) * np.sin(omega_d * time)
    )
    return displacement, velocity


def rise_time_constant(time, envelope, steady_amplitude) -> float:
    """tau from a least-squares fit of log(1 - A/A_ss) = -t/tau where 0.05 < A/A_ss < 0.95 [s]."""
    remaining = 1 - envelope / steady_amplitude
    fit = (remaining > 0.05) & (remaining < 0.95)
    slope = np.sum(time[fit] * np.log(remaining[fit])) / np.sum(time[fit] ** 2)
    return -1 / slope


def transient_response(result: FemResult, q: float, n_time_constants: float = 6.0, points_per_period: int = 40):
    """Switch-on transient of the working mode driven at its frequency (modal superposition in time).

    Parameters
    ----------
    result : FemResult
    q : float
        Quality factor [-].
    n_time_constants : float
        Duration in units of Q/(pi f_r) [-].
    points_per_period : int
        Time samples per period [-].
    """
    frequency = result.frequency
    expected = q / (np.pi * frequency)
    duration = n_time_constants * expected
    time = np.linspace(0.0, duration, int(duration * frequency * points_per_period) + 1)
    displacement, velocity = switch_on_response(time, frequency, frequency, q)
    steady = float(result.deflection_at_q(q))
    envelope = steady * np.hypot(displacement, velocity / (2 * np.pi * frequency))
    return TransientResponse(
        time=time,
        deflection=steady * displacement,
        envelope=envelope,
        steady_amplitude=steady,
        time_constant=float(rise_time_constant(time, envelope, steady)),
        expected_time_constant=float(expected),
        frequency=float(frequency),
    )
