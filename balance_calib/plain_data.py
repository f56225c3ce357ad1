"""Plain Python (dict, list, float, int, str) from numpy-bearing data, for YAML and JSON files."""

from __future__ import annotations

from typing import Mapping

import numpy as np


def plain_data(value: object) -> object:
    """Mappings, sequences and numpy arrays/scalars as plain Python, recursively; keys as str."""
    if isinstance(value, Mapping):
        return {str(k): plain_data(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_data(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain_data(value.tolist())
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value
