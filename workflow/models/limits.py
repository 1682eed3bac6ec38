"""The plausible range of every quantity tactile reads: one table for the command line, the configuration
reader, the log reader and the calibration reader (docs/safety.md, "What inputs are accepted").

:data:`LIMITS` holds two kinds of keys, each in the unit its name ends with:

* physical quantities, named as the log format names them (``lambda_mm``, ``frequency_hz``, ...): what
  a plate, a log or a calibration may hold, wide enough for any tactile plate and narrow enough to
  refuse a unit slip (a frequency in kHz, a thickness in m) and absurd values (a 1 nm resonator, a
  kilometre of glue, a negative modulus);
* configuration keys ``section.key`` of ``tactile run --config``, which the command-line options of
  the same quantity share; those of a physical quantity take its range from the first kind.

A position is plausible on the plate it is measured on: :func:`point_problem`.
"""

import math

from workflow.models import materials
from workflow.models.plate import Plate
from workflow.units import MM, UM


def mm_range(bounds) -> tuple:
    """A range in metres as millimetres, rounded as the configuration writes them."""
    return tuple(round(x / MM, 9) for x in bounds)


LIMITS = {
    # physical quantities (log columns and metadata, built-plate options, calibration records)
    "lambda_mm": (5.0, 200.0),
    "h_i_mm": (0.05, 20.0),
    "h_p_mm": (0.05, 10.0),
    "b_mm": (5.0, 500.0),
    "glue_um": (0.0, 500.0),
    "modulus_factor": (0.5, 1.5),
    "hi_offset_um": (-1000.0, 1000.0),
    "ceramic_offset_mm": (-10.0, 10.0),
    "glue_modulus_factor": (0.01, 1.5),
    "glue_thickness_factor": (0.1, 10.0),
    "width_offset_mm": (-10.0, 10.0),
    "ceramic_length_offset_mm": (-5.0, 5.0),
    "frequency_hz": (100.0, 10e6),
    "drive_voltage_v": (0.0, 1000.0),
    "velocity_m_s": (0.0, 10.0),
    "decay_time_s": (0.0, 1000.0),
    "temperature_c": (-50.0, 150.0),
    "q": (1.0, 1e5),
    "amplifier_gain": (0.1, 1000.0),
    "softening_s2_m2": (0.0, 100.0),
    "fem_accuracy": (1e-4, 0.05),
    # configuration keys
    "campaign.ringdown_samples": (2, 256),
    "campaign.ringdown_interval_us": (1, 1_000_000),
    "design.voltage_v": (1e-3, 1000.0),
    "design.wavelength_min_mm": mm_range(materials.WAVELENGTH_RANGE),
    "design.wavelength_max_mm": mm_range(materials.WAVELENGTH_RANGE),
    "design.hi_min_mm": mm_range(materials.RESONATOR_THICKNESS_RANGE),
    "design.hi_max_mm": mm_range(materials.RESONATOR_THICKNESS_RANGE),
    "design.width_mm": mm_range(materials.WIDTH_RANGE),
    "design.min_frequency_khz": (1.0, 1000.0),
    "design.target_deflection_um": (1e-3, 1000.0),
    "campaign.voltages_v": (1e-3, 1000.0),
    "campaign.ringdown_voltages_v": (1e-3, 1000.0),
    "campaign.span_hz": (1e-3, 1e6),
    "simulator.relative_noise": (0.0, 1.0),
    "simulator.floor_fraction": (0.0, 1.0),
    "simulator.phase_noise_deg": (0.0, 180.0),
    "simulator.drift_hz_per_s": (-1000.0, 1000.0),
    "simulator.ceramic_voltage_limit_v": (1e-3, 1000.0),
    "fem.width_min_mm": mm_range(materials.WIDTH_RANGE),
    "fem.width_max_mm": mm_range(materials.WIDTH_RANGE),
    "fem.fine_width_min_mm": mm_range(materials.WIDTH_RANGE),
    "fem.fine_width_max_mm": mm_range(materials.WIDTH_RANGE),
    "fem.fine_width_step_mm": (0.01, 70.0),
    "fem.accuracy": (0.0, 0.05),
    "fem.survey_accuracy": (0.0, 0.05),
    "maps.grid": (2, 400),
    "maps.fem_grid": (2, 400),
    "campaign.seed": (0, 2**32 - 1),
    "damping.seed": (0, 2**32 - 1),
    "damping.max_steps": (1, 1_000_000),
    "damping.walkers": (0, 10_000),
    "damping.posterior_draws": (1, 10_000),
    "fem.width_points": (2, 1000),
    "loop.scan_grid": (1, 100),
    "reliability": (0.5, 0.999),
    "loop.stock_hi_mm": mm_range(materials.RESONATOR_THICKNESS_RANGE),
    "loop.search_start_khz": (1.0, 39.0),
    "recommendation.stock_hi_mm": mm_range(materials.RESONATOR_THICKNESS_RANGE),
    "recommendation.stocks_per_design": (1, 9),
}
for _key, _quantity in (
    ("design.q", "q"), ("design.glue_um", "glue_um"), ("simulator.low_velocity_q", "q"), ("simulator.working_q", "q"),
    ("simulator.amplifier_gain", "amplifier_gain"), ("simulator.softening_s2_m2", "softening_s2_m2"),
    ("loop.reliability", "reliability"), ("recommendation.reliability", "reliability"),
):
    LIMITS[_key] = LIMITS[_quantity]
"""Accepted range [low, high] of each quantity, in the unit its name ends with.

Physical quantities: wavelength, resonator and ceramic thickness, width [mm] (any plate a lab builds;
the design space of Table 1 is narrower, :func:`~workflow.models.plate.check_design_space`), bond
[um], modulus factors [-] (ceramic c^E, resonator and bond E over their records'), resonator thickness
offset [um] and ceramic offset along x [mm] of a built plate, and the simulator's deviations beyond the
calibration's parameters: the modulus of a bond only partly cured over its record's [-], the bond's local thickness
over its mean [-], the width's and the ceramics' length error [mm], drive and resonance frequency [Hz] (a
tactile plate works at tens of kHz; a value in kHz is refused), peak voltage across the ceramics [V],
peak velocity [m/s] (above any vibrometer decoder's range), ring-down decay time [s] (the longest
record), plate temperature [deg C], quality factor [-], amplifier gain [V/V], amplitude softening
[s^2/m^2], FEM accuracy target (relative frequency error [-]).


Configuration keys: the ring-down record (samples, interval: the vibrometer's record, its reply line
under the 4 kB output buffer), the design box of Table 1 [mm], frequency [kHz], deflection [um], the
campaign's drive [V] and span [Hz], the simulated bench, the FEM sweeps (the mesh counts are
checked by :class:`~workflow.models.fem.FemSettings`, and every mesh's memory by
:data:`~workflow.models.fem.mesh.MEMORY_BUDGET`), map points per axis, random seeds, chain
length (a million steps is about an hour per law), emcee walkers (0: max(32, 2 D + 2) for each law's D
parameters; otherwise at least twice the parameters sampled: checked when the logs are read,
:func:`~workflow.damping.fit.minimum_walkers`), posterior draws, the loop's scan and robust design.
Every other number must be finite."""


_UNITS = (("_m_s", "m/s"), ("_s2_m2", "s^2/m^2"), ("_mm", "mm"), ("_um", "um"), ("_khz", "kHz"), ("_hz", "Hz"),
          ("_v", "V"), ("_s", "s"), ("_c", "deg C"))
"""Key ending -> the unit it names, for messages."""


def unit(key: str) -> str:
    """The unit of a :data:`LIMITS` key, from its name ("" for a dimensionless one)."""
    return next((name for suffix, name in _UNITS if key.endswith(suffix)), "")


SI_ROUNDING = 1e-12
"""Relative slack of a range for a value given in SI: the conversion from the key's unit and back rounds [-]."""


def problem(key: str, value: float, si: bool = False, name: str | None = None) -> str | None:
    """Why ``value`` is not a plausible ``key`` (None when it is), e.g. ``"lambda_mm = 1e+06 is outside
    the plausible range 5 to 200 mm"``.

    Parameters
    ----------
    key : str
        A key of :data:`LIMITS`.
    value : float
        In the unit of ``key``, or SI with ``si`` (a length in metres, shown in the unit of ``key``).
    name : str, optional
        How the message names the quantity (default ``key``).
    """
    low, high = LIMITS[key]
    shown = float(value) / (MM if key.endswith("_mm") else UM if key.endswith("_um") else 1.0) if si else float(value)
    if not math.isfinite(shown):
        return f"{name or key} = {shown!r} is not a finite number"
    slack = SI_ROUNDING * max(abs(low), abs(high)) if si else 0.0  # 500 um as 5e-4 m reads back as 500.00000000000006
    if low - slack <= shown <= high + slack:
        return None
    return f"{name or key} = {shown:g} is outside the plausible range {low:g} to {high:g} {unit(key)}".rstrip()


PLATE_QUANTITIES = (
    ("wavelength", "lambda_mm"),
    ("resonator_thickness", "h_i_mm"),
    ("ceramic_thickness", "h_p_mm"),
    ("width", "b_mm"),
    ("glue_thickness", "glue_um"),
)
"""Plate attribute -> its key in :data:`LIMITS`."""


def plate_problem(plate: Plate) -> str | None:
    """Why a scalar ``plate``'s geometry is not plausible (None when it is): the first of its wavelength,
    thicknesses, width and bond outside :data:`LIMITS`."""
    for attribute, key in PLATE_QUANTITIES:
        reason = problem(key, float(getattr(plate, attribute)), si=True)
        if reason:
            return reason
    return None


def point_problem(plate: Plate, x: float, y: float) -> str | None:
    """Why the point (x, y) [m] from the plate's centre is not on ``plate`` (None when it is)."""
    half_length, half_width = float(plate.length) / 2, float(plate.width) / 2
    tolerance = 1e-9
    if not (math.isfinite(x) and math.isfinite(y)):
        return f"point ({x:g}, {y:g}) mm is not a finite position"
    if abs(x) > half_length + tolerance or abs(y) > half_width + tolerance:
        return (f"point ({x / MM:g}, {y / MM:g}) mm is off the plate (x within +-{half_length / MM:g} mm, y within "
                f"+-{half_width / MM:g} mm of its centre)")
    return None
