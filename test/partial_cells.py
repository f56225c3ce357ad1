"""Hand-made partial cells (3 and 5 components) for the partial-calibration tests
(test_live_partial_calibration, test_ros_partial_calibration): their tables as a small laboratory
writes them, fitted by `balance-calib fit --axes`, and raw samples of their bridges.
"""

from dataclasses import dataclass

import numpy as np

from balance_calib.cli import main
from balance_calib.units import COMPONENTS


@dataclass(frozen=True)
class Cell:
    """A hand-made n-component cell: outputs (mV) = K · loads (N, N·m) + noise, small
    interactions.
    """

    axes: tuple[str, ...]  # the TM-663 components it measures (fit --axes)
    symbols: tuple[str, ...]  # the laboratory's own load symbols
    units: tuple[str, ...]
    k_mv: np.ndarray  # (n, n) mV per N or N·m
    capacity: np.ndarray  # (n,) N, N·m
    natural_zero_mv: np.ndarray  # (n,)
    noise_mv: float = 2.0e-5  # output noise, standard deviation

    @property
    def slots(self) -> list[int]:
        """The places of its components in FX..MZ (and of its bridges in FXV..MZV)."""
        return [COMPONENTS.index(a) for a in self.axes]

    @property
    def absent_slots(self) -> list[int]:
        return [i for i in range(6) if i not in self.slots]

    @property
    def sigma_load(self) -> np.ndarray:
        """Loads from the output noise alone (first principles): δL = K⁻¹ δV, per component."""
        return np.sqrt(((np.linalg.inv(self.k_mv) * self.noise_mv) ** 2).sum(axis=1))


THREE = Cell(
    ('FZ', 'MX', 'MY'),
    ('N', 'RM', 'PM'),
    ('N', 'N-m', 'N-m'),
    np.array([[4.0e-3, 3.0e-4, -2.0e-4], [1.0e-4, 5.0e-2, 2.0e-3], [-3.0e-4, 1.0e-3, 3.5e-2]]),
    np.array([500.0, 40.0, 60.0]),
    np.array([0.012, -0.008, 0.020]),
)
# five components (no axial force), the moments in N-mm as the lab writes them
FIVE = Cell(
    ('FY', 'FZ', 'MX', 'MY', 'MZ'),
    ('Y', 'N', 'RM', 'PM', 'YM'),
    ('N', 'N', 'N-mm', 'N-mm', 'N-mm'),
    np.array(
        [
            [6.0e-3, 2.0e-4, 1.0e-4, -3.0e-4, 9.0e-4],
            [-1.0e-4, 4.0e-3, 2.0e-4, 5.0e-4, 0.0],
            [3.0e-4, -2.0e-4, 5.0e-2, 1.0e-3, -4.0e-4],
            [0.0, 6.0e-4, -8.0e-4, 3.5e-2, 2.0e-4],
            [7.0e-4, 0.0, 3.0e-4, -1.2e-3, 4.5e-2],
        ]
    ),
    np.array([300.0, 500.0, 40.0, 60.0, 30.0]),
    np.array([0.01, -0.02, 0.0, 0.015, 0.005]),
)
# the 3-component cell's figures, for the DDS test
K_MV, CAPACITY, SLOTS, ABSENT = THREE.k_mv, THREE.capacity, THREE.slots, ('FX', 'FY', 'MZ')
SIGMA_LOAD = THREE.sigma_load


def cell_table_text(rng, cell: Cell = THREE) -> str:
    """A one-axis-at-a-time deadweight calibration as a small laboratory writes it: 2 series per
    axis (two fixture orientations, each with its own tare) of 7 points, natural zeros at two roll
    angles, in the lab's units and symbols. Loads and capacities in the file's units.
    """
    n = len(cell.axes)
    per_si = np.array([1e-3 if u == 'N-mm' else 1.0 for u in cell.units])  # file unit -> SI
    rows = []
    for series, axis in enumerate(list(range(n)) * 2, 1):
        tare = rng.uniform(-0.04, 0.04, n) * cell.capacity
        for step, fraction in enumerate(np.linspace(-1.0, 1.0, 7)):
            applied = np.zeros(n)
            applied[axis] = fraction * cell.capacity[axis]
            outputs = (
                cell.k_mv @ (applied + tare)
                + rng.normal(0.0, cell.noise_mv, n)
                + cell.natural_zero_mv
            )
            cells = [repr(float(v)) for v in np.r_[applied / per_si, outputs]]
            rows.append(f',S{series}-{step + 1},{series},Z,' + ','.join(cells))
    blank = ',' * n
    zero = ','.join(repr(float(v)) for v in cell.natural_zero_mv)
    zeros = [f',NZ{k + 1},Z,{roll}{blank},{zero}' for k, roll in enumerate((0, 180))]
    pad = ',' * (2 * n + 3)
    outputs = [f'r{s}' for s in cell.symbols]
    capacity = ','.join(repr(float(v)) for v in cell.capacity / per_si)
    return (
        '\n'.join(
            [
                f'FILE_TYPE,DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS{pad[1:]}',
                f'BALANCE_NAME,cell-{n}{pad[1:]}',
                f'DESCRIPTION,{n}-component cell{pad[1:]}',
                f'; load and output symbols{pad}',
                ',,,,' + ','.join(cell.symbols + tuple(outputs)),
                f'; units{pad}',
                ',,,,' + ','.join(cell.units + ('mV',) * n),
                f'; capacities{pad}',
                f',,,,{capacity}' + ',' * n,
                f'; natural zeros{pad}',
                *zeros,
                f'; data for analysis{pad}',
                ',Point ID,Series,Set' + ',' * (2 * n),
                *rows,
            ]
        )
        + '\n'
    )


def fit_cell(directory, seed: int = 5, cell: Cell = THREE):
    """The table written, then `balance-calib fit --axes ...` with a hand-written linear term file:
    the calibration.yaml path.
    """
    (directory / 'cell.csv').write_text(cell_table_text(np.random.default_rng(seed), cell))
    bridges = ', '.join(f'{a}V' for a in cell.axes)
    (directory / 'linear.terms').write_text(f'# the linear model of the cell\n{bridges}\n')
    assert (
        main(
            [
                'fit',
                str(directory / 'cell.csv'),
                '--out',
                str(directory / 'fit'),
                '--axes',
                ','.join(cell.axes),
                '--method',
                'direct',
                '--terms',
                str(directory / 'linear.terms'),
                '--no-plots',
            ]
        )
        == 0
    )
    return directory / 'fit' / 'calibration.yaml'


def raw_samples(rng, loads, cell: Cell = THREE) -> np.ndarray:
    """Raw /balance/raw rows (N, 6) for loads (N, n): the cell's bridges in their slots, unrelated
    numbers in the others (a DAQ's unused inputs), which the calibration must ignore.
    """
    raw = rng.uniform(-5.0, 5.0, (len(loads), 6))
    raw[:, cell.slots] = loads @ cell.k_mv.T
    return raw
