"""``tactile simulate``: the bench simulator, on pseudo-terminals or as a summary of its physics."""

import json
import os
import signal
import sys

from workflow.cli.options import (
    add_bench_arguments,
    add_built_plate_arguments,
    add_json_flag,
    bench_settings,
    built_plate_from_args,
    describe_law,
)
from workflow.units import KHZ, PM_PER_V


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="run the bench simulator (generator, vibrometer controller and lock-in over one simulated plate)",
        description="Serve the simulated generator, vibrometer controller and lock-in on pseudo-terminals (--pty), or print the "
        "simulated plate's physics (resonance, Q(v) law, working point). Protocols: docs/instruments.md.",
    )
    parser.add_argument("--pty", action="store_true",
                        help='serve on pseudo-terminals: print {"generator": PATH, "vibrometer": PATH} and serve until '
                        "interrupted (SIGTERM stops it cleanly)")
    add_bench_arguments(parser)
    add_built_plate_arguments(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args):
    from instruments.simulator import Bench
    from instruments.simulator.physics import working_point_velocity
    from instruments.simulator.ptyserver import open_ptys, serve
    from workflow.damping.laws import law_parameters
    from workflow.models.materials import DESIGN_VOLTAGE, PLATE_Q
    from workflow.models.plate import ORIGINAL_PLATE

    settings = bench_settings(args)
    if args.pty:
        terminated = []
        signal.signal(signal.SIGTERM, lambda signum, frame: terminated.append(signum))
        ptys = open_ptys()
        print(json.dumps({name: pair.path for name, pair in ptys.items()}), flush=True)
        print(
            f"tactile simulate: serving the generator on {ptys['generator'].path} and the vibrometer on "
            f"{ptys['vibrometer'].path}; stop with Ctrl-C or 'kill {os.getpid()}'",
            file=sys.stderr,
            flush=True,
        )
        try:
            serve(Bench(settings), ptys, should_stop=lambda: bool(terminated))
        finally:
            for pair in ptys.values():
                pair.close()
        return None
    response = settings.response
    built = built_plate_from_args(args)
    plate = ORIGINAL_PLATE if built is None else built.plate()
    v_work = working_point_velocity(plate, q=PLATE_Q, voltage=DESIGN_VOLTAGE)
    result = {
        **settings.metadata(),
        "working_voltage_v": DESIGN_VOLTAGE,
        "working_velocity_m_s": v_work,
        "working_q": float(response.law.quality_factor(v_work)),
    }
    if not args.json:
        print(
            f"simulated plate: resonance {response.resonance_frequency / KHZ:.3f} kHz, "
            f"static deflection {response.deflection_per_volt / PM_PER_V:.1f} pm/V"
        )
        print(f"Q(v): {describe_law(response.law.name, law_parameters(response.law))}")
        print(f"working point {DESIGN_VOLTAGE:g} V: velocity {v_work:.4f} m/s, Q {result['working_q']:.2f}")
    return result
