"""Check loads and the comparison of two calibrations: is a calibration still good, did the balance
change (interfaces.md, "Check loads, and comparing two calibrations").
"""
