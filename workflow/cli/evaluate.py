"""``tactile evaluate``: deflection and resonance of one geometry."""

import sys

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT
from workflow.cli.options import (
    add_calibration_option,
    add_ceramic_option,
    add_damping_option,
    add_drive_options,
    add_fem_options,
    add_json_flag,
    add_model_option,
    add_width_option,
    accuracy_line,
    calibration_fem_model,
    calibration_line,
    damping_line,
    design_model,
    load_calibration_option,
    load_damping,
    plate_from_args,
    positive_float,
)
from workflow.calibration.calibration import predict
from workflow.errors import TactileError
from workflow.pipeline.calibration_files import calibrated_record
from workflow.pipeline.records import evaluation_record
from workflow.units import KHZ, MM, UM


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="deflection and resonance frequency of one plate",
        description="Evaluate one plate geometry with the beam model or the FEM: the resonance "
        "frequency and the antinode deflection amplitude at the drive voltage.  A --voltage above the "
        f"bench's safety limit ({DEFAULT_CERAMIC_VOLTAGE_LIMIT:g} V peak across the ceramics) is still "
        "evaluated, with a warning.",
    )
    add_model_option(parser)
    parser.add_argument("--lambda-mm", type=positive_float, required=True, help="wavelength lambda [mm]")
    parser.add_argument("--hi-mm", type=positive_float, required=True, help="resonator thickness h_i [mm]")
    add_ceramic_option(parser, required=True)
    add_width_option(parser)
    add_drive_options(parser)
    add_damping_option(parser)
    add_calibration_option(parser)
    add_fem_options(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    if args.calibration is not None and args.damping is not None:
        raise TactileError("--calibration and --damping cannot be combined yet: the calibrated prediction uses the "
                           "constant --q")
    plate = plate_from_args(args)
    calibration = load_calibration_option(args)
    model = design_model(args)
    if calibration is not None and not model.calibrated:
        raise TactileError("--calibration corrects the FEM: give --model fem")
    if args.voltage > DEFAULT_CERAMIC_VOLTAGE_LIMIT:
        print(
            f"tactile evaluate: warning: {args.voltage:g} V is above the bench's safety limit of "
            f"{DEFAULT_CERAMIC_VOLTAGE_LIMIT:g} V peak across the ceramics: the bench would refuse this drive",
            file=sys.stderr,
        )
    evaluation = model.evaluate(plate, load_damping(args))
    result = evaluation_record(evaluation)
    prediction = None
    if calibration is not None:
        result["nominal_f_r_khz"], result["nominal_w_dyn_um"] = result["f_r_khz"], result["w_dyn_um"]
        fem = calibration_fem_model(calibration, args.q, args.voltage)
        prediction = predict(calibration, plate, fem.design_fem())
        result.update(calibrated_record(prediction, args.calibration))
    if not args.json:
        _print_human(evaluation, prediction, args.calibration)
    return result


def _print_human(evaluation, prediction, source: str) -> None:
    """The evaluation for people, and the calibrated ``prediction`` (or None) of the calibration read from ``source``."""
    plate, damped, fem = evaluation.plate, evaluation.q_of_v, evaluation.fem
    interval = "" if damped is None else " (90 %: {:.3f} to {:.3f} µm)".format(*(w / UM for w in damped.deflection_interval))
    deflection = evaluation.deflection if damped is None else damped.deflection
    print(
        f"{evaluation.model}: lambda {plate.wavelength / MM:g} mm, h_i {plate.resonator_thickness / MM:g} mm, "
        f"h_p {plate.ceramic_thickness / MM:g} mm, b {plate.width / MM:g} mm, "
        f"{'Q(v)' if damped else 'Q ' + format(evaluation.q, 'g')}, {evaluation.voltage:g} V -> "
        f"w_dyn {deflection / UM:.4f} µm{interval} at f_r {evaluation.frequency / KHZ:.3f} kHz"
    )
    if fem is not None and fem.antiresonances is not None:
        print(
            f"  coupled piezo model: antiresonance f_a {fem.antiresonance / KHZ:.3f} kHz, effective coupling k_eff "
            f"{fem.coupling_factor:.3f}, clamped capacitance {fem.clamped_capacitance * 1e9:.2f} nF"
        )
    if fem is not None and fem.error is not None:
        print(accuracy_line(fem.error))
    if damped is not None:
        print(damping_line(damped))
    if prediction is not None:
        print(calibration_line(prediction, source))
    for index, mode in enumerate(fem.modes if fem is not None else ()):
        mark = "  <- working mode (reported above)" if index == evaluation.working_mode else ""
        print(f"  mode {mode.frequency / KHZ:8.3f} kHz: {mode.deflection / UM:.4f} µm, transverse indicator "
              f"{mode.transverse_indicator:.2f}{mark}")
