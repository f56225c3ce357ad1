"""The rocket thrust stand of the second lab manual (seed 003): one axis, no rclpy.

nozzle.py       isentropic nozzle theory, eqs. (1)-(15)
calibration.py  §4.2: weights -> hysteresis-corrected readings -> line (via fit_model)
line_fit.py     Supplement 2: eqs. (25)-(27) written out
uncertainty.py  Supplement 1 §A1.4: error propagation, eqs. (18)-(21); measured C_F
significant.py  Supplement 1 §A1.3: value ± error with matching digits
analysis.py     measured against theoretical C_F from averaged signals
report.py       the comparison report (JSON + markdown)
"""
