"""The power amplifier between the generator and the ceramics (docs/instruments.md).

The generator is set in volts peak-to-peak at its output; the ceramics see the
amplifier's voltage gain times the generator's peak voltage.  Logs record the peak
voltage across the ceramics; the safety limit is stated there too.
"""

from dataclasses import dataclass

DEFAULT_GAIN = 10.0
"""Voltage gain of the bench amplifier unless configured otherwise [V/V]."""

DEFAULT_CERAMIC_VOLTAGE_LIMIT = 30.0
"""Safety limit on the peak voltage across the ceramics unless configured otherwise [V].

Twice the design voltage of 15 V: people touch the plate.
"""


@dataclass(frozen=True)
class PowerAmplifier:
    """A linear voltage amplifier.

    Attributes
    ----------
    gain : float
        Voltage gain, ceramic peak voltage / generator peak voltage [V/V].
    """

    gain: float = DEFAULT_GAIN

    def __post_init__(self):
        if not self.gain > 0:
            raise ValueError(f"amplifier gain must be positive, got {self.gain!r}")

    def ceramic_voltage(self, generator_vpp):
        """Peak voltage across the ceramics [V] for a generator setting [V peak-to-peak]."""
        return self.gain * generator_vpp / 2

    def generator_vpp(self, ceramic_voltage):
        """Generator setting [V peak-to-peak] giving a peak voltage across the ceramics [V]."""
        return 2 * ceramic_voltage / self.gain

    def generator_peak_limit(self, ceramic_voltage_limit):
        """Largest generator output peak voltage (amplitude plus |offset|) [V] within the ceramic limit [V]."""
        return ceramic_voltage_limit / self.gain
