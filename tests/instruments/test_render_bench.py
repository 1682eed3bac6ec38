"""The 33500's arbitrary-waveform amplitude modulation in the driver and the simulator, and a texture played on the
simulated bench: the plate answers with the envelope the model predicts, pre-compensation beats plain switching."""

import numpy as np
import pytest

from instruments.drivers.amplifier import PowerAmplifier
from instruments.drivers.arbitrary import MAX_POINTS, ModulatedDrive, arb_file_text, dac_codes, drive_of_codes
from instruments.drivers.base import MAX_LINE_BYTES
from instruments.drivers.errors import SafetyLimitError
from instruments.drivers.generator import modulation_script
from instruments.drivers.lockin import capture_interval
from instruments.procedures.capture import CaptureWindow
from instruments.procedures.render import play_and_capture
from instruments.procedures.simulated import simulated_station
from instruments.simulator.bench import default_bench_settings
from instruments.simulator.generator import GeneratorDevice
from instruments.simulator.physics import default_law
from workflow import logformat
from workflow.damping.envelope import EnvelopeModel, envelope_at
from workflow.pipeline.render_logs import compare_log, measure_rendering, read_render_log
from workflow.pipeline.rendering import PlateEnvelope
from workflow.rendering.synthesis import render
from workflow.rendering.textures import ConstantSpeed, Grating
from workflow.units import MM, UM

def _errors(device: GeneratorDevice) -> list:
    errors = []
    while (error := device.handle_line("SYST:ERR?")) != '+0,"No error"':
        errors.append(error.split(",")[0])
    return errors


def test_the_simulated_generator_loads_selects_and_modulates_with_an_arbitrary_waveform():
    device = GeneratorDevice(peak_voltage_limit=3.0)
    codes = ",".join(str(c) for c in (-32767, 0, 32767, 0, -32767, 0, 32767, 0))
    device.handle_line(f"DATA:ARB:DAC tex1, {codes};:DATA:ARB Tex2, 0.5,0.5,-1,1,0,0,0,0.25")
    assert device.handle_line("DATA:VOL:CAT?") == '"TEX1","TEX2"'
    device.handle_line('FUNC:ARB "TEX2";:FUNC:ARB:SRAT 1e4;:FUNC:ARB:FILT STEP;:AM:SOUR INT;:AM:INT:FUNC ARB')
    device.handle_line("SOUR1:AM:DEPTh 100;:SOUR1:AM:STAT ON;:OUTP:LOAD INF;:OUTP ON")
    assert device.handle_line("FUNC:ARB?;:FUNC:ARB:SRAT?;:AM:STAT?;:AM:INT:FUNC?;:AM:DEPT?") == \
        '"TEX2";+1.00000000000000E+04;1;ARB;+1.00000000000000E+02'
    waveform, rate = device.modulation()
    assert rate == 1e4 and waveform[:3] == pytest.approx([0.5, 0.5, -1.0])
    assert _errors(device) == []


@pytest.mark.parametrize("line, code", [
    ("DATA:ARB:DAC 1ABC, 0,0,0,0,0,0,0,0", "-224"),        # a name starts with a letter
    ("DATA:ARB:DAC ABC, 0,0,0,0,0,0,0", "-222"),           # at least 8 points
    ("DATA:ARB:DAC ABC, 0,0,0,0,0,0,0,40000", "-222"),     # codes within +-32767
    ("DATA:ARB:DAC ABC, 0,0,0,0,0,0,0,0.5", "-104"),       # codes are integers
    ("DATA:ARB ABC, 0,0,0,0,0,0,0,1.5", "-222"),           # values within +-1
    ("FUNC:ARB NOSUCH", "-224"),
    ("AM:INT:FUNC NOIS", "-224"),
    ("AM:SOUR EXT", "-224"),                               # not simulated
    ("AM:DEPT 130", "-222"),
    ("AM:INT:FUNC ARB;:AM:STAT ON", "-221"),               # no waveform selected
])
def test_the_simulated_generator_refuses_bad_waveforms_with_the_33500s_errors(line, code):
    device = GeneratorDevice(peak_voltage_limit=3.0)
    device.handle_line(line)
    assert _errors(device) == [code]


def test_a_depth_above_100_percent_counts_against_the_limit_at_every_layer():
    device = GeneratorDevice(peak_voltage_limit=1.5)
    device.handle_line("OUTP:LOAD INF;:VOLT 2.9;:AM:STAT ON")  # peak 1.45 V at 100 % depth
    device.handle_line("AM:DEPT 120")                           # would raise it to 1.6 V
    assert _errors(device) == ["-222"] and device.state.am_depth == 100.0
    station, _ = simulated_station(default_bench_settings(), settle_time=0.0)
    with pytest.raises(SafetyLimitError):
        station.generator.write("AM:DEPT 120")
    with pytest.raises(SafetyLimitError):
        station.generator.am_depth = 110
    with pytest.raises(SafetyLimitError):
        station.generator.write("SOUR1:AM 50")
    drive = ModulatedDrive(tuple(dac_codes(np.linspace(0, 31, 8), 31.0)), 1e4, 32e3, PowerAmplifier().generator_vpp(31.0))
    with pytest.raises(SafetyLimitError):
        station.generator.play_modulated(drive)


def test_a_drive_becomes_dac_codes_an_arb_file_and_one_line_per_command():
    drive = np.array([0.0, 7.5, 15.0, 30.0, 22.5, 30.0, 0.0, 1.0])
    codes = dac_codes(drive, 30.0)
    assert list(codes[:4]) == [-32767, -16384, 0, 32767]
    assert drive_of_codes(codes, 30.0) == pytest.approx(drive, abs=30.0 / 32767)
    with pytest.raises(ValueError):
        dac_codes(drive, 20.0)
    text = arb_file_text(codes, 12500.0)
    assert text.startswith("File Format:1.10\r\n") and 'Data Type:"short"' in text and "Sample Rate:12500" in text
    assert text.split("Data:\r\n")[1].split() == [str(c) for c in codes]
    longest = ModulatedDrive((-32767,) * MAX_POINTS, 1e4, 25e3, 1.0, name="ABCDEFGHIJKL")
    assert max(len(line) for line in modulation_script(longest)) <= MAX_LINE_BYTES
    with pytest.raises(ValueError, match="512 samples"):
        ModulatedDrive((0,) * (MAX_POINTS + 1), 1e4, 25e3, 1.0)


@pytest.fixture(scope="module")
def design_bench():
    """The simulated bench playing the h_p = 1 mm design (beam model) with a softening resonance, and its truth
    as an envelope model."""
    from workflow.models.plate import ORIGINAL_PLATE

    plate = ORIGINAL_PLATE.with_(wavelength=20.5354 * MM, resonator_thickness=0.7124 * MM)
    settings = default_bench_settings(plate, default_law(plate), softening=0.08)
    response = settings.response
    truth = EnvelopeModel(response.resonance_frequency, response.deflection_per_volt, response.law, response.softening)
    return settings, truth


def test_the_simulated_plate_answers_a_modulated_drive_as_the_envelope_model_predicts():
    """The lock-in's capture of a modulated drive, its times corrected for the filter's delay, is the envelope the
    model predicts (the filter rounds the envelope's kinks over a few of its 10 us time constants: 1 % at most)."""
    settings = default_bench_settings(drift_rate=0.0, relative_noise=0.0, floor_fraction=0.0, phase_noise=0.0,
                                      heating=False)
    quiet = settings.response
    model = EnvelopeModel(quiet.resonance_frequency, quiet.deflection_per_volt, quiet.law)
    rendering = render(model, Grating(2 * MM, 0.5, 0.3 * UM, 1.15 * UM), ConstantSpeed(0.1), 30.0, max_points=256)
    drive = ModulatedDrive(tuple(dac_codes(rendering.drive, 30.0)), 1 / rendering.interval, float(rendering.model.carrier),
                           PowerAmplifier().generator_vpp(30.0))
    station, bench = simulated_station(settings)
    station.prepare()
    window = CaptureWindow.after(capture_interval(rendering.duration / 128, at_least=True), 0.0, 128)
    record = play_and_capture(station, drive, window, settle=0.2)
    assert _errors(bench.generator) == []
    boundaries = rendering.velocity(np.append(rendering.envelope, rendering.envelope[0]))
    predicted = np.abs(envelope_at(rendering.model, rendering.drive, rendering.interval, boundaries,
                                   np.mod(record.time, rendering.duration)))
    assert np.max(np.abs(record.amplitude - predicted)) < 0.012 * np.max(predicted)
    assert np.sqrt(np.mean((record.amplitude - predicted) ** 2)) < 2e-3 * np.max(predicted)


def _measure(bench, path, restart=True):
    settings, truth = bench
    station, _ = simulated_station(settings, settle_time=0.0)
    texture, motion = Grating(2 * MM, 0.5, 0.3 * UM, 1.15 * UM), ConstantSpeed(0.1)
    return measure_rendering(station, path, texture, motion, PlateEnvelope(truth, "the simulator's truth"),
                             settings.response.resonance_frequency, loops=2, settle=0.2,
                             metadata={"texture_loop_s": 0.02}, restart=restart)


@pytest.fixture(scope="module")
def measured(design_bench, tmp_path_factory):
    path = tmp_path_factory.mktemp("render") / "render.csv"
    return _measure(design_bench, path), path


def test_on_the_bench_precompensation_renders_the_grating_better_than_plain_switching(measured):
    result, path = measured
    assert result.measured == 2 * 256 and result.procedure == "render"
    _, _, comparison = compare_log(path)
    plain, pre = comparison["plain"], comparison["precompensated"]
    assert pre["error"] < 0.75 * plain["error"]
    for c in (plain, pre):
        assert c["model_error"] < 0.03  # the simulator plays the model's own physics, with 0.5 % noise
        assert c["error"] == pytest.approx(c["predicted_error"], abs=0.02)
        assert len(c["contrast"]) == 2
    assert pre["rise_time_ms"] < 0.5 * plain["rise_time_ms"]


def test_the_render_log_holds_texture_model_and_drives(measured):
    _, path = measured
    metadata, playbacks = read_render_log(path)
    assert metadata["procedure"] == "render" and metadata["plan_playbacks"] == "plain,precompensated"
    assert {"model_law", "model_carrier_hz", "plan_precompensated_codes", "texture_loop_s"} <= set(metadata)
    assert [p.name for p in playbacks] == ["plain", "precompensated"]
    assert np.max(playbacks[1].drive) == pytest.approx(30.0, rel=1e-3)
    header = path.read_text().splitlines()
    assert ",".join(logformat.RENDER_COLUMNS) in header


def test_a_render_log_is_not_a_damping_campaign(measured):
    from workflow.damping.logs import read_log
    from workflow.errors import InputFileError

    _, path = measured
    with pytest.raises(InputFileError, match="a render log"):
        read_log(path)


def test_an_interrupted_render_log_resumes_with_the_playback_cut_short(measured, design_bench, tmp_path):
    _, path = measured
    lines = [line for line in path.read_text().splitlines(keepends=True) if not line.startswith("# readout:")]
    cut = tmp_path / "render.csv"
    kept = "".join(lines[:-100])
    cut.write_text(kept + lines[-100][:7])  # the second playback cut short, mid-row
    result = _measure(design_bench, cut, restart=False)
    assert (result.resumed, result.measured) == (256 + 156, 256), "its 156 rows kept, the playback again in full"
    assert cut.read_text().startswith(kept), "no measured row is deleted"
    _, playbacks = read_render_log(cut)
    assert [len(p.time) for p in playbacks] == [256, 256]


@pytest.mark.slow
def test_measure_fit_render_play_on_the_design_renders_the_2mm_grating_within_its_prediction(design_bench, tmp_path):
    """The chain a user runs: a campaign on the simulated h_p = 1 mm design, the Q(v) fit and softening, then the
    2 mm grating at 100 mm/s rendered with the fit (not the truth) and played: pre-compensation beats plain
    switching and the plate follows the prediction."""
    from instruments.procedures.simulated import simulate_campaign
    from workflow.damping.fit import fit_damping, parameter_summary
    from workflow.damping.likelihood import ForwardModel
    from workflow.damping.logs import read_logs

    settings, _ = design_bench
    simulate_campaign(tmp_path / "campaign.csv", settings)
    fit = fit_damping(read_logs([tmp_path / "campaign.csv"]), laws=("quadratic",), seed=1, max_steps=4000,
                      forward=ForwardModel(softening=True))
    summary = parameter_summary(fit.best)
    fitted = EnvelopeModel(summary["f_r_0"]["median"], summary["gain"]["median"], fit.answer.median_law(),
                           summary["kappa"]["median"])
    station, _ = simulated_station(settings, settle_time=0.0)
    result = measure_rendering(station, tmp_path / "render.csv", Grating(2 * MM, 0.5, 0.3 * UM, 1.15 * UM),
                               ConstantSpeed(0.1), PlateEnvelope(fitted, "fit"), settings.response.resonance_frequency,
                               loops=2, settle=0.2, metadata={"texture_loop_s": 0.02})
    _, _, comparison = compare_log(result.path)
    plain, pre = comparison["plain"], comparison["precompensated"]
    assert pre["error"] < 0.7 * plain["error"]
    assert pre["model_error"] < 0.03 and plain["model_error"] < 0.03


@pytest.mark.hardware
def test_a_real_33500_takes_the_modulated_drive():
    """Opt-in (``pytest -m hardware``): the command forms on a real 33500-series generator on
    $TACTILE_GENERATOR_PORT, its output kept off: the waveform loaded and selected, AM by it at 100 %."""
    import os

    import serial

    from instruments.drivers.generator import FunctionGenerator

    port = os.environ.get("TACTILE_GENERATOR_PORT")
    if not port:
        pytest.skip("set TACTILE_GENERATOR_PORT to a real 33500-series generator")
    generator = FunctionGenerator(serial.Serial(port, timeout=2), 0.5)
    try:
        generator.output = False
        generator.play_modulated(ModulatedDrive(tuple(dac_codes(np.linspace(0.0, 1.0, 16), 1.0)), 1e4, 25e3, 0.01))
        generator.check_errors("loading a modulated drive")
        assert generator.am_state and generator.am_function == "ARB" and not generator.output
        assert generator.arb_sample_rate == pytest.approx(1e4) and generator.am_depth == pytest.approx(100.0)
    finally:
        generator.switch_off()
