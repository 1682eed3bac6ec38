"""Bench instruments: serial drivers, the bench simulator and the measurement procedures.

Layers, one direction: drivers (:mod:`.generator`, :mod:`.vibrometer`, :mod:`.lockin`, over an open
pyserial port) <- procedures (:mod:`.procedures`, writing logs through
:mod:`.logwriter`) <- CLI.  The simulator (:mod:`.simulator`) is only a transport: a
pyserial URL handler (``tactile-sim://``) or pseudo-terminals; drivers never know.
The protocols are documented in ``docs/instruments.md``.
"""
