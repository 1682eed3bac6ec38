"""The run configuration: defaults, overrides, and errors that name the key."""

import re

import pytest

from workflow.errors import InputFileError
from workflow.models import materials
from workflow.pipeline.config import default_config, load_config, merge, to_toml


def test_design_defaults_come_from_table_1():
    design = default_config()["design"]
    assert design["voltage_v"] == materials.DESIGN_VOLTAGE
    assert design["ceramic_thicknesses_mm"] == [0.5, 1.0, 2.0]
    assert design["target_deflection_um"] == 1.15


def test_printed_configuration_reads_back_identically(tmp_path):
    path = tmp_path / "effective.toml"
    path.write_text(to_toml(default_config()))
    assert load_config(path) == default_config()


def test_a_user_file_overrides_only_its_keys(tmp_path):
    path = tmp_path / "my.toml"
    path.write_text("[design]\nvoltage_v = 12\nceramic_thicknesses_mm = [1.0]\n[maps]\ngrid = 9\n")
    config = load_config(path)
    assert config["design"]["voltage_v"] == 12.0 and isinstance(config["design"]["voltage_v"], float)
    assert config["design"]["ceramic_thicknesses_mm"] == [1.0]
    assert config["maps"]["grid"] == 9
    assert config["design"]["q"] == materials.PLATE_Q


@pytest.mark.parametrize(
    "text, words",
    [
        ("[design]\nvoltag_v = 12\n", "design.voltag_v"),
        ("[desing]\nvoltage_v = 12\n", "[desing]"),
        ('[design]\nvoltage_v = "high"\n', "design.voltage_v"),
        ("[maps]\ngrid = 4.5\n", "maps.grid"),
        ('[fem]\nfine_width_step_mm = "one"\n', "fem.fine_width_step_mm"),
        ('[design]\nceramic_thicknesses_mm = [1.0, "two"]\n', "design.ceramic_thicknesses_mm[1]"),
        ("[design\n", "not valid TOML"),
        ("[damping]\nwalkers = 10001\n", "'damping.walkers' = 10001 is outside the accepted range 0 to 10000"),
        ("[damping]\nwalkers = -3\n", "'damping.walkers' = -3 is outside the accepted range 0 to 10000"),
        ("[damping]\nsoftening = 1\n", "'damping.softening' must be true or false"),
        ("[campaign]\nringdown_samples = 300\n", "'campaign.ringdown_samples' = 300 is outside the accepted range 2 to 256"),
        ("[campaign]\nringdown_interval_us = 0\n", "'campaign.ringdown_interval_us' = 0 is outside the accepted range 1"),
        ("[campaign]\nringdown_voltages_v = [5.0, -1.0]\n", "'campaign.ringdown_voltages_v' = -1.0 is outside the accepted range"),
        ("[simulator]\nsoftening_s2_m2 = -0.1\n", "'simulator.softening_s2_m2' = -0.1 is outside the accepted range 0.0 to 100.0"),
        ('[damping]\nlaws = ["cubic"]\n', "'damping.laws' holds 'cubic'; accepted: 'quadratic', 'linear'"),
        ("[damping]\nlaws = []\n", "'damping.laws' is empty"),
        ("[design]\nceramic_thicknesses_mm = [0.7]\n", "'design.ceramic_thicknesses_mm' holds 0.7; accepted: 0.5, 1.0, 2.0"),
        ("[design]\nmin_frequency_khz = -5.0\n", "'design.min_frequency_khz' = -5.0 is outside the accepted range"),
        ("[design]\nwavelength_min_mm = 40.0\nwavelength_max_mm = 15.0\n", "'design.wavelength_min_mm' = 40.0 must be below"),
        ("[simulator]\nrelative_noise = -0.1\n", "'simulator.relative_noise' = -0.1 is outside the accepted range 0.0 to 1.0"),
        ("[simulator]\nlow_velocity_q = 40.0\n", "'simulator.working_q' = 54.0 must be below 'simulator.low_velocity_q'"),
        ("[campaign]\nvoltages_v = []\n", "'campaign.voltages_v' is empty"),
        ("[fem]\nn_modes = 0\n", "[fem] FEM settings must be positive integers"),
        ('[fem]\nelement = "hex99"\n', "[fem] unknown FEM element 'hex99'"),
        ("[loop]\nscan_grid = [7]\n", "'loop.scan_grid' must be [points along x, points across]"),
        ("[loop]\nreliability = 1.5\n", "'loop.reliability' = 1.5 is outside the accepted range"),
        ("[loop]\nhp_mm = 0.7\n", "'loop.hp_mm' holds 0.7"),
        ("[loop]\nstock_hi_mm = []\n", "'loop.stock_hi_mm' is empty"),
    ],
)
def test_configuration_errors_name_the_key(tmp_path, text, words):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputFileError) as error:
        load_config(path)
    assert words in str(error.value) and str(path) in str(error.value)


def test_too_few_walkers_for_the_logs_is_a_configuration_error_before_the_chain(tmp_path):
    """emcee needs twice the sampled parameters (the flexible law with softening, drift and heating: 15 + one resonance
    per sweep): the step says so, naming the key and the range, before any sampling."""
    from workflow.damping.synthetic import campaign_csv, simulate_campaign
    from workflow.pipeline.runner import RunContext, RunResults
    from workflow.pipeline.steps import damping_fit

    log = tmp_path / "campaign.csv"
    log.write_text(campaign_csv(simulate_campaign(seed=1, voltages=(5.0, 10.0, 15.0), points_per_sweep=25)))
    config = default_config()
    config["damping"]["walkers"] = 15
    context = RunContext(config=config, out=tmp_path, results=RunResults(logs=[log]))
    with pytest.raises(InputFileError, match=r"'damping.walkers' = 15 is outside the accepted range 36 to 10000 .* 3 sweeps"):
        damping_fit(context)


def test_missing_configuration_file_is_named(tmp_path):
    with pytest.raises(InputFileError, match="absent.toml: no such file"):
        load_config(tmp_path / "absent.toml")


def test_an_unknown_material_record_is_refused_at_load(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[design]\nceramic = "PZT-99"\n', encoding="utf-8")
    with pytest.raises(InputFileError, match=r"bad.toml: 'design.ceramic' holds 'PZT-99'; accepted: 'paper', 'PZT-5H'"):
        load_config(path)
    path.write_text('[design]\nresonator = "PZT-5H"\nglue_um = 20.0\n[fem]\npiezo = "coupled"\n', encoding="utf-8")
    with pytest.raises(InputFileError, match="resonator"):
        load_config(path)


def test_the_simulated_deviations_are_declared_once_for_the_configuration_its_ranges_and_the_options():
    """[simulator] built_* keys, their ranges and ``tactile measure``'s --dev-* options all come from
    SIMULATED_DEVIATIONS: the defaults give back the demonstration deviations, each key refuses a value outside its
    quantity's range, and every option exists with that range."""
    import argparse

    from workflow.cli.options import add_built_plate_arguments, deviations_from_args
    from workflow.models.builtplate import DEMONSTRATION_DEVIATIONS, SIMULATED_DEVIATIONS
    from workflow.models.limits import LIMITS
    from workflow.pipeline.domain import built_plate_deviations

    config = default_config()
    assert sorted(k for k in config["simulator"] if k.startswith("built_")) == sorted(s.config_key for s in SIMULATED_DEVIATIONS)
    assert built_plate_deviations(config) == DEMONSTRATION_DEVIATIONS
    parser = argparse.ArgumentParser()
    add_built_plate_arguments(parser)
    for setting in SIMULATED_DEVIATIONS:
        high = LIMITS[setting.quantity][1]
        with pytest.raises(InputFileError, match=re.escape(f"'simulator.{setting.config_key}'")):
            merge(config, {"simulator": {setting.config_key: high * 2 + 1}})
        args = parser.parse_args(["--deviations", "none", setting.option, f"{high:g}"])
        assert getattr(deviations_from_args(args), setting.field) == pytest.approx(high * setting.scale)
