"""ConfigError: a balance config or calibration file that cannot be used.

A leaf module, below config.py and model/ alike: a calibration (model/calibration.py) raises it
without importing the config reader, which itself builds on model/.
"""


class ConfigError(ValueError):
    """A balance or calibration file that cannot be used; the message names file and key."""
