"""The report's first table: the robust design per h_p beside the nominal optimum, under the calibration on the
built plates (:mod:`workflow.pipeline.robust_recommendation`)."""

from workflow.optimise.robust import RobustCandidate
from workflow.pipeline.markdown import step_figures, table
from workflow.pipeline.robust_recommendation import RobustRecommendation
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM, UM


def _band(values, unit: float, digits: int) -> str:
    low, median, high = (v / unit for v in values)
    return f"{median:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _nearest(candidate: RobustCandidate) -> str:
    nearest = candidate.nearest_transverse
    if nearest is None:
        return "none computed"
    return f"{nearest['f'] / KHZ:.3f} kHz ({100 * nearest['relative_distance']:.1f} % away)"


def _row(label: str, design: str, candidate: RobustCandidate, damped, verdict: str) -> tuple:
    plate = candidate.plate
    return (
        label,
        design,
        f"{float(plate.wavelength) / MM:.3f}",
        f"{float(plate.resonator_thickness) / MM:.3f}",
        f"{float(plate.length) / MM:.1f}",
        _band(candidate.frequency, KHZ, 3),
        f"{candidate.probability:.3f} ± {candidate.probability_error:.1g}",
        _band(candidate.deflection, UM, 2),
        "–" if damped is None else _band(damped.required_voltage, 1.0, 1),
        _nearest(candidate),
        verdict,
    )


def _meets(candidate: RobustCandidate, reliability: float) -> bool:
    """P reaches the reliability within two Monte Carlo standard errors."""
    return candidate.probability >= reliability - 2 * candidate.probability_error


def _deflection_shortfall(damped) -> str:
    """Empty when the design reaches the target deflection at the design voltage with Q(v) (median), else why not."""
    if damped is None or damped.reaches_target:
        return ""
    return (f"misses {damped.target / UM:g} µm at {damped.problem.voltage:g} V: needs {damped.required_voltage[1]:.1f} V "
            "with Q(v)")


def buildable(choice, reliability: float) -> bool:
    """A robust design whose P meets the reliability and which reaches the target deflection with Q(v)."""
    return (choice.best is not None and _meets(choice.best, reliability)
            and not _deflection_shortfall(choice.best_damped))


def _robust_verdict(choice, reliability: float) -> str:
    if not _meets(choice.best, reliability):
        return f"P below {reliability:g}: widen the stocks tried"
    shortfall = _deflection_shortfall(choice.best_damped)
    return f"**{shortfall}**" if shortfall else "**build this**"


def _nominal_verdict(candidate: RobustCandidate, damped, settings) -> str:
    """What the nominal design fails of the robust design's tests (frequency probability, mode separation, target
    deflection), or "robust as it is"."""
    reliability, limit = settings.reliability, settings.min_frequency / KHZ
    reasons = [] if _meets(candidate, reliability) else [
        f"likely below {limit:g} kHz: P {candidate.probability:.3f} < {reliability:g}"]
    if not candidate.separated:
        reasons.append(f"a transverse mode {100 * candidate.nearest_transverse['relative_distance']:.1f} % away "
                       f"(< {100 * settings.separation:g} %)")
    shortfall = _deflection_shortfall(damped)
    if shortfall:
        reasons.append(shortfall)
    return "**" + "; ".join(reasons) + "**" if reasons else "robust as it is"


def robust_section(context: RunContext, robust: RobustRecommendation) -> str:
    """"What to build": per h_p the robust row, then the nominal optimum's, with their predicted f_r and w bands and
    P(f_r >= f_min); a line per h_p without a robust design; what the bands contain."""
    settings = robust.settings
    reliability, limit = settings.reliability, settings.min_frequency / KHZ
    voltage = context.config["design"]["voltage_v"]
    rows, missing = [], []
    for hp, choice in robust.choices.items():
        label = f"{hp / MM:g}"
        if choice.best is not None:
            rows.append(_row(label, f"robust (stock h_i of {len(choice.candidates)} tried)", choice.best,
                             choice.best_damped, _robust_verdict(choice, reliability)))
        else:
            rows.append((label, "robust: **none**", *["–"] * 8, "see below"))
            missing.append(f"h_p = {label} mm: {choice.reason}")
        rows.append(_row(label, f"nominal {choice.nominal_source} optimum", choice.nominal, choice.nominal_damped,
                         _nominal_verdict(choice.nominal, choice.nominal_damped, settings)))
    plates = ", ".join(robust.calibrated_on)
    built = [hp for hp, c in robust.choices.items() if buildable(c, reliability)]
    target = context.config["design"]["target_deflection_um"]
    text = [
        "## What to build\n\n"
        f"The FEM calibrated on the measured built plates ({plates}) predicts how a plate of each design would "
        f"resonate as built; the **robust** design per h_p is the stock resonator thickness and wavelength with "
        f"P(f_r ≥ {limit:g} kHz) ≥ {reliability:g} under that calibration and the manufacturing tolerances, "
        "and the largest deflection among the stocks tried (docs/calibration.md, \"The recommended design in "
        "tactile run\"). The nominal optimum (the next section) is checked the same way, for comparison."
        + (f" Build: {', '.join(f'h_p = {hp / MM:g} mm' for hp in built)} from the robust rows." if built else
           " **No h_p has a design to build**: see the verdicts."),
        table(["h_p [mm]", "design", "λ [mm]", "h_i [mm]", "L [mm]", "f_r as built [kHz], median [5 %, 95 %]",
               f"P(f_r ≥ {limit:g} kHz)", f"w at {voltage:g} V, Q = {robust.q:g} [µm]",
               f"V for {target:g} µm with Q(v)", "nearest transverse-mixing mode", "verdict"], rows),
    ]
    if missing:
        text.append("No robust design: " + "; ".join(missing) + ".")
    tolerances = settings.tolerances
    text.append(
        "What these bands contain: the calibration's posterior (its parameters and its model-discrepancy term, "
        f"from the built plates' measurements), manufacturing scatter (standard deviations h_i "
        f"{tolerances.resonator_thickness / UM:g} µm, h_p {tolerances.ceramic_thickness / UM:g} µm, λ "
        f"{tolerances.wavelength / UM:g} µm, bond {tolerances.glue_thickness / UM:g} µm), and the surrogate's and the "
        "FEM's errors; P is from fresh Monte Carlo draws (± its standard error). What they do not contain: Q(v) (the "
        f"deflections are at the constant Q = {robust.q:g}; the voltage for {target:g} µm is with the fitted Q(v) at "
        "the posterior-median plate, median [5 %, 95 %] over the Q(v) posterior only), and "
        "ways a new plate may differ from the calibration plates beyond what the discrepancy term learned from them "
        "(another ceramic, another bonding process). The nearest transverse-mixing mode is the FEM's at the "
        f"posterior-median plate; a robust design needs it more than {100 * settings.separation:g} % away. "
        f"{robust.evaluations} FEM evaluations."
    )
    built = context.results.built_calibration
    if built is not None:
        text.append(_calibration_state(built.calibration))
    figures = step_figures(context, "built_calibration")
    if figures:
        text.append(figures)
    return "\n\n".join(text)


def _calibration_state(calibration) -> str:
    """Whether the calibration plates are represented by its parameters (the posterior-predictive check) and which
    parameters only the prior bounds."""
    check = calibration.check()
    bounded = "".join(f" {name} is {where}: the prior, not the data, limits it."
                      for name, where in calibration.at_prior_bounds().items())
    statement = check["statement"].rstrip(".")
    return f"The calibration (`calibration/calibration.json`): {statement}.{bounded}"
