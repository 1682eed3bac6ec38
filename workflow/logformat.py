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
"""Measurement point along the plate's length, from its centre [mm] (column of a scan; metadata when constant)."""
Y_POSITION = "y_mm"
"""Measurement point across the plate, from its centre [mm]."""
SCAN_COLUMNS = COLUMNS + (X_POSITION, Y_POSITION)
"""The columns of a deflection scan, in this order."""

LAMBDA_MM = "lambda_mm"
"""Metadata: the built plate's nominal wavelength [mm]."""
HI_MM = "h_i_mm"
"""Metadata: nominal resonator thickness [mm]."""
HP_MM = "h_p_mm"
"""Metadata: nominal ceramic thickness [mm]."""
B_MM = "b_mm"
"""Metadata: nominal width [mm]."""
CERAMIC = "ceramic"
"""Metadata: ceramic material record name (optional)."""
RESONATOR = "resonator"
"""Metadata: resonator material record name (optional)."""
GLUE_UM = "glue_um"
"""Metadata: nominal bond thickness [um] (optional)."""
BUILT_PLATE_KEYS = (LAMBDA_MM, HI_MM, HP_MM, B_MM)
"""The metadata keys every built-plate log has."""
