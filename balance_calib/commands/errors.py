"""The one error a sub-command raises for bad input."""


class CommandError(Exception):
    """Bad input: printed as one line on stderr by balance-calib, exit status 2."""
