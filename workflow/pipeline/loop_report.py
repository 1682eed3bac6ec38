"""The report's sections on the loop of ``tactile run`` and on the published plates (:mod:`workflow.pipeline.loop`)."""

from workflow.pipeline.loop import LOOP_FOLDER
from workflow.pipeline.markdown import median_band, step_figures, table
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM


def _geometry(plate) -> str:
    return (f"λ {float(plate.wavelength) / MM:.3f}, h_i {float(plate.resonator_thickness) / MM:g}, "
            f"h_p {float(plate.ceramic_thickness) / MM:g} mm")


def loop_section(context: RunContext, second) -> str:
    """"Closing the loop on a built plate": each stage's f_r, the scan and the calibration's pairs."""
    if second is None:
        return ""
    first = context.results.loop_first_plate
    calibration, predicted = context.results.loop_calibration
    best = context.results.loop_redesign.best
    minimum = context.config["design"]["min_frequency_khz"] * KHZ
    reliability = context.config["loop"]["reliability"]

    def verdict(frequency):
        return "meets" if frequency >= minimum else "misses"

    rows = [
        ("1. design (plate #1, nominal FEM)", _geometry(first.plate), f"{first.nominal_frequency / KHZ:.3f}", ""),
        ("2. plate #1 built, measured", "", f"{first.measured_frequency / KHZ:.3f}",
         f"{verdict(first.measured_frequency)} {minimum / KHZ:g} kHz"),
        ("3. calibrated prediction of plate #1 (90 %)", "", median_band(predicted, KHZ), ""),
        (f"4. robust re-design (P ≥ {reliability:g}; stock h_i)", _geometry(best.plate), median_band(best.frequency, KHZ),
         f"P(f_r ≥ {minimum / KHZ:g} kHz) = {best.probability:.3f} ± {best.probability_error:.3f}"),
        ("5. re-designed plate built, measured", "", f"{second.measured_frequency / KHZ:.3f}",
         f"{verdict(second.measured_frequency)} {minimum / KHZ:g} kHz"),
    ]
    parameters = "; ".join(f"{name} {p['median']:.4g} [{p['p05']:.4g}, {p['p95']:.4g}]"
                           + ("" if p["unit"] in ("", "-") else f" {p['unit']}")
                           for name, p in calibration.summary().items())
    return (
        "## Closing the loop on a built plate\n\n"
        "The bench simulator plays each plate as built with the hidden deviations of the [simulator] section "
        "(`built_*` keys: a demonstration, docs/instruments.md); the resonance search and a coarse deflection scan "
        f"run through the real procedures and write their logs into `{LOOP_FOLDER}/`.  The calibration "
        f"(`{LOOP_FOLDER}/calibration.json`) reads only plate #1's logs, never the deviations; it uses its "
        f"{', '.join(calibration.plates[0].data_used)}; the robust re-design keeps plate #1's "
        "h_p and width and picks h_i from the stock list (docs/calibration.md).\n\n"
        + table(("stage", "geometry", "f_r [kHz]", "verdict"), rows)
        + f"\n\nPosterior (median [90 %]): {parameters}.  {calibration.identifiability()['statement']}."
        + "".join(f"  {name} is {where}: the prior, not the data, limits it."
                  for name, where in calibration.at_prior_bounds().items())
        + "\n\n"
        f"The simulator's truth for plate #1 as built: {first.built_frequency / KHZ:.3f} kHz; for the re-designed "
        f"plate: {second.built_frequency / KHZ:.3f} kHz.\n\n"
        + "\n\n".join(filter(None, (step_figures(context, "loop_first_plate"), step_figures(context, "loop_calibration"))))
    )


def case_study_section(context: RunContext, directions) -> str:
    """"Case study: the published plates": calibrate on one, predict the other."""
    if directions is None:
        return ""
    rows = [
        (d.calibrated_on.split("/")[-1], d.predicted.split("/")[-1], f"{d.measured / KHZ:.3f}",
         median_band(d.band, KHZ), f"{d.error * 100:+.2f} %", "yes" if d.inside else "no")
        for d in directions
    ]
    inside = sum(d.inside for d in directions)
    worst = max(abs(d.error) for d in directions)
    return (
        "## Case study: the published plates\n\n"
        "Each published plate's measured resonance (shipped with tactile, docs/calibration.md) calibrates the model "
        "alone; the calibration then predicts the other plate.\n\n"
        + table(("calibrated on", "predicts", "measured [kHz]", "predicted [kHz] (90 %)", "error", "inside 90 %"), rows)
        + f"\n\nIn plain words: one plate predicts the other within {worst * 100:.1f} % of its measured frequency "
        f"(the uncalibrated FEM is off by several per cent), and the measurement falls inside the 90 % interval in "
        f"{inside} of the 2 directions."
    )
