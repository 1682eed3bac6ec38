"""Simulated measurements in-process: the real procedures over the ``tactile-sim://`` transport.

:func:`simulate_campaign` is what ``tactile run`` and the damping fit's tests use to
obtain a Q(v) campaign log quickly (bench time is simulated; nothing sleeps).
"""

from dataclasses import replace

import serial

from instruments.drivers.amplifier import PowerAmplifier
from instruments.drivers.lockin import capture_interval
from instruments.procedures.ringdown import RingdownPlan, ringdown
from instruments.procedures.sweeps import CampaignPlan, ProcedureResult, Station, open_station, q_campaign
from instruments.simulator.bench import INSTRUMENTS, TEMPERATURE_AUX, Bench, BenchSettings, default_bench_settings, register_bench
from instruments.simulator.urlhandler import bench_url, register_url_handler

SIMULATED_NOTE = "SIMULATED data from the tactile bench simulator, not a measurement"


def simulated_station(settings: BenchSettings, voltage_limit: float | None = None, **options) -> tuple[Station, Bench]:
    """A station on a new simulated bench, through ``tactile-sim://`` ports.

    Parameters
    ----------
    settings : BenchSettings
    voltage_limit : float or None
        The station's (and driver's) safety limit [V peak across the ceramics]; by
        default the bench's own limit.
    options
        Passed to :class:`Station` (``retries``, ``settle_time``, ``time_constant``); the plate's temperature
        sensor is on the lock-in's Aux In 1.
    """
    register_url_handler()
    bench = Bench(settings)
    name = register_bench(bench)
    # reads on a simulated port never wait: the timeout is nominal
    ports = [serial.serial_for_url(bench_url(name, instrument), timeout=1.0) for instrument in INSTRUMENTS]
    limit = settings.ceramic_voltage_limit if voltage_limit is None else voltage_limit
    options = {"clock": bench.clock, "sleep": bench.sleep, "temperature_aux": TEMPERATURE_AUX + 1, **options}
    return open_station(*ports, PowerAmplifier(settings.amplifier_gain), limit, **options), bench


def reopened_station(station: Station, bench: Bench) -> Station:
    """A new station on the ports of ``station``'s simulated bench, reopened (as after an unplugged cable)."""
    drivers = (station.generator, station.vibrometer, station.lockin)
    ports = [serial.serial_for_url(driver.port.port, timeout=1.0) for driver in drivers]
    readout = station.readout
    return open_station(*ports, station.amplifier, station.voltage_limit, clock=bench.clock, sleep=bench.sleep,
                        settle_time=station.settle_time, retries=station.retries, time_constant=readout.time_constant,
                        temperature_aux=readout.temperature_aux)


def simulation_metadata(settings: BenchSettings) -> dict:
    """Header lines marking a log as simulated, with the simulator's settings; a built plate's nominal geometry
    and an off-centre measurement point too."""
    built = {} if settings.built_plate is None else settings.built_plate.nominal.metadata()
    return {"simulated": "yes", "note": SIMULATED_NOTE, **built, **settings.point_metadata(), **settings.metadata()}


def simulate_campaign(
    path,
    settings: BenchSettings | None = None,
    voltages=CampaignPlan.voltages,
    points_per_sweep: int = CampaignPlan.points_per_sweep,
    span: float = CampaignPlan.span,
    center_frequency: float | None = None,
    seed: int | None = None,
    restart: bool = True,
    alternate: bool = CampaignPlan.alternate,
) -> ProcedureResult:
    """Run a Q(v) campaign on a simulated bench and write its log to ``path``.

    Parameters
    ----------
    path : path-like
        The log (docs/log-format.md) to write.
    settings : BenchSettings or None
        The bench (plate physics, law, noise, drift, faults); default
        :func:`.simulator.bench.default_bench_settings`.
    voltages : sequence of float
        Drive of each sweep [V peak across the ceramics].
    points_per_sweep : int
    span : float
        Sweep width [Hz].
    center_frequency : float or None
        Sweep centre [Hz]; default the simulated plate's resonance at time 0 rounded to 1 Hz
        (``tactile measure campaign --simulate`` finds it by a resonance search instead).
    seed : int or None
        Replaces the measurement-noise seed of ``settings``.
    restart : bool
        Overwrite an existing log (default) rather than resume it.
    alternate : bool
        Odd sweeps downward (:class:`CampaignPlan`).

    Returns
    -------
    ProcedureResult
        ``path``, counts and per-sweep peak and Q estimates.
    """
    settings = settings or default_bench_settings()
    if seed is not None:
        settings = replace(settings, seed=seed)
    centre = round(settings.response.resonance_frequency) if center_frequency is None else center_frequency
    plan = CampaignPlan(centre, span, points_per_sweep, tuple(float(v) for v in voltages), alternate)
    station, _ = simulated_station(settings, settle_time=0.0)
    return q_campaign(station, path, plan, metadata=simulation_metadata(settings), restart=restart, fsync=False)


def simulate_ringdown(
    path,
    settings: BenchSettings | None = None,
    voltages=RingdownPlan.voltages,
    cycles: int = RingdownPlan.cycles,
    samples: int = RingdownPlan.samples,
    interval: float = RingdownPlan.interval,
    seed: int | None = None,
    restart: bool = True,
) -> ProcedureResult:
    """Ring-downs on a simulated bench at its resonance (time 0, rounded to 1 Hz), logged to ``path``.

    Parameters as :class:`~instruments.procedures.ringdown.RingdownPlan` (``interval`` [s] taken to the lock-in's
    nearest capture interval); ``settings``, ``seed`` and ``restart`` as :func:`simulate_campaign`.
    """
    settings = settings or default_bench_settings()
    if seed is not None:
        settings = replace(settings, seed=seed)
    plan = RingdownPlan(round(settings.response.resonance_frequency), tuple(float(v) for v in voltages), cycles, samples,
                        capture_interval(interval))
    station, _ = simulated_station(settings, settle_time=0.0)
    return ringdown(station, path, plan, metadata=simulation_metadata(settings), restart=restart, fsync=False)
