"""The one error type of the tools."""


class ToolError(Exception):
    """One line for stderr; exit status 1."""
