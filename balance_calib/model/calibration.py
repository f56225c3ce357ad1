"""A calibration: the fitted models of one balance, with its capacities and rated outputs.

What `balance_calibrator` loads and `refit` and `fit` write as calibration.yaml; reading and
writing the file (and taking a balance config as a calibration) is calibration_file.py's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import datetime as _dt
from typing import Any, Mapping

import numpy as np

from ..errors import ConfigError
from ..plain_data import plain_data as _plain
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .balance_model import BalanceModel

FORMAT = 'balance_calib/calibration 1'

# Extra model variables and the live input each needs.
VARIABLE_INPUTS = {
    'dT': 'temperature',
    'dT2': 'temperature',
    'dir_FX': 'load_history',
    'dir_FY': 'load_history',
    'dir_FZ': 'load_history',
    'dir_MX': 'load_history',
    'dir_MY': 'load_history',
    'dir_MZ': 'load_history',
}


@dataclass(frozen=True)
class Calibration:
    """The fitted models of one balance, the one adopted, and the balance's capacities (N, N·m)
    and rated outputs (mV) per component and bridge output.
    """

    balance: str
    models: Mapping[str, BalanceModel]  # by name: 'linear', ..., 'cubic+temperature'
    adopted: str  # the model to use when the node asks for 'adopted'
    base_model: str  # the TM-663 model the adopted one builds on
    capacity: np.ndarray  # full scale per component
    rated_output_mv: np.ndarray
    components: tuple[str, ...] = COMPONENTS
    bridge_outputs: tuple[str, ...] = BRIDGE_OUTPUTS
    sigma_pct_fs: Mapping[str, float] = field(default_factory=dict)
    fitted_at: str = ''
    reference_temperature_c: float | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)  # body, source bags, effects...

    def model(self, name: str = 'adopted') -> BalanceModel:
        key = self.adopted if name in ('adopted', '') else name
        if key not in self.models:
            raise ConfigError(
                f'calibration of {self.balance} has no {key!r} model '
                f'(it has {", ".join(self.models)})'
            )
        return self.models[key]

    def requires(self, name: str = 'adopted') -> tuple[str, ...]:
        """Live inputs the model needs besides the bridge outputs: 'temperature',
        'load_history'.
        """
        needed = []
        for variable in self.model(name).extra_variables:
            kind = VARIABLE_INPUTS.get(variable) or self.channel_input(variable) or variable
            if kind not in needed:
                needed.append(kind)
        return tuple(needed)

    def channel_input(self, variable: str) -> str | None:
        """The live input a table channel's variable needs: 'temperature' for a temperature
        channel (its d<SYMBOL> is dT), the channel's symbol for any other; None if not one.
        """
        for symbol, entry in ((self.extra or {}).get('channels') or {}).items():
            if entry.get('variable', f'd{symbol}') == variable:
                return 'temperature' if entry.get('kind') == 'temperature' else str(symbol)
        return None

    def temperature_variables(self) -> dict[str, str]:
        """{d<SYMBOL>: 'dT'} for a table's temperature channel: the live calibrator evaluates it
        as the bag calibrations' dT (°C from /balance/temperature less the reference).
        """
        return {
            str(entry.get('variable', f'd{symbol}')): 'dT'
            for symbol, entry in ((self.extra or {}).get('channels') or {}).items()
            if entry.get('kind') == 'temperature'
        }

    @property
    def output_unit(self) -> str:
        """The unit of the bridge outputs the models take: mV, or what a table gave that has no
        conversion to mV (counts, -, mV/V without the excitation), as `fit` records it.
        """
        return str((self.extra or {}).get('output_unit', 'mV'))

    @property
    def fitted_datetime(self) -> _dt.datetime | None:
        try:
            return _dt.datetime.fromisoformat(self.fitted_at)
        except (TypeError, ValueError):
            return None

    def to_dict(self) -> dict[str, Any]:
        return {
            'format': FORMAT,
            'balance': self.balance,
            'fitted_at': self.fitted_at,
            'adopted_model': self.adopted,
            'base_model': self.base_model,
            'components': list(self.components),
            'bridge_outputs': list(self.bridge_outputs),
            'capacity': {c: float(v) for c, v in zip(self.components, self.capacity)},
            'rated_output_mv': {
                c: float(v) for c, v in zip(self.bridge_outputs, self.rated_output_mv)
            },
            'reference_temperature_c': self.reference_temperature_c,
            'sigma_pct_fs': {k: float(v) for k, v in self.sigma_pct_fs.items()},
            **({'extra': _plain(self.extra)} if self.extra else {}),
            'models': {
                name: {k: v for k, v in m.to_dict().items() if k not in ('components', 'inputs')}
                for name, m in self.models.items()
            },
        }
