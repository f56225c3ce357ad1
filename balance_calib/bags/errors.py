"""The one error type of the bag layer."""


class BagError(ValueError):
    """A bag cannot be written or read; the message names the file (and topic) concerned."""
