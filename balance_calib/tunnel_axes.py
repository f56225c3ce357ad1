"""Wind-on use, TM-663 §10.2: loads and outputs in the tunnel axis system.

An installation is a signed permutation: tunnel component i = sign_i x balance component perm_i.
§10.2.1 (balance mounted as calibrated, Fig. 11.1 -> 11.2): F_X = -F_X̄, F_Z = -F_Z̄, others equal.
§10.2.2 (mounted rolled 180°, Fig. 11.1 -> 11.3): F_X, F_Y, M_Y, M_Z change sign.
The same map applies to the bridge outputs (F_XV = -F_X̄V, ...), so eqs. (50)-(85) are
`to_tunnel(model(from_tunnel(outputs_tunnel)))`. Another installation is a config string such as
"-FX,FY,-FZ,MX,MY,MZ".
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .array_types import FloatArray
from .units import COMPONENTS


@dataclass(frozen=True)
class Installation:
    name: str
    permutation: tuple[int, ...]  # tunnel component i comes from balance component permutation[i]
    signs: tuple[float, ...]

    def __post_init__(self) -> None:
        if sorted(self.permutation) != list(range(len(self.permutation))) or len(
            self.signs
        ) != len(self.permutation):
            raise ValueError(f'installation {self.name}: not a signed permutation')
        if len(self.permutation) == 6 and (sorted(self.permutation[:3]) != [0, 1, 2]):
            raise ValueError(
                f'installation {self.name}: forces must map to forces and moments to moments'
            )

    def to_tunnel(self, balance_values: ArrayLike) -> FloatArray:
        """Balance-axis loads (or outputs) (..., 6) -> tunnel axes."""
        values = np.asarray(balance_values, dtype=np.float64)
        permutation, signs = self._arrays
        return values.take(permutation, axis=-1) * signs

    @cached_property
    def _arrays(self) -> tuple[NDArray[np.intp], FloatArray]:
        return np.array(self.permutation, dtype=np.intp), np.array(self.signs, dtype=float)

    def from_tunnel(self, tunnel_values: ArrayLike) -> FloatArray:
        """Tunnel-axis loads (or outputs) -> balance axes (the inverse map)."""
        values = np.asarray(tunnel_values, dtype=float)
        result = np.empty_like(values)
        result[..., list(self.permutation)] = values * np.asarray(self.signs)
        return result

    @property
    def spec(self) -> str:
        return ','.join(
            ('-' if s < 0 else '') + COMPONENTS[p] for p, s in zip(self.permutation, self.signs)
        )


IDENTITY = Installation('balance', tuple(range(6)), (1.0,) * 6)
UPRIGHT = Installation('upright', tuple(range(6)), (-1.0, 1.0, -1.0, 1.0, 1.0, 1.0))  # §10.2.1
INVERTED = Installation('inverted', tuple(range(6)), (-1.0, -1.0, 1.0, 1.0, -1.0, -1.0))  # §10.2.2
NAMED = {'upright': UPRIGHT, 'inverted': INVERTED, 'balance': IDENTITY, 'none': IDENTITY}


def parse_installation(spec: str) -> Installation:
    """'upright' (§10.2.1), 'inverted' (§10.2.2), 'balance' (no change) or e.g.
    '-FX,FY,-FZ,MX,MY,MZ'.
    """
    key = spec.strip().lower()
    if key in NAMED:
        return NAMED[key]
    parts = [p.strip().upper() for p in spec.split(',')]
    if len(parts) != 6:
        raise ValueError(
            f'installation {spec!r}: expected upright, inverted, or six signed components '
            f'like "-FX,FY,-FZ,MX,MY,MZ"'
        )
    signs, perm = [], []
    for p in parts:
        sign = -1.0 if p.startswith('-') else 1.0
        name = p.lstrip('+-')
        if name not in COMPONENTS:
            raise ValueError(f'installation {spec!r}: unknown component {name!r}')
        signs.append(sign)
        perm.append(COMPONENTS.index(name))
    return Installation(spec, tuple(perm), tuple(signs))
