"""Synthetic interferometer campaigns with a known Q(v), for tests and benchmarks.

The same physics as the fit's forward model (:mod:`workflow.damping.likelihood`): one
mode, w = g V / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2) solved self-consistently,
velocity 2 pi f w, the resonance drifting between sweeps (a random walk), Gaussian noise
with relative and absolute parts.  Optionally the resonance softens with amplitude
(f_r0 (1 - kappa v^2), each sweep solved in its measuring order, branch following),
drifts linearly in time within the sweeps, sweeps alternate up and down, and the
vibrometer reads the velocity times |phi| at an off-antinode point.  Seeded: the same
arguments give the same rows.
"""

from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np

from workflow import logformat
from workflow.damping.harmonic import softened_amplitudes
from workflow.damping.laws import QuadraticLoss
from workflow.damping.logs import CampaignLog

TRUE_LAW = QuadraticLoss(q0=150.0, alpha=0.234)
"""A glued-plate-like law: Q(0) = 150, Q = 54 near 0.225 m/s."""


@dataclass(frozen=True)
class PowerTruth:
    """A hidden truth none of the fit's laws contains: 1/Q = 1/Q0 + alpha |v|^p (Q0 [-], alpha [(s/m)^p], p [-])."""

    q0: float
    alpha: float
    p: float
    name: ClassVar[str] = "power"

    def quality_factor(self, velocity):
        return 1.0 / (1.0 / self.q0 + self.alpha * np.abs(velocity) ** self.p)


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
    softening: float = 0.0,
    drift_rate: float = 0.0,
    seconds_per_point: float = 1.0,
    alternate: bool = False,
    mode_factor: float = 1.0,
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
    softening : float
        kappa in f_r(v) = f_r0 (1 - kappa v^2) [s^2/m^2].
    drift_rate : float
        Drift of the resonance in time, within and across sweeps [Hz/s].
    seconds_per_point : float
        Time between rows (the ``timestamp_s`` of row i is i times this) [s].
    alternate : bool
        Odd sweeps run downwards in frequency (rows in measuring order).
    mode_factor : float
        |phi| at the measurement point: the velocity read over the antinode's [-].

    Returns
    -------
    CampaignLog
        With ``sources = ("synthetic",)``.
    """
    rng = np.random.default_rng(seed)
    n = len(voltages)
    resonances = resonance_frequency + np.cumsum(np.r_[0.0, rng.normal(0.0, drift_per_sweep, n - 1)])
    upward = np.linspace(resonance_frequency - half_span, resonance_frequency + half_span, points_per_sweep)
    frequency = np.array([upward[::-1] if alternate and k % 2 else upward for k in range(n)])
    time = seconds_per_point * np.arange(n * points_per_sweep).reshape(n, points_per_sweep)
    static = gain * np.asarray(voltages, dtype=float)[:, None]
    deflection = softened_amplitudes(static, frequency, resonances[:, None] + drift_rate * time, softening,
                                     law.quality_factor)
    velocity = (2 * np.pi * frequency * deflection * mode_factor).ravel()
    noise = np.sqrt((relative_noise * velocity) ** 2 + absolute_noise**2)
    measured = np.abs(velocity + noise * rng.standard_normal(velocity.shape))
    sweep = np.repeat(np.arange(n), points_per_sweep)
    return CampaignLog(frequency.ravel(), np.asarray(voltages, dtype=float)[sweep], measured, sweep, ("synthetic",),
                       timestamp=time.ravel(), mode_factor=None if mode_factor == 1.0 else np.full(sweep.size, mode_factor))


def campaign_csv(log: CampaignLog, title: str = "synthetic Q(v) campaign") -> str:
    """The campaign as log-format text (docs/log-format.md), timestamps one second apart."""
    columns = (logformat.SWEEP, logformat.TIMESTAMP, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.VELOCITY)
    times = np.arange(len(log.velocity), dtype=float) if log.timestamp is None else log.timestamp
    rows = ((f"{k}", f"{t:.1f}", f"{f:.3f}", f"{v:.6g}", f"{u:.8g}")
            for k, t, f, v, u in zip(log.sweep, times, log.frequency, log.drive_voltage, log.velocity))
    return logformat.head_text(title, {"format_version": logformat.FORMAT_VERSION}, columns) + logformat.rows_text(rows)
