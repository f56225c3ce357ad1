"""Shared fixtures: the two balances of TM-663 and a seeded simulated campaign reduced to points."""
import numpy as np
import pytest

from balance_calib.config import load_balance_config


@pytest.fixture(scope='session')
def lmc6522():
    return load_balance_config('lmc6522')


@pytest.fixture(scope='session')
def b660h():
    return load_balance_config('b660h')


@pytest.fixture(scope='session', params=['lmc6522', 'b660h'])
def balance(request):
    return load_balance_config(request.param)


@pytest.fixture
def rng():
    return np.random.default_rng(20261124)


@pytest.fixture
def ros_domain():
    """A ROS_DOMAIN_ID for this test alone (ros_harness.new_domain_id, the suite's one allocator)."""
    from ros_harness import new_domain_id       # rclpy only for the tests that ask for a domain
    return new_domain_id()
