"""A calibrator session without ROS for the tare tests (test/live/test_live_tare_*.py): the session
the node drives, built from the parameter table's defaults, and a tare taken on the memo's balance
carrying a model weight.
"""

from pathlib import Path

from live_cases import CAPACITY, NOISE_MV, TRUTH
import numpy as np

from balance_calib.live.parameters import PARAMETERS, STRING_ARRAY
from balance_calib.live.session import CalibratorSession
from balance_calib.simulation.wind_on import wind_on_outputs

# what the balance carries with the model on, balance axes: 0.3 FS on F_Z, 0.05 FS on M_Y
WEIGHT_BALANCE = np.array([0.0, 0.0, 0.3, 0.0, 0.05, 0.0]) * CAPACITY


def session(calibration: Path, node: str = '/balance_calibrator', **parameters):
    values = {
        name: spec.default for name, spec in PARAMETERS.items() if spec.default != STRING_ARRAY
    }
    values.update(calibration_file=str(calibration), tare_samples=50, model='cubic', **parameters)
    lines = []
    made = CalibratorSession(
        values.__getitem__, node, lambda level, line: lines.append((level, line))
    )
    return made, lines


def take_tare(made: CalibratorSession, seed: int = 0):
    outputs = wind_on_outputs(
        TRUTH,
        np.repeat(WEIGHT_BALANCE[None], 50, axis=0),
        electrical_zero_mv=0.0,
        noise_mv=NOISE_MV,
        seed=seed,
    )
    assert made.start_window('tare', lambda: None) is None
    made.live.process(outputs, 10**9 + np.arange(50) * 10**6, now_s=0.0)
    ok, message = made.finish_window('tare', True, 1.0)
    assert ok, message
