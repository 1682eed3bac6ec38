"""Interferometer log format, version 1 (docs/log-format.md): the names, once.

UTF-8 CSV.  Optional leading metadata lines ``# key: value`` (the first may be a title
line), then one header row and the data rows.  Readers live in
:mod:`workflow.damping.logs`; the writer in :mod:`instruments.procedures.logwriter`.
"""

FORMAT_VERSION = 1

FREQUENCY = "frequency_hz"
"""Drive frequency [Hz]."""
DRIVE_VOLTAGE = "drive_voltage_v"
"""Peak voltage across the ceramics [V]."""
VELOCITY = "velocity_m_s"
"""Peak velocity amplitude at the measurement point [m/s]."""
SWEEP = "sweep"
"""Integer sweep id (optional)."""
TIMESTAMP = "timestamp_s"
"""Seconds since the start of the campaign (optional)."""
PHASE = "phase_deg"
"""Phase of the velocity relative to the drive [deg] (optional)."""

REQUIRED_COLUMNS = (FREQUENCY, DRIVE_VOLTAGE, VELOCITY)
OPTIONAL_COLUMNS = (SWEEP, TIMESTAMP, PHASE)
COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
"""The columns our writer emits, in this order."""

METADATA_PREFIX = "# "
"""Metadata lines read ``# key: value``."""
