"""Arbitrary waveforms of the 33500 series as an amplitude-modulating signal: codes, command lines, .arb files.

A drive envelope V(t) (peak volts across the ceramics, held over each sample) becomes the
33500's amplitude modulation of a sine carrier (docs/rendering.md#on-the-generator): with
100 % depth the output amplitude is the carrier's times (1 + m) / 2, so the modulating
waveform is m = 2 V / V_full - 1 (V_full the carrier's amplitude across the ceramics, the
envelope's largest value), sent as 16-bit DAC codes round(32767 m) with ``DATA:ARB:DAC`` and
played at ``FUNC:ARB:SRAT`` samples per second.  The command forms are those of the Keysight
33500B/33600A programming reference (``DATA:ARBitrary:DAC``, ``DATA:VOLatile:CLEar``,
``FUNCtion:ARBitrary``, ``FUNCtion:ARBitrary:SRATe``, ``FUNCtion:ARBitrary:FILTer``,
``AM:SOURce``, ``AM:INTernal:FUNCtion``, ``AM:DEPTh``, ``AM:STATe``), as PyMeasure's
``Agilent33500`` driver sends them (``data_volatile_clear``, ``data_arb(..., "DAC")``,
``arb_file``, ``arb_srate``, ``arb_filter``).  The whole waveform travels in one command line
of at most :data:`~instruments.drivers.base.MAX_LINE_BYTES`: :data:`MAX_POINTS` samples.

:func:`arb_file_text` writes the same waveform as a 33500 ``.arb`` file (``File Format:1.10``,
``Data Type:"short"``), for ``MMEMory:LOAD:DATA`` or the front panel's USB import.
"""

import math
import re
from dataclasses import dataclass

import numpy as np


DAC_FULL_SCALE = 32767
"""DAC code of +1 (and minus that of -1) of ``DATA:ARB:DAC`` [-]."""
MIN_POINTS = 8
"""Fewest samples of a 33500 arbitrary waveform [-]."""
MAX_POINTS = 512
"""Most samples sent here: ``DATA:ARB:DAC <12-character name>,`` and 512 codes of up to 7 characters fit a
4096-byte line [-]."""
SAMPLE_RATE_RANGE = (1e-6, 250e6)
"""``FUNC:ARB:SRAT`` range of the series [Sa/s] (PyMeasure's bounds; a given model may allow less)."""
NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,11}")
"""A waveform's name in volatile memory: a letter, then up to 11 letters, digits or underscores."""
DEFAULT_NAME = "TACTILE"
"""The name the drives are stored under."""


def dac_codes(drive, full_scale: float) -> np.ndarray:
    """Modulating DAC codes of a drive envelope ``drive`` [V] at 100 % depth, carrier amplitude ``full_scale`` [V].

    Values outside [0, full_scale] are refused (ValueError): clipping belongs to the synthesis.
    """
    drive = np.asarray(drive, dtype=float)
    if not (full_scale > 0 and np.all(np.isfinite(drive)) and np.all((drive >= 0) & (drive <= full_scale * (1 + 1e-12)))):
        raise ValueError(f"a drive envelope must lie within 0 and its full scale {full_scale:g} V")
    return np.round((2 * np.minimum(drive / full_scale, 1.0) - 1) * DAC_FULL_SCALE).astype(int)


def drive_of_codes(codes, full_scale: float) -> np.ndarray:
    """The drive envelope [V] that DAC ``codes`` play at 100 % depth with the carrier amplitude ``full_scale`` [V]."""
    return full_scale * (1 + np.asarray(codes, dtype=float) / DAC_FULL_SCALE) / 2


@dataclass(frozen=True)
class ModulatedDrive:
    """A sine carrier amplitude-modulated by an arbitrary waveform, as the 33500 plays it.

    Attributes
    ----------
    codes : tuple of int
        The modulating waveform's DAC codes, :data:`MIN_POINTS` to :data:`MAX_POINTS` of them.
    sample_rate : float
        Samples per second [Sa/s].
    carrier_frequency : float
        [Hz]
    amplitude_vpp : float
        Carrier amplitude at the generator, the output's amplitude at m = +1 [V peak-to-peak].
    name : str
        The waveform's name in volatile memory.
    """

    codes: tuple
    sample_rate: float
    carrier_frequency: float
    amplitude_vpp: float
    name: str = DEFAULT_NAME

    def __post_init__(self):
        if not NAME.fullmatch(self.name):
            raise ValueError(f"waveform name {self.name!r}: a letter, then up to 11 letters, digits or underscores")
        if not MIN_POINTS <= len(self.codes) <= MAX_POINTS:
            raise ValueError(f"an arbitrary waveform has {MIN_POINTS} to {MAX_POINTS} samples here, got {len(self.codes)}")
        if not all(isinstance(c, (int, np.integer)) and abs(c) <= DAC_FULL_SCALE for c in self.codes):
            raise ValueError(f"DAC codes are integers from -{DAC_FULL_SCALE} to {DAC_FULL_SCALE}")
        if not SAMPLE_RATE_RANGE[0] <= self.sample_rate <= SAMPLE_RATE_RANGE[1]:
            raise ValueError(f"sample rate {self.sample_rate:g} Sa/s outside {SAMPLE_RATE_RANGE[0]:g} to "
                             f"{SAMPLE_RATE_RANGE[1]:g} Sa/s")
        if not (math.isfinite(self.carrier_frequency) and self.carrier_frequency > 0):
            raise ValueError(f"carrier frequency must be positive, got {self.carrier_frequency!r}")
        if not (math.isfinite(self.amplitude_vpp) and self.amplitude_vpp > 0):
            raise ValueError(f"carrier amplitude must be positive, got {self.amplitude_vpp!r} Vpp")

    @property
    def period(self) -> float:
        """Duration of one pass of the waveform [s]."""
        return len(self.codes) / self.sample_rate

    def setup_commands(self) -> list:
        """The lines that load the waveform and modulate the carrier with it (no level, no output switching).

        Modulation off first (volatile memory in use cannot be cleared), the carrier, the waveform
        into cleared volatile memory, selected with its sample rate and the STEP filter (each
        sample held), then internal AM by it at 100 % depth.
        """
        return [
            "AM:STAT OFF",
            "FUNC SIN",
            f"FREQ {self.carrier_frequency:.12g}",
            "DATA:VOL:CLE",
            f"DATA:ARB:DAC {self.name}," + ",".join(str(int(code)) for code in self.codes),
            f"FUNC:ARB {self.name}",
            f"FUNC:ARB:SRAT {self.sample_rate:.12g}",
            "FUNC:ARB:FILT STEP",
            "AM:SOUR INT",
            "AM:INT:FUNC ARB",
            "AM:DEPT 100",
            "AM:STAT ON",
        ]


def arb_file_text(codes, sample_rate: float) -> str:
    """A 33500 ``.arb`` file of DAC ``codes`` played at ``sample_rate`` [Sa/s], levels +-1 V (as a modulating
    waveform only its shape and rate count)."""
    header = [
        "File Format:1.10",
        "Checksum:0",
        "Channel Count:1",
        f"Sample Rate:{sample_rate:.12g}",
        "High Level:1.000000",
        "Low Level:-1.000000",
        'Data Type:"short"',
        'Filter:"STEP"',
        f"Data Points:{len(codes)}",
        "Data:",
    ]
    return "\r\n".join(header + [str(int(code)) for code in codes]) + "\r\n"

