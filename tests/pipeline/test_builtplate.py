"""Built plates on the bench: log metadata, the simulated built plate, the scanner, deflection scans and their MAC."""

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from instruments.drivers.errors import ConnectionLost, InstrumentError
from instruments.procedures.logwriter import read_log
from instruments.procedures.scan import ScanPlan, deflection_scan, grid_points
from instruments.procedures.simulated import reopened_station, simulated_station, simulation_metadata
from instruments.procedures.sweeps import ResonancePlan, resonance_search
from instruments.simulator import FaultSettings, default_bench_settings
from instruments.simulator.bench import built_bench_settings
from instruments.simulator.builtplate import built_plate_model
from workflow import logformat
from workflow.cli import main
from workflow.errors import InputFileError
from workflow.models.builtplate import DEMONSTRATION_DEVIATIONS, BuiltPlate, PlateDeviations, deviated_plate
from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.probes import antinode_probe_points
from workflow.models.fem.surface import modal_assurance_criterion
from workflow.models.plate import ORIGINAL_PLATE
from workflow.pipeline.builtplate import read_built_plate, read_scan, scan_mac

MESH = FemSettings(elements_per_ceramic=4, elements_across_half_width=4)
"""A coarse mesh: the tests compare models on the same mesh."""
DESIGN = ORIGINAL_PLATE.with_(wavelength=20.56e-3, resonator_thickness=0.75e-3, ceramic_thickness=1.0e-3)
"""A plate designed for about 25 kHz (the paper's P1 geometry, as an input)."""


@pytest.fixture(scope="module")
def nominal():
    return built_plate_model(DESIGN, PlateDeviations(), MESH)


@pytest.fixture(scope="module")
def built():
    return built_plate_model(DESIGN, DEMONSTRATION_DEVIATIONS, MESH)


def write_log(path: Path, metadata: dict, rows: str = "25000,2,0.01,0,0,0\n") -> Path:
    lines = ["# tactile interferometer log"] + [f"# {key}: {value}" for key, value in metadata.items()]
    path.write_text("\n".join(lines) + "\n" + ",".join(logformat.COLUMNS) + "\n" + rows)
    return path


def test_built_plate_metadata_round_trip(tmp_path):
    plate = BuiltPlate(20.56e-3, 0.75e-3, 1.0e-3, 49e-3, "PZT-5A", "paper", 35e-6)
    again = read_built_plate(write_log(tmp_path / "p.csv", plate.metadata()))
    assert again.ceramic == "PZT-5A" and again.resonator == "paper"
    assert np.allclose([again.wavelength, again.resonator_thickness, again.ceramic_thickness, again.width, again.glue_thickness],
                       [plate.wavelength, plate.resonator_thickness, plate.ceramic_thickness, plate.width, plate.glue_thickness],
                       rtol=1e-12)
    assert again.plate().ceramic.name == "PZT-5A"
    bare = read_built_plate(write_log(tmp_path / "q.csv", {"lambda_mm": 15.66, "h_i_mm": 0.5, "h_p_mm": 0.5, "b_mm": 49}))
    assert bare.ceramic is None and bare.glue_thickness is None and bare.plate().glue_thickness == 0


@pytest.mark.parametrize("metadata, message", [
    ({"lambda_mm": 20, "h_i_mm": 1, "h_p_mm": 1}, "no '# b_mm: ...' metadata line"),
    ({"lambda_mm": "20 mm", "h_i_mm": 1, "h_p_mm": 1, "b_mm": 49}, "line 2: metadata lambda_mm = '20 mm' is not a finite number"),
    ({"lambda_mm": 20, "h_i_mm": -1, "h_p_mm": 1, "b_mm": 49}, "line 3: h_i_mm = -1 is outside the plausible range 0.05 to 20 mm"),
    ({"lambda_mm": 20, "h_i_mm": 1e-6, "h_p_mm": 1, "b_mm": 49}, "line 3: h_i_mm = 1e-06 is outside the plausible range"),
    ({"lambda_mm": 1e6, "h_i_mm": 1, "h_p_mm": 1, "b_mm": 49}, "line 2: lambda_mm = 1e[+]06 is outside the plausible range"),
    ({"lambda_mm": 20, "h_i_mm": 1, "h_p_mm": 1, "b_mm": 49, "ceramic": "PZT-9"}, "line 6: ceramic 'PZT-9' is not a material record"),
    ({"lambda_mm": 20, "h_i_mm": 1, "h_p_mm": 1, "b_mm": 49, "glue_um": -3}, "line 6: glue_um = -3 is outside the plausible range 0 to 500 um"),
    ({"lambda_mm": 20, "h_i_mm": 1, "h_p_mm": 1, "b_mm": 49, "glue_um": 1e9}, "line 6: glue_um = 1e[+]09 is outside"),
])
def test_built_plate_metadata_errors_name_file_and_line(tmp_path, metadata, message):
    path = write_log(tmp_path / "bad.csv", metadata)
    with pytest.raises(InputFileError, match=message) as error:
        read_built_plate(path)
    assert str(path) in str(error.value)


def test_deviated_plate_scales_the_moduli_and_keeps_d31():
    plate = deviated_plate(DESIGN, replace(DEMONSTRATION_DEVIATIONS, ceramic_modulus_factor=0.9))
    assert plate.ceramic.youngs_modulus == pytest.approx(0.9 * DESIGN.ceramic.youngs_modulus)
    assert plate.ceramic.d31 == pytest.approx(DESIGN.ceramic.d31)
    assert plate.resonator.youngs_modulus == pytest.approx(0.95 * DESIGN.resonator.youngs_modulus)
    assert plate.resonator_thickness == pytest.approx(0.72e-3) and plate.glue_thickness == pytest.approx(40e-6)


def test_surface_modes_match_the_probes(nominal):
    points = antinode_probe_points(DESIGN)
    at_probes = nominal.surface.at(points[:, 0], points[:, 1])
    reference = nominal.result.probe_model
    assert np.max(np.abs(at_probes.probe_shapes - reference.probe_shapes)) < 0.01 * np.max(np.abs(reference.probe_shapes))
    mirrored = nominal.surface.deflection(-points[:, 0], -points[:, 1], nominal.resonance_frequency, 54.0)
    assert modal_assurance_criterion(mirrored, reference.response(nominal.resonance_frequency, 54.0)) > 0.9999


def test_built_plate_resonance_follows_the_fem_of_the_deviated_plate(nominal, built, tmp_path):
    softer = built_plate_model(DESIGN, PlateDeviations(ceramic_modulus_factor=0.9), MESH)
    assert softer.resonance_frequency < nominal.resonance_frequency
    direct = evaluate_fem(deviated_plate(DESIGN, DEMONSTRATION_DEVIATIONS), 54.0, 15.0, MESH)
    assert built.resonance_frequency == pytest.approx(direct.frequency, rel=1e-9)
    assert -0.10 < built.resonance_frequency / nominal.resonance_frequency - 1 < -0.06
    settings = built_bench_settings(built, drift_rate=0.0)
    station, _ = simulated_station(settings, settle_time=0.0)
    found = resonance_search(station, tmp_path / "r.csv", ResonancePlan(15e3, 40e3, 101, 41), simulation_metadata(settings),
                             fsync=False)
    assert found.summary["resonance_frequency_hz"] == pytest.approx(built.resonance_frequency, rel=2e-3)
    assert read_built_plate(tmp_path / "r.csv").wavelength == pytest.approx(DESIGN.wavelength)
    metadata = read_log(tmp_path / "r.csv").metadata
    assert metadata["simulator_deviation_glue_um"] == "40.0"


def test_scanner_commands_and_off_plate_refusal(built):
    station, bench = simulated_station(built_bench_settings(built), settle_time=0.0)
    vibrometer = station.vibrometer
    x_min, x_max, y_min, y_max = vibrometer.scan_range
    assert x_max == pytest.approx(float(DESIGN.length) / 2, abs=1e-7) and y_min == pytest.approx(-24.5e-3)
    vibrometer.move_to(-12.3456e-3, 20e-3)
    assert (vibrometer.position_x, vibrometer.position_y) == (pytest.approx(-12.3456e-3), pytest.approx(20e-3))
    with pytest.raises(InstrumentError, match=r"kept Y at '20.0000' after 'Set,Scanner,0,Y,25.0000'"):
        vibrometer.position_y = 25e-3  # off the plate: the controller ignores it, the read-back says so
    assert bench.vibrometer.position == pytest.approx((-12.3456e-3, 20e-3))
    assert bench.vibrometer.handle_line("Set,Scanner,0,X,abc") is None  # an invalid setting is ignored
    assert bench.vibrometer.position == pytest.approx((-12.3456e-3, 20e-3))
    plain, _ = simulated_station(default_bench_settings(), settle_time=0.0)
    with pytest.raises(InstrumentError, match="Unknown command"):
        plain.vibrometer.position_x = 0.0


def scan_keys(path):
    rows = read_log(Path(path), logformat.SCAN_COLUMNS).rows
    return [(row[logformat.X_POSITION], row[logformat.Y_POSITION]) for row in rows]


def test_interrupted_scan_resumes_without_losing_or_repeating_points(built, tmp_path):
    path = tmp_path / "scan.csv"
    settings = built_bench_settings(built, faults=FaultSettings(disconnect_at=80))
    station, bench = simulated_station(settings, settle_time=0.0)
    plan = ScanPlan(built.resonance_frequency, 5.0, grid_points(built.surface.half_length, built.surface.half_width, 7, 5))
    with pytest.raises(ConnectionLost, match="disconnected"):
        deflection_scan(station, path, plan, simulation_metadata(settings), fsync=False)
    partial = scan_keys(path)
    assert 0 < len(partial) < 35
    with open(path, "a") as file:  # a crash in the middle of a row
        file.write("23000,5,0.1")
    again = reopened_station(station, bench)
    result = deflection_scan(again, path, plan, simulation_metadata(settings), fsync=False)
    assert result.resumed == len(partial) and result.measured == 35 - len(partial)
    final = scan_keys(path)
    assert len(final) == len(set(final)) == 35 and final[: len(partial)] == partial
    other = ScanPlan(built.resonance_frequency, 5.0, plan.points[:-1])
    with pytest.raises(InputFileError, match="plan_points"):
        deflection_scan(again, path, other, fsync=False)


def scan_of(model, frequency, tmp_path, name):
    settings = built_bench_settings(model, drift_rate=0.0)
    station, _ = simulated_station(settings, settle_time=0.0)
    plan = ScanPlan(frequency, 5.0, grid_points(model.surface.half_length, model.surface.half_width, 15, 5))
    deflection_scan(station, tmp_path / name, plan, simulation_metadata(settings), fsync=False)
    return read_scan(tmp_path / name)


def test_mac_is_one_for_the_nominal_plate_and_drops_with_a_transverse_mode(nominal, tmp_path):
    scan = scan_of(nominal, nominal.resonance_frequency, tmp_path, "nominal.csv")
    assert scan.plate.wavelength == pytest.approx(DESIGN.wavelength) and len(scan.x) == 75
    assert scan_mac(scan, nominal) > 0.995
    transverse = max(nominal.result.modes, key=lambda mode: mode.transverse_indicator * (mode.deflection > 0))
    mixed = scan_of(nominal, transverse.frequency, tmp_path, "transverse.csv")
    assert scan_mac(mixed, nominal) < 0.6


def test_mac_of_shapes():
    shape = np.array([1.0, -0.5, 0.2, 0.9])
    assert modal_assurance_criterion(shape * (2 - 3j), shape) == pytest.approx(1.0)
    assert modal_assurance_criterion([1, 1, 0, 0], [1, -1, 0, 0]) == pytest.approx(0.0)
    assert 0 < modal_assurance_criterion(shape + [0, 0.3, 0.3, 0], shape) < 1


def run_cli(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exit:
        code = exit.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_scan_writes_log_figure_and_resumes(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TACTILE_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "scan.csv"
    args = ["measure", "scan", "--simulate", "--lambda-mm", "20.56", "--hi-mm", "0.75", "--hp-mm", "1", "--deviations",
            "none", "--sim-accuracy", "0.05", "--grid", "9", "3", "--coarse-points", "61", "--out", str(out), "--json"]
    code, stdout, err = run_cli(capsys, *args)
    assert code == 0, err
    summary = json.loads(stdout.splitlines()[-1])
    assert summary["measured"] == 27 and summary["mac"] > 0.99 and Path(summary["figure"]).stat().st_size > 10_000
    assert read_built_plate(out).resonator_thickness == pytest.approx(0.75e-3)
    code, stdout, _ = run_cli(capsys, *args)
    assert code == 0 and json.loads(stdout.splitlines()[-1])["resumed"] == 27


@pytest.mark.parametrize("argv, message", [
    ([], "a scan needs the plate"),
    (["--lambda-mm", "20", "--hi-mm", "0.75"], "--hp-mm missing"),
    (["--lambda-mm", "20", "--hi-mm", "0.75", "--hp-mm", "1", "--dev-ceramic-factor", "3"],
     "argument --dev-ceramic-factor: 3 is outside the accepted range 0.5 to 1.5"),
    (["--lambda-mm", "20", "--hi-mm", "0.75", "--hp-mm", "1", "--dev-hi-offset-um", "-800"],
     "resonator_thickness must be a positive finite length"),
    (["--lambda-mm", "20", "--hi-mm", "0.75", "--hp-mm", "1", "--points", "1:2,300:0"], "--points: point \\(300, 0\\) mm is off the plate"),
    (["--lambda-mm", "20", "--hi-mm", "0.75", "--hp-mm", "1", "--points", "1:2,3"], "expected points as x:y"),
])
def test_cli_scan_errors_are_one_line(tmp_path, capsys, argv, message):
    code, _, err = run_cli(capsys, "measure", "scan", "--simulate", "--out", str(tmp_path / "s.csv"), *argv)
    assert code == 2 and err.count("\n") == 1
    assert re.search(message, err)


def test_run_configuration_defaults_to_the_demonstration_deviations():
    from workflow.pipeline.config import default_config
    from workflow.pipeline.domain import built_plate_deviations

    config = default_config()
    deviations = built_plate_deviations(config)
    assert deviations.glue_thickness == pytest.approx(DEMONSTRATION_DEVIATIONS.glue_thickness)
    assert deviations.resonator_thickness_offset == pytest.approx(DEMONSTRATION_DEVIATIONS.resonator_thickness_offset)
    assert deviations.ceramic_offset == pytest.approx(DEMONSTRATION_DEVIATIONS.ceramic_offset)
    config["simulator"]["built_ceramic_factor"] = 0.9
    assert built_plate_deviations(config).ceramic_modulus_factor == 0.9
