"""Zero and tare belong to an installation: the persisted state records the calibration file's
content, the installation, the namespace and the node, and the session restores it only when all
four match (without ROS: the session the node drives).
"""

from dataclasses import replace

from live_cases import MEMO
import numpy as np
from tare_cases import session, take_tare
import yaml

from balance_calib.calibration_file import save_calibration
from balance_calib.live.diagnostics_status import OK, WARN
from balance_calib.live.session import CalibratorSession
from balance_calib.live.tare_store import calibration_sha256, restore_refusal, TareOwner
from balance_calib.tunnel_axes import INVERTED, UPRIGHT


def calibration_status(made: CalibratorSession):
    status = made.report()[1]
    return status, dict(status.values)


def test_the_tare_is_restored_for_the_same_calibration_installation_and_node(calibration):
    first, _ = session(calibration)
    take_tare(first)
    saved = yaml.safe_load((calibration.parent / 'calibration.tare.yaml').read_text())['taken_for']
    assert saved['calibration_sha256'] == calibration_sha256(calibration) != ''
    assert (saved['installation'], saved['namespace'], saved['node']) == (
        '-FX,FY,-FZ,MX,MY,MZ',
        '/',
        'balance_calibrator',
    )
    again, lines = session(calibration)
    np.testing.assert_array_equal(again.live.tare.tare_load, first.live.tare.tare_load)
    assert again.tare_refused == '' and any('restored from' in line for _, line in lines)
    status, values = calibration_status(again)
    assert status.level == OK and values['tare_not_restored'] == 'none'


def test_changed_calibration_content_is_not_restored_and_says_why_until_a_new_tare(calibration):
    take_tare(session(calibration)[0])
    # the same file name, one coefficient changed by a part in 10^6
    cubic = MEMO.models['cubic']
    coefficients = cubic.coefficients.copy()
    coefficients.flat[0] *= 1 + 1e-6
    changed = MEMO.models | {'cubic': cubic.with_coefficients(coefficients)}
    save_calibration(calibration, replace(MEMO, models=changed))
    later, lines = session(calibration)
    assert later.live.tare.tare_load is None and later.live.tare.zero_mv is None
    warnings = [line for level, line in lines if level == 'warning' and 'not restoring' in line]
    assert len(warnings) == 1 and 'another calibration' in warnings[0], lines
    status, values = calibration_status(later)
    assert status.level == WARN and 'NOT restored' in status.message
    assert 'another calibration' in values['tare_not_restored']
    assert calibration_status(later)[0].level == WARN  # stays, tick after tick
    take_tare(later)  # a new ~/tare: it belongs to this calibration
    status, values = calibration_status(later)
    assert status.level == OK and values['tare_not_restored'] == 'none'
    assert session(calibration)[0].live.tare.tare_load is not None


def test_another_namespace_or_installation_is_not_restored(calibration, tmp_path):
    shared = str(tmp_path / 'shared.tare.yaml')  # tare_file names one file for every node
    take_tare(session(calibration, tare_file=shared)[0])
    left, lines = session(calibration, '/left/balance_calibrator', tare_file=shared)
    assert left.live.tare.tare_load is None
    assert (
        'taken by node /balance_calibrator, this is /left/balance_calibrator' in left.tare_refused
    )
    inverted, _ = session(calibration, tare_file=shared, installation='inverted')
    assert inverted.live.tare.tare_load is None
    assert (
        'taken in the upright installation (-FX,FY,-FZ,MX,MY,MZ), now inverted'
        in inverted.tare_refused
    )
    # the same signed permutation spelt out is the same installation
    spelt, _ = session(calibration, tare_file=shared, installation='-FX,FY,-FZ,MX,MY,MZ')
    assert spelt.live.tare.tare_load is not None and spelt.tare_refused == ''


def test_an_older_tare_file_without_an_owner_is_read_not_restored_and_warned_about(calibration):
    take_tare(session(calibration)[0])
    path = calibration.parent / 'calibration.tare.yaml'
    data = yaml.safe_load(path.read_text())
    del data['taken_for']
    data['format'] = 'balance_calib/tare 1'  # as the node wrote it before
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    older, lines = session(calibration)
    assert older.live.tare.tare_load is None
    assert [level for level, line in lines if 'not restoring' in line] == ['warning']
    assert 'older tare file' in calibration_status(older)[1]['tare_not_restored']


def test_the_matching_rule():
    owner = TareOwner('ab' * 32, '-FX,FY,-FZ,MX,MY,MZ', '/', 'balance_calibrator', 'upright')

    def refusal(**changed):
        return restore_refusal(owner, replace(owner, **changed))

    assert refusal() == ''
    assert refusal(installation_name='as calibrated') == ''  # a label, not the axes
    assert 'another calibration' in refusal(calibration_sha256='cd' * 32)
    unknown = replace(owner, calibration_sha256='')
    assert 'another calibration' in restore_refusal(unknown, unknown)  # unknown never matches
    assert 'this is /left/balance_calibrator' in refusal(namespace='/left')
    assert 'this is /balance_calibrator_2' in refusal(node='balance_calibrator_2')
    assert 'installation' in refusal(installation='-FX,-FY,FZ,MX,-MY,-MZ')
    assert 'older tare file' in restore_refusal(None, owner)
    assert TareOwner.of_node('', INVERTED, '/left/balance_calibrator') == TareOwner(
        '', '-FX,-FY,FZ,MX,-MY,-MZ', '/left', 'balance_calibrator', 'inverted'
    )
    assert TareOwner.of_node('', UPRIGHT, '/balance_calibrator').namespace == '/'
