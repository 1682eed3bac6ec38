"""``tactile render``: a texture and a finger's motion in, the plate's pre-compensated drive out (docs/rendering.md)."""

from pathlib import Path

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT, DEFAULT_GAIN, PowerAmplifier
from instruments.drivers.arbitrary import MAX_POINTS, MIN_POINTS
from workflow.cli.options import (
    add_build_options,
    add_force_option,
    add_json_flag,
    add_rendering_arguments,
    add_texture_arguments,
    bounded,
    describe_texture,
    plate_from_args,
    positive_float,
    rendering_model,
    texture_and_motion,
)
from workflow.models.plate import ORIGINAL_PLATE
from workflow.pipeline.outputs import output_folder
from workflow.pipeline.rendering import RENDER_OUTPUTS, render_summary, write_rendering
from workflow.rendering.synthesis import render, search_periods
from workflow.units import MM

DEFAULT_OUT = Path("render")
"""Output folder when --out is not given, relative to the working directory."""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="a texture at a finger speed -> the plate's pre-compensated drive (33500 amplitude modulation)",
        description="Compute the drive that renders a texture on the plate: the wanted deflection envelope along the "
        "finger's motion, the drive that makes the plate's envelope follow it (the envelope equation with Q(v) and "
        "softening inverted, clipped to the voltage limit, samples out of reach flagged), the envelope predicted for it "
        "and for plain switching, and the smallest grating period rendered within --error at that speed. Writes "
        "drive.csv, the drives as 33500 .arb files and SCPI scripts (amplitude modulation by an arbitrary waveform), "
        "render.png and render.json into --out.",
    )
    add_texture_arguments(parser)
    add_rendering_arguments(parser)
    plate = parser.add_argument_group("plate", "the plate whose beam model gives the resonance and gain without a fit "
                                      "(default: the paper's original plate)")
    for flag, value, text in (("--lambda-mm", ORIGINAL_PLATE.wavelength, "wavelength lambda"),
                              ("--hi-mm", ORIGINAL_PLATE.resonator_thickness, "resonator thickness h_i"),
                              ("--hp-mm", ORIGINAL_PLATE.ceramic_thickness, "ceramic thickness h_p"),
                              ("--b-mm", ORIGINAL_PLATE.width, "width b")):
        plate.add_argument(flag, type=positive_float, default=value / MM, help=f"{text} [mm] (default {value / MM:g})")
    add_build_options(plate)
    bench = parser.add_argument_group("bench")
    bench.add_argument("--max-voltage", type=positive_float, default=DEFAULT_CERAMIC_VOLTAGE_LIMIT, metavar="VOLTS",
                       help=f"safety limit, peak volts across the ceramics: the drive is clipped to it "
                       f"(default {DEFAULT_CERAMIC_VOLTAGE_LIMIT:g})")
    bench.add_argument("--amplifier-gain", type=positive_float, default=DEFAULT_GAIN,
                       help=f"power amplifier voltage gain, for the generator settings of the scripts (default {DEFAULT_GAIN:g})")
    bench.add_argument("--points", type=bounded(int, MIN_POINTS, MAX_POINTS), default=MAX_POINTS,
                       help=f"most samples of the arbitrary waveform, {MIN_POINTS} to {MAX_POINTS} (the longest that "
                       f"one command line carries; default {MAX_POINTS})")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, metavar="DIR",
                        help=f"output folder (default: {DEFAULT_OUT} in the working directory, a folder git ignores)")
    add_force_option(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    texture, motion = texture_and_motion(args)
    envelope = rendering_model(args, plate_from_args(args))
    amplifier = PowerAmplifier(args.amplifier_gain)
    with output_folder(args.out, RENDER_OUTPUTS, force=args.force) as out:
        rendering = render(envelope.model, texture, motion, args.max_voltage, max_points=args.points)
        low, high = texture.levels
        search = search_periods(rendering.model, low, high, args.max_voltage)
        summary = {**describe_texture(texture, motion),
                   **render_summary(rendering, search, motion.typical_speed, args.error, envelope)}
        summary["files"] = write_rendering(out, rendering, amplifier, summary)
    if not args.json:
        _print_human(summary)
    return summary


def _print_human(summary: dict) -> None:
    low, high = summary["texture_levels_um"]
    kind = (f"{summary['texture_period_mm']:g} mm grating (duty {summary['texture_duty']:g})"
            if summary["texture_kind"] == "grating" else f"profile of {summary['texture_points']} points")
    print(f"render: {kind}, {low:g} to {high:g} µm, finger at {summary['texture_speed_mm_s']:g} mm/s")
    print(f"  model: {summary['model']['source']}")
    tau = summary["time_constant_ms"]
    print(f"  carrier {summary['carrier_hz']:.1f} Hz; loop {summary['loop_s'] * 1e3:.2f} ms in {summary['points']} samples "
          f"({summary['sample_rate_sa_s']:.6g} Sa/s); envelope time constant {tau['low']:.2f} ms at {low:g} µm, "
          f"{tau['high']:.2f} ms at {high:g} µm")
    print(f"  pre-compensated drive: peak {summary['peak_drive_v']:.2f} V (limit {summary['voltage_limit_v']:g} V), "
          f"predicted envelope error {summary['error']:.1%}; out of reach: rise held back by the limit "
          f"{summary['limited_rise_share']:.1%} of the loop, fall by the free decay {summary['limited_fall_share']:.1%}")
    print(f"  plain switching: peak {summary['plain_peak_drive_v']:.2f} V, predicted envelope error {summary['plain_error']:.1%}")
    periods = summary["smallest_period"]
    print(f"  smallest grating period within {summary['error_target']:.0%} at {summary['texture_speed_mm_s']:g} mm/s: "
          + ", ".join(f"{_period(periods[name])} {label}" for name, label in
                      (("precompensated", "pre-compensated"), ("plain", "plain switching"))))
    print(f"  files: {', '.join(summary['files'].values())}")


def _period(record: dict) -> str:
    prefix = "<= " if record["found"] == "at most" else ""
    return f"{prefix}{record['period_mm']:.3g} mm"
