"""report.md of a demo-like refit holds what a balance engineer signs, and its figures read at 100
%.

The refit is the demo's: LMC6522's Appendix A campaign with an undeclared temperature sensitivity
on the F_X bridge (the demo's --effects), fitted by the pipeline behind ~/refit. Expected values
come from the memo's tables (3, 2, 9) and from the fit's own arrays, not from a previous report.
"""

import re

import numpy as np
from PIL import Image
import pytest

from balance_calib.calibrate.records import bag_record
from balance_calib.calibrate.write_record import write_record
from balance_calib.calibration_settings import RecordOptions
from balance_calib.config import load_balance_config
from balance_calib.refit.pipeline import calibrate_points
from balance_calib.refit.plots import CLIP_PCT, describe_variable, point_categories
from balance_calib.refit.report_sections import add_lab_units_to_report
from balance_calib.simulation.balance_sim import (
    simulate_campaign,
    SimulationSettings,
    table17_noise,
)
from balance_calib.units import (
    implied_excitation_v,
    loads_to_display,
    NEWTON_METRE_PER_INCH_LBF,
    NEWTON_PER_LBF,
    ratiometric_to_mv,
)

DEMO_EFFECTS = 'temperature:sensitivity_per_k=0.0045|0|0|0|0|0'
# TM-663 Table 3: rated loads (N, N·m) and rated outputs (mV) of LMC6522
TABLE3_LOADS = {'FX': 980, 'FY': 4900, 'FZ': 9800, 'MX': 196, 'MY': 784, 'MZ': 392}
TABLE3_OUTPUTS = {
    'FXV': 1.908,
    'FYV': 2.258,
    'FZV': 1.220,
    'MXV': 3.072,
    'MYV': 2.850,
    'MZV': 2.178,
}
# TM-663 Table 2: load types and point numbers of LMC6522
TABLE2 = [
    ('single-component', 1, 160),
    ('longitudinal three-component combined', 161, 184),
    ('six-component combined', 185, 256),
    ('longitudinal three-component + roll', 257, 292),
    ('lateral three-component', 293, 328),
]


@pytest.fixture(scope='module')
def refit(tmp_path_factory, campaigns):
    config = load_balance_config('lmc6522')
    result = calibrate_points(campaigns.points(seed=3, effects=DEMO_EFFECTS), config)
    out = tmp_path_factory.mktemp('refit')
    write_record(bag_record(result), RecordOptions(out))
    return result, out, (out / 'report.md').read_text()


def table_row(markdown: str, first_cells) -> list[str]:
    """The cells of the markdown table row whose first cells are first_cells."""
    for line in markdown.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if line.startswith('|') and cells[: len(first_cells)] == [str(c) for c in first_cells]:
            return cells
    raise AssertionError(f'no table row starting with {first_cells}')


def test_rated_loads_and_outputs_say_what_full_scale_is(refit):
    _, _, report = refit
    assert 'Full scale (FS) of every "% FS"' in report
    for (component, load), (bridge, output) in zip(TABLE3_LOADS.items(), TABLE3_OUTPUTS.items()):
        cells = table_row(report, [component])
        unit = 'N·m' if component.startswith('M') else 'N'
        assert cells[1] == f'{load:g} {unit}' and cells[2] == bridge and float(cells[3]) == output


def test_load_point_breakdown_follows_table_2(refit):
    result, _, report = refit
    labels = result.points.label
    zero = result.points.is_zero_point
    for title, low, high in TABLE2:
        row = next(line for line in report.splitlines() if line.startswith(f'| {title}'))
        cells = [c.strip() for c in row.strip('|').split('|')]
        inside = (labels >= low) & (labels <= high)
        assert cells[1] == f'{low}–{high}'
        assert [int(c) for c in cells[2:5]] == [
            high - low + 1,
            int((inside & ~zero).sum()),
            int((inside & zero).sum()),
        ]
    assert (
        f'{len(labels)} points: {int((~zero).sum())} loaded, {int(zero.sum())} zero points'
        in report
    )


def test_calibration_body_loads_per_orientation_as_tables_9_and_13(refit):
    result, _, report = refit
    weight = result.report['calibration_body']['weight_N']
    body = (
        result.diagnosis.calibration_body
        if result.diagnosis is not None
        else result.reduction.body
    )
    # Table 9 form: I_g = 2 (F_Z down): F_Z = W, M_Y = -x_cg W; I_g = 5: F_Y = F_Z = W/sqrt(2)
    cells = table_row(report, ['2'])
    assert float(cells[5]) == pytest.approx(body.weight_n, abs=1e-3)
    assert float(cells[7]) == pytest.approx(-body.cg_m[0] * body.weight_n, abs=2e-3)
    cells = table_row(report, ['5'])
    assert float(cells[4]) == pytest.approx(body.weight_n / np.sqrt(2), abs=1e-3)
    assert float(cells[5]) == pytest.approx(body.weight_n / np.sqrt(2), abs=1e-3)
    assert weight == pytest.approx(body.weight_n, abs=1e-3)
    for orientation in range(1, 9):
        assert int(table_row(report, [str(orientation)])[2]) == int(
            np.sum(result.points.orientation == orientation)
        )


def test_sigma_two_sigma_and_largest_residual_per_component(refit):
    result, _, report = refit
    capacity = np.asarray(result.config.capacity)
    for order, fit in result.fits.items():
        pct = fit.fit.residuals / capacity * 100.0
        for k, component in enumerate(result.config.components):
            cells = table_row(report, [order, component])
            sigma = np.sqrt(np.mean(pct[:, k] ** 2))
            worst = np.argmax(np.abs(pct[:, k]))
            assert float(cells[2]) == pytest.approx(sigma, abs=6e-4)
            assert float(cells[3]) == pytest.approx(2 * sigma, abs=6e-4)
            assert float(cells[4]) == pytest.approx(pct[worst, k], abs=6e-4)
            assert int(cells[5]) == int(result.points.label[worst])
            assert int(cells[6]) == int(np.sum(np.abs(pct[:, k]) > CLIP_PCT))
    # the adopted model's row exists and is smaller on F_X than the base model's: the effect was
    # applied
    assert float(table_row(report, ['adopted', 'FX'])[2]) < float(
        table_row(report, ['cubic', 'FX'])[2]
    )


def test_conditioning_and_standard_errors_are_reported(refit):
    result, _, report = refit
    for order, fit in result.fits.items():
        cells = table_row(report, [order, str(len(fit.fit.model.terms))])
        assert float(cells[3]) == pytest.approx(fit.fit.condition_number, rel=1e-3)
        assert f'#### {order}: standard errors' in report
    # the linear F_X row of the standard-error table carries the fit's own numbers
    section = report.split('#### linear: standard errors')[1].split('```')[1]
    row = next(line for line in section.splitlines() if line.startswith('FX'))
    errors = result.fits['linear'].fit.standard_errors[0]
    assert [float(x) for x in row.split()[1:]] == pytest.approx(list(errors), rel=2e-3, abs=1e-4)


def test_temperature_excitation_date_and_sources(refit):
    result, _, report = refit
    temperature = result.points.temperature_c
    match = re.search(r'Balance temperature: ([\d.]+) to ([\d.]+) °C', report)
    assert match and float(match[1]) == pytest.approx(np.nanmin(temperature), abs=0.006)
    assert float(match[2]) == pytest.approx(np.nanmax(temperature), abs=0.006)
    # Table 3 gives each rated output in mV and in µst: E = 4 V / (K ε) with K = 2 -> 3 V
    match = re.search(r'Excitation: ([\d.]+) V \(implied', report)
    assert match and float(match[1]) == pytest.approx(3.0, abs=0.01)
    assert re.search(r'Fitted: 20\d\d-\d\d-\d\dT', report)
    assert 'Source files: simulation (no bag)' in report


def test_one_figure_per_model_at_most_two_panels_wide_and_readable(refit):
    result, out, report = refit
    names = [
        'residuals_linear.png',
        'residuals_quadratic.png',
        'residuals_cubic.png',
        'residuals_adopted.png',
        'effect_temperature.png',
    ]
    for name in names:
        assert f'![{name}]({name})' in report
        width, height = Image.open(out / name).size
        # two panels of ~500 px at 100 dpi: no 2827x462 strips, nothing shrunk below reading size
        assert 600 <= width <= 1100 and 400 <= height <= 1300, (name, width, height)
    sizes = {Image.open(out / n).size for n in names[:4]}
    assert len(sizes) == 1  # the adopted model's figure has the layout of the other three


def test_single_and_combined_points_are_told_apart(campaigns):
    config = load_balance_config('lmc6522')
    points = campaigns.points(seed=1, noise=None)
    categories = point_categories(points, config)
    single = (points.label <= 160) & ~points.is_zero_point
    assert set(categories[single]) == {'single'}
    assert set(categories[(points.label > 160) & ~points.is_zero_point]) == {'combined'}
    assert set(categories[points.is_zero_point]) == {'zero'}


def test_axis_words_for_diagnosis_variables():
    assert describe_variable('dT*FXV') == ('(T − T_ref) × F_X bridge output', 'K·mV')
    assert describe_variable('time (s)') == ('time since the first point', 'h')
    words, unit = describe_variable('dir_FX')
    assert words.startswith('F_X load direction') and unit == ''
    assert describe_variable('FXV^2*FZV') == ('(F_X bridge output)² × F_Z bridge output', 'mV³')
    assert describe_variable('dT^2') == ('(T − T_ref)²', 'K²')


def test_report_in_lab_units_on_request(refit):
    result, out, _ = refit
    add_lab_units_to_report(out / 'report.md', result.report, 'lbf')
    report = (out / 'report.md').read_text()
    assert '## Loads in lab units (lbf, in-lbf)' in report
    assert report.index('## Loads in lab units') < report.index(
        '## Effects found in the residuals'
    )
    # 980 N = 220.31 lbf; 196 N·m = 1734.7 in-lbf (1 lbf = 0.45359237 kg x 9.80665 m/s², 1 in =
    # 0.0254 m)
    assert table_row(report, ['FX', '220.3', 'lbf'])
    assert table_row(report, ['MX', '1735', 'in-lbf'])
    sigma_n = result.fits['cubic'].sigma_pct_fs['FX'] / 100 * 980
    assert float(table_row(report, ['cubic', 'FX', 'lbf'])[3]) == pytest.approx(
        sigma_n / 4.4482216, rel=2e-3
    )


def test_unit_conversions_at_the_edges():
    assert NEWTON_PER_LBF == pytest.approx(4.4482216152605, rel=1e-12)
    assert NEWTON_METRE_PER_INCH_LBF == pytest.approx(0.1129848290276167, rel=1e-12)
    assert loads_to_display([980.0, 196.0], ['FX', 'MX'], 'lbf') == pytest.approx(
        [220.3089, 1734.7], rel=1e-4
    )
    assert loads_to_display([9.80665, 9.80665], ['FZ', 'MY'], 'kgf') == pytest.approx([1.0, 1.0])
    assert ratiometric_to_mv(2.0, 'mV/V', 5.0) == pytest.approx(10.0)
    assert ratiometric_to_mv([1500.0, -300.0], 'microV/V', [10.0, 5.0]) == pytest.approx(
        [15.0, -1.5]
    )
    for bad in (float('nan'), 0.0, -5.0, []):
        with pytest.raises(ValueError, match='excitation voltage'):
            ratiometric_to_mv(1.0, 'mV/V', bad)
    with pytest.raises(ValueError, match="bridge output unit 'V'"):
        ratiometric_to_mv(1.0, 'V', 5.0)
    # B660H Table 6: 0.83325 mV at 1666.5 µst, K = 2 -> exactly 1 V
    assert implied_excitation_v([0.83325], [1666.5]) == pytest.approx(1.0, rel=1e-6)


def test_refit_command_writes_lab_units_on_request(tmp_path):
    import subprocess

    from balance_calib.simulation.campaign_bag import write_campaign_bag

    config = load_balance_config('lmc6522')
    settings = SimulationSettings(
        samples_per_point=3, transition_samples=2, seed=1, noise_sigma_pct_fs=table17_noise(config)
    )
    bag = write_campaign_bag(simulate_campaign(config, settings=settings), tmp_path / 'bag')
    done = subprocess.run(
        [
            'balance-calib',
            'refit',
            str(bag),
            '--balance',
            'lmc6522',
            '--out',
            str(tmp_path / 'out'),
            '--no-diagnosis',
            '--report-units',
            'lbf',
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    report = (tmp_path / 'out' / 'report.md').read_text()
    assert table_row(report, ['FZ', '2203', 'lbf'])  # 9800 N / 4.4482216 N/lbf
    assert table_row(report, ['MY', '6939', 'in-lbf'])  # 784 N·m / 0.11298483 N·m/in-lbf
    assert f'`{bag}`' in report  # the source file is named


def _campaign_line(report_md):
    return next(x for x in report_md.read_text().splitlines() if 'Campaign:' in x)


def test_a_simulated_bag_is_not_dated_as_a_campaign(tmp_path):
    from balance_calib.benchmarks.refit_reliability import (
        campaign_events,
        small_campaign,
        write_mcap,
    )
    from balance_calib.calibrate.from_bags import RefitSettings, run_refit
    from balance_calib.simulation.campaign_bag import write_campaign_bag

    config = load_balance_config('lmc6522')
    settings = SimulationSettings(
        seed=2, samples_per_point=2, noise_sigma_pct_fs=table17_noise(config)
    )
    bag = write_campaign_bag(simulate_campaign(config, settings=settings), tmp_path / 'bag')
    run_refit([bag], 'lmc6522', tmp_path / 'out', RefitSettings(diagnose=False, plots=False))
    line = _campaign_line(tmp_path / 'out' / 'report.md')
    assert "stamps are the simulation's clock" in line and 'not the date of a campaign' in line
    # a bag without the simulation's note (as a recorder writes one) is dated as it is
    recorded = write_mcap(
        campaign_events(small_campaign('lmc6522', seed=2)), tmp_path / 'recorded.mcap'
    )
    run_refit([recorded], 'lmc6522', tmp_path / 'out2', RefitSettings(diagnose=False, plots=False))
    line = _campaign_line(tmp_path / 'out2' / 'report.md')
    assert 'UTC' in line and 'simulation' not in line
