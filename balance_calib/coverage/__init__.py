"""Does a calibration cover a run's loads, and which points would make it: predicted uncertainty
over a run (run.py), the schedule's support (support.py), design of added points (design.py).
"""
