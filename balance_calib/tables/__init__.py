"""Calibration data tables of other tools (BALFIT-style CSV, interfaces.md): reader, writer,
units.
"""
