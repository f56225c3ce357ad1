"""Sub-commands of balance-calib, one module each (see cli.py)."""
