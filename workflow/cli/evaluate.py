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
from workflow.errors import TactileError
from workflow.pipeline.calibration_files import calibrated_record
from workflow.pipeline.records import geometry_record


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
    result = {"model": args.model, **geometry_record(plate), "q": args.q, "voltage_v": args.voltage, **evaluation.record}
    if calibration is not None:
        result["nominal_f_r_khz"], result["nominal_w_dyn_um"] = result["f_r_khz"], result["w_dyn_um"]
        fem = calibration_fem_model(calibration, args.q, args.voltage)
        result.update(calibrated_record(calibration, plate, fem.design_fem(), args.calibration))
    if not args.json:
        _print_human(result, args.model, evaluation.working_mode)
    return result


def _print_human(result: dict, model: str, working_mode) -> None:
    """The evaluation for people; ``working_mode`` is the index of the FEM mode whose deflection is reported."""
    damped = "damping" in result
    interval = (f" (90 %: {result['w_dyn_um_p05']:.3f} to {result['w_dyn_um_p95']:.3f} µm)"
                if "w_dyn_um_p05" in result else "")
    print(
        f"{model}: lambda {result['lambda_mm']:g} mm, h_i {result['h_i_mm']:g} mm, h_p {result['h_p_mm']:g} mm, "
        f"b {result['b_mm']:g} mm, {'Q(v)' if damped else 'Q ' + format(result['q'], 'g')}, "
        f"{result['voltage_v']:g} V -> w_dyn {result['w_dyn_um']:.4f} µm{interval} at f_r {result['f_r_khz']:.3f} kHz"
    )
    if "f_a_khz" in result:
        print(
            f"  coupled piezo model: antiresonance f_a {result['f_a_khz']:.3f} kHz, effective coupling k_eff "
            f"{result['k_eff']:.3f}, clamped capacitance {result['clamped_capacitance_nf']:.2f} nF"
        )
    if "f_error_estimate" in result:
        print(accuracy_line(result))
    if damped:
        print(damping_line(result))
    if "nominal_f_r_khz" in result:
        print(calibration_line(result))
    for index, mode in enumerate(result.get("modes", [])):
        mark = "  <- working mode (reported above)" if index == working_mode else ""
        print(f"  mode {mode['f_khz']:8.3f} kHz: {mode['w_um']:.4f} µm, transverse indicator {mode['transverse']:.2f}{mark}")
