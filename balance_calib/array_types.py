"""The numpy array type of the package's annotations: one alias, used everywhere.

`FloatArray` is a float64 array of any shape (loads in N / N·m, outputs in mV, coefficients);
inputs that accept lists or scalars as well are annotated `numpy.typing.ArrayLike`.
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

FloatArray: TypeAlias = NDArray[np.float64]
