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

X_POSITION = "x_mm"
"""Measurement point along the plate's length, from its centre [mm] (column, or metadata when constant)."""
Y_POSITION = "y_mm"
"""Measurement point across the width, from the centre [mm] (column, or metadata when constant)."""
WAVELENGTH = "lambda_mm"
"""Metadata: the measured plate's nominal wavelength [mm] (maps the measurement point onto the mode)."""
DECAY_TIME = "decay_time_s"
"""Ring-down logs: time since the end of the burst [s]; its presence makes a log a ring-down log."""
TEMPERATURE = "temperature_c"
"""Plate temperature where the bench reports it [deg C] (optional)."""

POSITION_COLUMNS = (X_POSITION, Y_POSITION)
RINGDOWN_COLUMNS = (SWEEP, TIMESTAMP, DECAY_TIME, FREQUENCY, DRIVE_VOLTAGE, VELOCITY, TEMPERATURE)
"""The columns of a ring-down log (``sweep`` is the burst id), in the order our writer emits them."""
READ_COLUMNS = COLUMNS + POSITION_COLUMNS + (DECAY_TIME, TEMPERATURE)
"""Every column the reader knows."""
