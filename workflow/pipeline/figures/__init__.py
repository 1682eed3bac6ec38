"""Figures: functions that take result objects and return matplotlib Figures (no file I/O)."""
