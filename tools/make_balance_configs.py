#!/usr/bin/env python3
"""Regenerate config/lmc6522.yaml and config/b660h.yaml from NAL TM-663.

Tables 10-16 and Appendices A/B come from the machine-readable extracts in data/tm663 (a copy of
the steering ../shared/data, held equal by test/project/test_memo_data.py; its README says how
they were checked); Tables 1, 3-9 and 17 are short and typed here once, with their table
numbers. The YAML files are what the package installs and reads; this script is their provenance.
    python tools/make_balance_configs.py [--data DIR] [--out-dir DIR]
(defaults: data/tm663 and config/ of this repository).
"""

import argparse
import csv
from itertools import combinations
import json
from pathlib import Path

import yaml

R = 0.5**0.5  # the 45-degree positions 5-8 of Fig. 3
OUT = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')
COMP = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')

MEMO = {
    'LMC6522': {
        'file': 'lmc6522',
        'title': 'LMC-6522-50/Z1000-S (integral balance), NAL TM-663 §6.1, §7, Appendix A',
        'capacity': [980, 4900, 9800, 196, 784, 392],  # Table 1 / Table 3, N and N·m
        'rated_output_microstrain': [1271.4, 1501.0, 814.7, 2048.4, 1931.3, 1444.7],  # Table 3
        'rated_output_mv': [1.908, 2.258, 1.220, 3.072, 2.850, 2.178],  # Table 3
        'rotation_outputs_mv': {  # Table 4
            'fz_down': [0.06015, 0.06017, 0.06038, 0.05999, 0.05903, 0.06030],
            'fz_up': [0.07275, 0.05596, -0.1042, 0.06035, 0.1192, 0.05958],
            'difference': [-0.0126, 0.00421, 0.16458, -0.00036, -0.06017, 0.00072],
        },
        'body_estimate': {'fz_n': 669.4, 'mx_nm': -0.0098, 'my_nm': -8.163},  # Table 5
        'tare_table': {
            'weight_n': 669.44,
            'moment_nm': 8.163,
            'diagonal_n': 473.34,  # Table 9
            'diagonal_moment_nm': 5.772,
        },
        'sigma': {
            'linear': [1.46, 0.13, 0.06, 0.14, 0.04, 0.07],  # Table 17
            'quadratic': [0.08, 0.04, 0.05, 0.03, 0.03, 0.03],
            'cubic': [0.08, 0.03, 0.04, 0.03, 0.02, 0.03],
        },
        'load_types': {
            'component': [1, 160],
            'longitudinal_combined': [161, 184],  # Table 2
            'six_component_combined': [185, 256],
            'longitudinal_plus_roll': [257, 292],
            'lateral_plus_axial': [293, 328],
        },
    },
    'B660H': {
        'file': 'b660h',
        'title': 'B660H (integral balance), NAL TM-663 §6.2, §8, Appendix B',
        'capacity': [686, 3920, 7840, 245, 588, 245],  # Table 1 / Table 6
        'rated_output_microstrain': [1666.5, 1814.5, 3173.8, 2688.0, 2153.1, 847.9],  # Table 6
        'rated_output_mv': [0.83325, 0.90725, 1.5869, 1.344, 1.07655, 0.42395],  # Table 6
        'rotation_outputs_mv': {  # Table 7
            'fz_down': [-0.00224, 0.0178, 0.29632, 0.0304, -0.006, 0.018],
            'fz_up': [0.0204, 0.0204, 0.0198, 0.01992, 0.0202, 0.0202],
            'difference': [-0.02264, -0.0026, 0.27652, 0.01048, -0.0262, -0.0022],
        },
        'body_estimate': {'fz_n': 681.6, 'mx_nm': -0.0676, 'my_nm': -4.635},  # Table 8
        'tare_table': {
            'weight_n': 681.59,
            'moment_nm': 4.635,
            'diagonal_n': 481.96,  # Table 13
            'diagonal_moment_nm': 3.273,
        },
        'sigma': {
            'linear': [0.99, 0.22, 0.09, 0.11, 0.08, 0.15],  # Table 17
            'quadratic': [0.06, 0.04, 0.05, 0.05, 0.04, 0.04],
            'cubic': [0.06, 0.04, 0.05, 0.05, 0.04, 0.04],
        },
        'load_types': {
            'component': [1, 164],
            'longitudinal_combined': [165, 188],  # Table 2
            'six_component_combined': [189, 260],
            'longitudinal_plus_roll': [261, 296],
            'lateral_plus_axial': [297, 332],
        },
    },
}


class Flow(list):
    """A list written on one line."""


yaml.add_representer(
    Flow, lambda d, v: d.represent_sequence('tag:yaml.org,2002:seq', v, flow_style=True)
)


def term_names(order):
    names = ['1'] + list(OUT)
    if order != 'linear':
        names += [f'{v}^2' for v in OUT] + [f'{a}*{b}' for a, b in combinations(OUT, 2)]
    if order == 'cubic':
        names += [f'{v}^3' for v in OUT]
    return names


def matrix(seed, order):
    rows = {}
    for comp in COMP:
        entry = seed[order][comp]
        values = [entry['const']] + entry['lin']
        if order != 'linear':
            quad = entry['quad']
            values += [quad[f'{v}*{v}'] for v in OUT] + [
                quad[f'{a}*{b}'] for a, b in combinations(OUT, 2)
            ]
        if order == 'cubic':
            values += entry['cube']
        rows[comp] = Flow(values)
    return {'terms': Flow(term_names(order)), 'coefficients': rows}


def schedule(path):
    rows = []
    with open(path, newline='') as f:
        for rec in csv.DictReader(f):
            if rec['executed'].strip() != '1':
                continue
            loads = [
                float(rec[k])
                for k in ('FX_kgf', 'FY_kgf', 'FZ_kgf', 'MX_kgfm', 'MY_kgfm', 'MZ_kgfm')
            ]
            loads = [int(x) if x == int(x) else x for x in loads]
            byproduct = [c for c in rec['paren_cols'].strip().split(';') if c]
            rows.append(Flow([int(rec['point']), int(rec['Ig'])] + loads + [' '.join(byproduct)]))
    return rows


def main(argv=None):
    root = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description='Regenerate the balance configs from NAL TM-663.')
    parser.add_argument(
        '--data',
        type=Path,
        default=root / 'data' / 'tm663',
        help="the memo's table extracts (default data/tm663)",
    )
    parser.add_argument(
        '--out-dir',
        type=Path,
        default=root / 'config',
        help='where lmc6522.yaml and b660h.yaml go (default config/)',
    )
    args = parser.parse_args(argv)
    data = args.data
    seeds = json.loads((data / 'seed_matrices.json').read_text())
    for name, memo in MEMO.items():
        body = memo['body_estimate']
        doc = {
            'balance': name,
            'description': memo['title'],
            'units': {
                'loads': 'N and N·m',
                'bridge_outputs': 'mV',
                'schedule': 'kgf and kgf·m as printed',
                'kgf_to_n': 9.80665,
            },
            'components': Flow(COMP),
            'bridge_outputs': Flow(OUT),
            'capacity': dict(zip(COMP, memo['capacity'])),
            'rated_output_mv': dict(zip(OUT, memo['rated_output_mv'])),
            'rated_output_microstrain': dict(zip(OUT, memo['rated_output_microstrain'])),
            'calibration_body': {
                'weight_n': memo['tare_table']['weight_n'],
                # forward of the balance centre: -M_Y(CB) / F_Z(CB) of the memo's Table 5 / 8
                'cg_x_m': round(
                    memo['tare_table']['moment_nm'] / memo['tare_table']['weight_n'], 6
                ),
                'cg_y_m': 0.0,
                'cg_z_m': 0.0,
                'axial_jig_weight_n': 2.94,
                'rotation_outputs_mv': {
                    k: Flow(v) for k, v in memo['rotation_outputs_mv'].items()
                },
                'memo_estimate': {
                    'fz_n': body['fz_n'],
                    'mx_nm': body['mx_nm'],
                    'my_nm': body['my_nm'],
                },
                'memo_tare_table': memo['tare_table'],
            },
            'gravity_directions': {  # I_g -> unit vector of gravity in balance axes (Fig. 3)
                1: Flow([0, 1, 0]),
                2: Flow([0, 0, 1]),
                3: Flow([0, -1, 0]),
                4: Flow([0, 0, -1]),
                5: Flow([0, R, R]),
                6: Flow([0, R, -R]),
                7: Flow([0, -R, R]),
                8: Flow([0, -R, -R]),
            },
            'load_types': {k: Flow(v) for k, v in memo['load_types'].items()},
            'matrices': {
                order: matrix(seeds[name], order) for order in ('linear', 'quadratic', 'cubic')
            },
            'table17_sigma_pct_fs': {
                order: dict(zip(COMP, v)) for order, v in memo['sigma'].items()
            },
            # refit acceptance gates (balance_calib/gates/): a refit failing one is not
            # adopted
            'acceptance': {
                # σ of the base (cubic) model, eqs. (44)-(49): 3x Table 17's cubic row, at least
                # 0.25 % FS
                'sigma_limit_pct_fs': {
                    c: max(0.25, round(3 * s, 3)) for c, s in zip(COMP, memo['sigma']['cubic'])
                },
                'outlier_robust_sigmas': 7.0,  # leave-one-out residual of one point / robust σ
                'outlier_floor_pct_fs': 0.05,  # ... and at least this far off
                'sensitivity_nominal_tolerance': 0.15,  # fitted / Table 10-14 linear sensitivity -
                #   1
                'sensitivity_active_tolerance': 0.05,  # fitted / active calibration's - 1
                'body_weight_tolerance': 0.10,  # body weight / declared - 1
                'capacity_margin': 0.05,  # applied load / capacity - 1
                'zero_shift_pct_fs': 2.0,  # between consecutive zero points of one block
            },
            'schedule': {
                'columns': Flow(
                    [
                        'point',
                        'Ig',
                        'FX_kgf',
                        'FY_kgf',
                        'FZ_kgf',
                        'MX_kgfm',
                        'MY_kgfm',
                        'MZ_kgfm',
                        'byproduct',
                    ]
                ),
                'rows': schedule(data / f"{memo['file']}_schedule.csv"),
            },
        }
        text = yaml.dump(doc, sort_keys=False, allow_unicode=True, width=200)
        header = (
            f'# {name}: everything NAL TM-663 gives for this balance. Generated by '
            'tools/make_balance_configs.py from data/tm663; edit there, not here.\n# schedule '
            'rows: point, I_g, loads in kgf / kgf·m as\n# printed, and the columns printed in '
            'parentheses (by-products of the loading hardware).\n'
        )
        target = args.out_dir / f"{memo['file']}.yaml"
        target.write_text(header + text)
        print('wrote', target)


if __name__ == '__main__':
    main()
