"""bridge_publisher's parameter table (parameter_table.Spec), without rclpy.

The node reads every parameter once, at start-up, to build its timeline: all are read-only. The
thrust stand of `mode` thrust_stand (simulation/thrust_stand.py) takes seed and the playing
parameters (rate_hz, speed, loop, exit_when_done, wait_for_subscribers...); its physics has no
parameters of its own on the node.
"""

from __future__ import annotations

from ..parameter_table import Spec, startup

MODES = ('calibration', 'wind_on', 'replay', 'thrust_stand')


PARAMETERS: dict[str, Spec] = {
    'mode': startup(
        'calibration',
        'what the node plays: a calibration campaign, a wind_on run, '
        "a replay of bags or the thrust_stand (the node's --help "
        'describes each)',
        choices=MODES,
    ),
    'balance': startup('lmc6522', 'balance config: lmc6522, b660h or a path'),
    'truth_model': startup(
        'cubic',
        "which of the config's matrices the simulated balance obeys: linear, quadratic or cubic",
    ),
    'rate_hz': startup(100.0, 'bridge samples per second on /balance/raw', 0.0, low_open=True),
    'effects': startup(
        '',
        'effects the simulated balance has, e.g. "temperature:sensitivity_per_k=0.0045|0|0|0|0|0"',
    ),
    'seed': startup(0, 'random seed of the simulated noise', 0),
    'noise_sigma_pct_fs': startup(
        -1.0, 'σ of a point mean, % FS, all components; < 0: Table 17 cubic row'
    ),
    'point_duration_s': startup(
        1.0, 'calibration: seconds of samples at each load point', 0.0, low_open=True
    ),
    'transition_s': startup(
        0.3,
        'calibration: seconds between points (applied_load all NaN, weights being changed)',
        0.0,
    ),
    'physical_seconds_per_point': startup(
        90.0,
        "calibration: the campaign's temperature and "
        'drift follow a real one of this many seconds a '
        'point, however fast it plays',
    ),
    'points': startup('', "e.g. '1-60,100' (point numbers as printed); '' = all"),
    'schedule_file': startup(
        '',
        'calibration: a load schedule CSV (layout of the Appendix A/B '
        "sheets, e.g. from balance-calib design); '' = the config's",
    ),
    'speed': startup(1.0, 'simulated (or recorded) seconds per real second', 0.0, low_open=True),
    'bag': startup('', 'replay: bag directory or .mcap; several separated by commas'),
    'profile_csv': startup('', "wind_on: time_s,FX,FY,FZ,MX,MY,MZ (balance axes); '' = α sweep"),
    'installation': startup(
        'upright', 'wind_on: upright or inverted (TM-663 §10.2), as balance_calibrator is set'
    ),
    'hold_s': startup(1.0, 'wind_on sweep: time at each α, s', 0.0, low_open=True),
    'wind_off_s': startup(2.0, 'wind_on sweep: wind-off samples first (for ~/tare), s', 0.0),
    'alpha_start_deg': startup(-2.0, 'wind_on sweep: first angle of attack, degrees'),
    'alpha_end_deg': startup(22.0, 'wind_on sweep: last angle of attack, degrees'),
    'alpha_step_deg': startup(
        2.0, 'wind_on sweep: angle-of-attack step, degrees', 0.0, low_open=True
    ),
    'model_weight_n': startup(
        0.0,
        'wind_on: weight of the model on the balance, N; with '
        "aero_model: > 0 overrides the model file's weight (and CG)",
    ),
    'aero_model': startup(
        '', 'wind_on: a model file (config/models) -> the physical run of §10.3'
    ),
    'dynamic_pressure_pa': startup(
        50000.0, 'wind_on with aero_model: q∞ of the wind-on holds, Pa', 0.0, low_open=True
    ),
    'model_cg_m': startup(
        [0.0, 0.0, 0.0],
        'wind_on with aero_model and model_weight_n > 0: the true CG, body axes, m',
    ),
    'wind_off_rolls_deg': startup(
        [0.0, 90.0, 180.0, 270.0],
        "wind_on with aero_model: the "
        "wind-off sweep's rolls, degrees (every roll at every α of "
        'wind_off_alphas_deg)',
    ),
    'wind_off_alphas_deg': startup(
        [-2.0, 10.0, 22.0],
        "wind_on with aero_model: the wind-off sweep's angles of attack, degrees",
    ),
    'wind_off_hold_s': startup(
        0.3, 'wind_on with aero_model: time at each wind-off attitude, s', 0.0, low_open=True
    ),
    'electrical_zero_mv': startup(
        0.04, 'calibration and wind_on: bridge outputs with nothing on the balance, mV'
    ),
    'temperature_c': startup(20.0, 'wind_on: balance temperature, °C'),
    'temperature_rate_hz': startup(10.0, '/balance/temperature messages per second'),
    'loop': startup(False, 'start again from the beginning when the schedule, sweep or bag ends'),
    'exit_when_done': startup(
        False, 'end the node when the schedule, sweep or bag ends (exit status 0)'
    ),
    'wait_for_subscribers': startup(
        0,
        'start only when /balance/raw has this many subscribers '
        '(with aero_model /model/attitude and '
        '/tunnel/dynamic_pressure too) ...',
    ),
    'start_delay_s': startup(
        0.5, '... and this long after, so their other topics are matched too, s'
    ),
    'wait_for_subscribers_timeout_s': startup(
        30.0, 'give up (exit status 1) after waiting this long for them, s; 0 = wait for ever'
    ),
}
