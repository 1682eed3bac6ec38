"""The run configuration: defaults, overrides, and errors that name the key."""

import pytest

from workflow.errors import InputFileError
from workflow.models import materials
from workflow.pipeline.config import default_config, load_config, to_toml


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
    ],
)
def test_configuration_errors_name_the_key(tmp_path, text, words):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputFileError) as error:
        load_config(path)
    assert words in str(error.value) and str(path) in str(error.value)


def test_missing_configuration_file_is_named(tmp_path):
    with pytest.raises(InputFileError, match="no such configuration file"):
        load_config(tmp_path / "absent.toml")
