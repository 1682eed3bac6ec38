"""Synthetic interferometer campaigns with a known Q(v), for tests and benchmarks.

The same physics as the fit's forward model (:mod:`workflow.damping.likelihood`): one
mode, w = g V / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2) solved self-consistently,
velocity 2 pi f w, the resonance drifting between sweeps (a random walk), Gaussian noise
with relative and absolute parts.  Seeded: the same arguments give the same rows.
"""

from typing import Sequence

import numpy as np

from workflow import logformat
from workflow.damping.harmonic import self_consistent_amplitude
from workflow.damping.laws import QuadraticLoss
from workflow.damping.logs import CampaignLog

TRUE_LAW = QuadraticLoss(q0=150.0, alpha=0.234)
"""A glued-plate-like law: Q(0) = 150, Q = 54 near 0.225 m/s."""


def simulate_campaign(
    law=TRUE_LAW,
    gain: float = 1.42e-9,
    resonance_frequency: float = 31.17e3,
    voltages: Sequence[float] = (3.0, 6.0, 9.0, 12.0, 15.0, 18.0),
    points_per_sweep: int = 50,
    half_span: float = 1.0e3,
    drift_per_sweep: float = 15.0,
    relative_noise: float = 0.02,
    absolute_noise: float = 1e-3,
    seed: int = 0,
) -> CampaignLog:
    """Sweeps at several voltages around a drifting resonance.

    Parameters
    ----------
    law : Q(v) law
        The true damping law.
    gain : float
        Quasi-static deflection per volt g [m/V].
    resonance_frequency : float
        Resonance of the first sweep [Hz]; the sweeps are centred on it.
    voltages : sequence of float
        Peak drive voltage of each sweep [V].
    points_per_sweep : int
    half_span : float
        Each sweep covers resonance_frequency +- half_span [Hz].
    drift_per_sweep : float
        Standard deviation of the resonance's random-walk step between sweeps [Hz].
    relative_noise, absolute_noise : float
        Noise standard deviations: relative [-] and absolute [m/s].
    seed : int

    Returns
    -------
    CampaignLog
        With ``sources = ("synthetic",)``.
    """
    rng = np.random.default_rng(seed)
    n = len(voltages)
    resonances = resonance_frequency + np.cumsum(np.r_[0.0, rng.normal(0.0, drift_per_sweep, n - 1)])
    frequency = np.tile(np.linspace(resonance_frequency - half_span, resonance_frequency + half_span, points_per_sweep), n)
    sweep = np.repeat(np.arange(n), points_per_sweep)
    voltage = np.asarray(voltages, dtype=float)[sweep]
    deflection = self_consistent_amplitude(gain * voltage, frequency, resonances[sweep], law.quality_factor)
    velocity = 2 * np.pi * frequency * deflection
    noise = np.sqrt((relative_noise * velocity) ** 2 + absolute_noise**2)
    measured = np.abs(velocity + noise * rng.standard_normal(velocity.shape))
    return CampaignLog(frequency, voltage, measured, sweep, ("synthetic",))


def campaign_csv(log: CampaignLog, title: str = "synthetic Q(v) campaign") -> str:
    """The campaign as log-format text (docs/log-format.md), timestamps one second apart."""
    header = ",".join((logformat.SWEEP, logformat.TIMESTAMP, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.VELOCITY))
    lines = [f"{logformat.METADATA_PREFIX}{title}", f"{logformat.METADATA_PREFIX}format_version: {logformat.FORMAT_VERSION}", header]
    for i, (k, f, v, u) in enumerate(zip(log.sweep, log.frequency, log.drive_voltage, log.velocity)):
        lines.append(f"{k},{float(i):.1f},{f:.3f},{v:.6g},{u:.8g}")
    return "\n".join(lines) + "\n"
