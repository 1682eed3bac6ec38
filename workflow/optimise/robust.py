"""Robust design under a calibration: the largest deflection with P(f_r >= f_min) >= a reliability.

For each stock resonator thickness h_i (docs/calibration.md, "Robust design"):

1. a linear surrogate of ln f_r and ln w over ln lambda, the calibration parameters and a
   ceramic-thickness offset, from FEM evaluations (a two-level design where the accuracy allows,
   :class:`~workflow.calibration.plate_surrogate.DesignFem`) at a Latin hypercube of a box spanning the
   posterior's central 99 % and three manufacturing standard deviations, lambda around the
   beam model's estimate;
2. Monte Carlo draws: posterior samples plus manufacturing scatter (normal, standard deviations
   :class:`Tolerances`) plus the surrogate's and the FEM's errors and the calibration's model discrepancy;
   lambda is solved so that
   the quantile of f_r at level (1 - reliability) minus :data:`SOLVE_MARGIN_SE` Monte Carlo
   standard errors equals f_min (conservative by the solve's own sampling error);
3. the achieved probability from fresh draws (its Monte Carlo standard error given), and one FEM
   evaluation at the posterior median for the mode separation and the homogeneity of |w|.

The candidate with the largest median deflection whose modes are separated is the optimum.  A given design (e.g.
the nominal optimum) is checked the same way with its own lambda instead of a solved one
(:func:`robust_candidates` with ``solve`` False): its probability under the same posterior and scatter.
"""

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import brentq

from workflow.calibration.calibration import POSTERIOR_RANGE, Calibration, nominal_theta, prediction_points
from workflow.calibration.parameters import deviated_plate
from workflow.calibration.plate_surrogate import DesignFem, DesignValues, SurrogateDesign
from workflow.calibration.surrogate import ResponseSurface, fit_response_surface, latin_hypercube
from workflow.errors import InfeasibleError
from workflow.models import analytical, materials
from workflow.models.plate import Plate

OFFSET_NAMES = ("glue_um", "resonator_offset_um")
"""Calibration parameters that manufacturing scatter adds to (always among the robust inputs)."""
LAMBDA_BOX = (0.93, 1.06)
"""The surrogate's lambda range around the beam model's estimate, as factors [-]."""
SOLVE_DRAWS = 20000
"""Monte Carlo draws of the lambda solve (common to every trial lambda) [-]."""
SOLVE_MARGIN_SE = 2.0
"""The solve targets the quantile this many binomial standard errors sqrt(a (1 - a) / n) below the requested
level a = 1 - reliability, so that fresh draws find P >= reliability despite the solve's own sampling error [-]."""
CHECK_DRAWS = 20000
"""Fresh draws that estimate the achieved probability [-]."""


@dataclass(frozen=True)
class Tolerances:
    """Manufacturing standard deviations (normal, independent).

    Attributes
    ----------
    resonator_thickness, ceramic_thickness, wavelength, glue_thickness : float
        Standard deviations of h_i, h_p, lambda and the bond thickness [m].
    """

    resonator_thickness: float = 10e-6
    ceramic_thickness: float = 10e-6
    wavelength: float = 50e-6
    glue_thickness: float = 5e-6


@dataclass(frozen=True)
class RobustSettings:
    """What the robust optimum must satisfy.

    Attributes
    ----------
    reliability : float
        Required P(f_r >= min_frequency) [-].
    min_frequency : float
        [Hz].
    separation : float
        No other mode with a transverse indicator above ``transverse_threshold`` within this
        relative distance of the working frequency [-].
    transverse_threshold : float
        [-].
    tolerances : Tolerances
    seed : int
    """

    reliability: float = 0.95
    min_frequency: float = materials.MIN_FREQUENCY
    separation: float = 0.03
    transverse_threshold: float = 0.3
    tolerances: Tolerances = Tolerances()
    seed: int = 0


@dataclass(frozen=True)
class RobustCandidate:
    """The robust design for one stock h_i.

    Attributes
    ----------
    plate : Plate
        Nominal design: the stock h_i and the solved lambda [m].
    frequency, deflection : tuple of float
        (p05, p50, p95) of f_r [Hz] and w [m] under posterior and scatter.
    probability, probability_error : float
        Achieved P(f_r >= f_min) and its Monte Carlo standard error [-].
    draws : int
        Fresh draws behind the probability [-].
    margin : float
        p05 of f_r minus f_min [Hz].
    nearest_transverse : dict or None
        The closest other mode with a transverse indicator above the threshold: ``f`` [Hz],
        ``relative_distance`` [-], ``indicator`` [-]; None if there is none.
    separated : bool
        Mode separation holds.
    homogeneity : float
        Coefficient of variation of |w| over the 44 probes at the median design [-] (0: uniform).
    surrogate_error : float
        Leave-one-out relative error of the frequency surrogate [-].
    evaluations : int
        FEM evaluations for this candidate [-].
    lambda_at_edge : bool
        The solved lambda sits at the edge of the surrogate's box (the result is then an extrapolation).
    working : FemResult or None
        The FEM result at the posterior median (its modes and deflection as a function of Q, for Q(v)); not compared.
    """

    plate: Plate
    frequency: tuple
    deflection: tuple
    probability: float
    probability_error: float
    draws: int
    margin: float
    nearest_transverse: dict | None
    separated: bool
    homogeneity: float
    surrogate_error: float
    evaluations: int
    lambda_at_edge: bool
    working: object = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class RobustDesign:
    """Candidates per stock thickness and the index of the optimum."""

    candidates: tuple
    best_index: int

    @property
    def best(self) -> RobustCandidate:
        return self.candidates[self.best_index]

    @property
    def evaluations(self) -> int:
        return sum(c.evaluations for c in self.candidates)


def robust_inputs(calibration: Calibration) -> tuple:
    """Parameter names of the robust surrogate after ln lambda: the calibration's, the offsets, then h_p's offset."""
    names = calibration.settings.names
    return names + tuple(n for n in OFFSET_NAMES if n not in names)


def posterior_columns(calibration: Calibration, plate: Plate) -> np.ndarray:
    """Posterior samples extended by the offsets the calibration did not infer (held at their nominal) [SI]."""
    names = robust_inputs(calibration)
    extra = nominal_theta(names, plate)[len(calibration.settings.names):]
    return np.hstack([calibration.samples, np.broadcast_to(extra, (len(calibration.samples), len(extra)))])


def scattered_draws(calibration: Calibration, plate: Plate, tolerances: Tolerances, n: int, seed: int) -> np.ndarray:
    """(n, 1 + k + 1 + 2) draws of (ln lambda deviation, parameters, h_p offset) [SI] and the model discrepancy of
    ln f_r and ln w [-]: posterior plus scatter plus, for each drawn posterior sample, a normal draw of its
    discrepancy terms (:mod:`workflow.calibration.posterior`)."""
    rng = np.random.default_rng(seed)
    names = robust_inputs(calibration)
    chosen = rng.integers(0, len(calibration.samples), n)
    theta = posterior_columns(calibration, plate)[chosen]
    theta[:, names.index("glue_um")] = np.abs(theta[:, names.index("glue_um")] + rng.normal(0, tolerances.glue_thickness, n))
    theta[:, names.index("resonator_offset_um")] += rng.normal(0, tolerances.resonator_thickness, n)
    log_lambda = rng.normal(0, tolerances.wavelength / float(plate.wavelength), n)
    offset = rng.normal(0, tolerances.ceramic_thickness, n)
    return np.column_stack([log_lambda, theta, offset, rng.normal(0, calibration.discrepancy[chosen])])


def robust_plate(plate: Plate, names: Sequence[str], point) -> Plate:
    """The plate at one robust input: ``point`` = (ln(lambda [m]), the calibration parameters ``names`` in their units,
    the ceramic thickness's offset [m]) applied to ``plate`` [m]."""
    moved = plate.with_(wavelength=float(np.exp(point[0])), ceramic_thickness=float(plate.ceramic_thickness) + point[-1])
    return deviated_plate(moved, names, point[1:-1])


def beam_wavelength(plate: Plate, frequency: float) -> float:
    """lambda at which the beam model of ``plate`` resonates at ``frequency`` [m]."""
    low, high = materials.WAVELENGTH_RANGE
    residual = lambda wavelength: float(analytical.resonance_frequency(plate.with_(wavelength=wavelength))) - frequency  # noqa: E731
    if residual(low * 0.5) * residual(high * 1.5) > 0:
        raise InfeasibleError(f"no wavelength gives {frequency / 1e3:.2f} kHz for h_i {float(plate.resonator_thickness) * 1e3:g} mm")
    return brentq(residual, low * 0.5, high * 1.5, xtol=1e-9)


def calibration_ratio(calibration: Calibration) -> float:
    """Posterior-median surrogate f_r over the beam model's f_r, averaged over the calibrated plates [-]."""
    median = np.median(calibration.samples, axis=0)
    ratios = [float(s.frequency(median)) / float(analytical.resonance_frequency(p.plate))
              for s, p in zip(calibration.surrogates, calibration.plates)]
    return float(np.mean(ratios))


@dataclass(frozen=True)
class RobustSurrogate:
    """Linear response surfaces of one nominal plate over (ln lambda, parameters..., h_p offset).

    Attributes
    ----------
    bounds : numpy.ndarray
        (n, 2) box of the inputs [SI; ln m for lambda].
    log_frequency, log_deflection : ResponseSurface
    frequency_sigma : float
        Leave-one-out and FEM errors of ln f_r in quadrature [-].
    evaluations : int
    """

    bounds: np.ndarray
    log_frequency: ResponseSurface
    log_deflection: ResponseSurface
    frequency_sigma: float
    evaluations: int

    def sample(self, log_lambda: float, draws: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """ln f_r and ln w of ``draws`` (deviations and discrepancies, :func:`scattered_draws`) about the design
        ln lambda, each with its surrogate's error drawn from ``seed`` and its discrepancy added."""
        rng = np.random.default_rng(seed)
        shifted, discrepancy = draws[:, :-2].copy(), draws[:, -2:]
        shifted[:, 0] += log_lambda
        inside = np.clip(shifted, self.bounds[:, 0], self.bounds[:, 1])
        return (self.log_frequency(inside) + rng.normal(0, self.frequency_sigma, len(draws)) + discrepancy[:, 0],
                self.log_deflection(inside) + rng.normal(0, self.log_deflection.loo_rms, len(draws)) + discrepancy[:, 1])


def start_problem(calibration: Calibration, plate: Plate, settings: RobustSettings) -> str | None:
    """Why no robust lambda can be sought for ``plate`` (the beam model reaches the calibrated frequency limit at no
    wavelength), or None."""
    try:
        beam_wavelength(plate, settings.min_frequency / calibration_ratio(calibration))
    except InfeasibleError as error:
        return str(error)
    return None


def robust_design_points(calibration: Calibration, plate: Plate, settings: RobustSettings,
                         solve: bool = True) -> SurrogateDesign:
    """The FEM design of a nominal plate's robust surrogate (the module's step 1): lambda around the beam model's
    estimate of the robust lambda when ``solve``, around the plate's own otherwise."""
    names = robust_inputs(calibration)
    tol = settings.tolerances
    guess = beam_wavelength(plate, settings.min_frequency / calibration_ratio(calibration)) if solve else float(plate.wavelength)
    low, high = np.percentile(posterior_columns(calibration, plate), POSTERIOR_RANGE, axis=0)
    scatter = {"glue_um": tol.glue_thickness, "resonator_offset_um": tol.resonator_thickness}
    spread = np.array([3 * scatter.get(name, 0.0) for name in names])
    low, high = low - spread, high + spread
    high = np.maximum(high, low + 1e-3 * np.abs(low) + 1e-9)
    half_hp = max(3 * tol.ceramic_thickness, 1e-6)
    bounds = np.vstack([np.log(np.array(LAMBDA_BOX) * guess), np.column_stack([low, high]), [-half_hp, half_hp]])
    points = latin_hypercube(prediction_points(len(bounds) - 1), bounds, settings.seed)
    return SurrogateDesign(points, bounds, tuple(robust_plate(plate, names, point) for point in points))


def fit_robust_surrogate(design: SurrogateDesign, values: DesignValues) -> RobustSurrogate:
    """The linear surrogate through a design's values."""
    log_f = fit_response_surface(design.points, values.log_frequency, design.bounds, 1)
    log_w = fit_response_surface(design.points, values.log_deflection, design.bounds, 1)
    sigma = float(np.hypot(log_f.loo_rms, values.fem_error))
    return RobustSurrogate(design.bounds, log_f, log_w, sigma, values.evaluations)


def conservative_level(reliability: float, draws: int) -> float:
    """Quantile level [-] the lambda solve targets: 1 - reliability less :data:`SOLVE_MARGIN_SE` binomial standard
    errors of a quantile estimated from ``draws`` samples (never below half the requested level)."""
    level = 1 - reliability
    return max(level - SOLVE_MARGIN_SE * np.sqrt(level * (1 - level) / draws), level / 2)


@dataclass(frozen=True)
class _Solved:
    """A nominal plate's lambda solved on its surrogate (the module's step 2) and fresh draws at it."""

    surrogate: RobustSurrogate
    design: Plate
    frequencies: np.ndarray
    deflections: np.ndarray
    at_edge: bool
    median: Plate


def _solve(calibration: Calibration, plate: Plate, settings: RobustSettings, surrogate: RobustSurrogate,
           solve: bool = True) -> _Solved:
    """lambda solved on the surrogate (``solve``) or the plate's own, and the fresh draws at it."""
    too_low = too_high = False
    log_lambda = float(np.log(plate.wavelength))
    if solve:
        draws = scattered_draws(calibration, plate, settings.tolerances, SOLVE_DRAWS, settings.seed)
        target = np.log(settings.min_frequency)
        level = conservative_level(settings.reliability, SOLVE_DRAWS)

        def shortfall(log_lambda):
            log_f, _ = surrogate.sample(log_lambda, draws, settings.seed)
            return float(np.percentile(log_f, 100 * level)) - target

        low, high = surrogate.bounds[0]
        too_low, too_high = shortfall(low) < 0, shortfall(high) > 0
        log_lambda = low if too_low else high if too_high else brentq(shortfall, low, high, xtol=1e-8)
    check = scattered_draws(calibration, plate, settings.tolerances, CHECK_DRAWS, settings.seed + 1)
    log_f, log_w = surrogate.sample(log_lambda, check, settings.seed + 1)
    design = plate.with_(wavelength=float(np.exp(log_lambda))) if solve else plate
    median = deviated_plate(design, robust_inputs(calibration), np.median(posterior_columns(calibration, plate), axis=0))
    return _Solved(surrogate, design, np.exp(log_f), np.exp(log_w), bool(too_low or too_high), median)


def _candidate(solved: _Solved, result, settings: RobustSettings, q: float) -> RobustCandidate:
    """The candidate of a solved plate, from the FEM result at its posterior median (the module's step 3)."""
    frequencies = solved.frequencies
    probability = float(np.mean(frequencies >= settings.min_frequency))
    nearest, separated = mode_separation(result, settings)
    probes = np.abs(result.probe_model.response(result.frequency, q))
    return RobustCandidate(
        plate=solved.design,
        frequency=tuple(float(x) for x in np.percentile(frequencies, [5, 50, 95])),
        deflection=tuple(float(x) for x in np.percentile(solved.deflections, [5, 50, 95])),
        probability=probability,
        probability_error=float(np.sqrt(probability * (1 - probability) / CHECK_DRAWS)),
        draws=CHECK_DRAWS,
        margin=float(np.percentile(frequencies, 5) - settings.min_frequency),
        nearest_transverse=nearest,
        separated=separated,
        homogeneity=float(np.std(probes) / np.mean(probes)),
        surrogate_error=solved.surrogate.log_frequency.loo_rms,
        evaluations=solved.surrogate.evaluations + 1,
        lambda_at_edge=solved.at_edge,
        working=result,
    )


def robust_candidates(calibration: Calibration, plates: Sequence[Plate], settings: RobustSettings, fem: DesignFem,
                      q: float, solve: Sequence[bool] | None = None) -> tuple:
    """The robust design of each nominal plate (its h_i and h_p fixed, lambda solved; see the module), or, where
    ``solve`` says False, the check of the plate as given (its own lambda).

    The FEM evaluations of every plate's surrogate go in one batch per level (:meth:`DesignFem.values`), and those at
    the solved designs' posterior medians (to the accuracy) in a last one, so that the workers of a pool stay busy
    across the plates.
    """
    solve = [True] * len(plates) if solve is None else list(solve)
    designs = [robust_design_points(calibration, plate, settings, s) for plate, s in zip(plates, solve)]
    surrogates = [fit_robust_surrogate(design, values) for design, values in zip(designs, fem.values(designs))]
    solved = [_solve(calibration, plate, settings, surrogate, s) for plate, surrogate, s in zip(plates, surrogates, solve)]
    medians = fem.accurate([s.median for s in solved])
    return tuple(_candidate(s, result, settings, q) for s, result in zip(solved, medians))


def robust_candidate(calibration: Calibration, plate: Plate, settings: RobustSettings, fem: DesignFem,
                     q: float) -> RobustCandidate:
    """The robust design of one nominal plate (its h_i and h_p fixed, lambda solved); see the module."""
    (candidate,) = robust_candidates(calibration, [plate], settings, fem, q)
    return candidate


def mode_separation(result, settings: RobustSettings) -> tuple[dict | None, bool]:
    """The nearest other mode above the transverse threshold (f [Hz], relative distance, indicator) and
    whether it lies outside ``settings.separation`` of the working mode."""
    working = result.frequency
    others = [(abs(m.frequency / working - 1), m) for k, m in enumerate(result.modes)
              if k != result.best_index and m.transverse_indicator > settings.transverse_threshold]
    if not others:
        return None, True
    distance, mode = min(others, key=lambda pair: pair[0])
    nearest = {"f": mode.frequency, "relative_distance": distance, "indicator": mode.transverse_indicator}
    return nearest, distance > settings.separation


def robust_design(calibration: Calibration, plate: Plate, stock: Sequence[float], settings: RobustSettings,
                  fem: DesignFem, q: float) -> RobustDesign:
    """Robust candidates for each stock h_i [m] of the nominal ``plate`` (h_p, b, materials) and the optimum.

    Raises
    ------
    InfeasibleError
        When no candidate has its modes separated and its lambda inside the design range.
    """
    candidates = robust_candidates(calibration, [plate.with_(resonator_thickness=h) for h in stock], settings, fem, q)
    return select_robust(candidates)


def select_robust(candidates: Sequence[RobustCandidate],
                  wavelength_range: tuple = materials.WAVELENGTH_RANGE) -> RobustDesign:
    """The candidate with the largest median deflection among those with separated modes and lambda inside
    ``wavelength_range`` [m] (and not at its surrogate's box edge).

    Raises
    ------
    InfeasibleError
        When there is none, with each candidate's reason.
    """
    low, high = wavelength_range
    feasible = [k for k, c in enumerate(candidates)
                if c.separated and not c.lambda_at_edge and low <= float(c.plate.wavelength) <= high]
    if not feasible:
        raise InfeasibleError(
            "no stock thickness gives a robust design with separated modes and lambda inside its range: "
            + "; ".join(f"h_i {float(c.plate.resonator_thickness) * 1e3:g} mm: lambda {float(c.plate.wavelength) * 1e3:.2f} mm"
                        f"{' (box edge)' if c.lambda_at_edge else ''}, separated {c.separated}" for c in candidates)
        )
    best = max(feasible, key=lambda k: candidates[k].deflection[1])
    return RobustDesign(tuple(candidates), best)
