"""The one error a table calibration raises: one line naming the file and what is wrong."""

from __future__ import annotations


class TableCalibrationError(ValueError):
    """The table cannot be calibrated as asked; one line saying why."""
