"""Shared fixtures: the two balances of TM-663, seeded simulated campaigns (as the simulation's
Campaign, reduced to points, or recorded as a bag), and a ROS domain for a DDS test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from balance_calib.config import load_balance_config

# How a simulated campaign is paced (SimulationSettings beyond the seed and the noise). Tests whose
# pace is part of what they check (the bridge publisher's, the recorder's) keep their own.
RECIPES = {
    # the memo's schedule at the simulation's own pace: one sample a point
    'memo': {},
    # recorded and refitted from a bag: 10 samples a point, 3 while the weights change
    'bag': {
        'samples_per_point': 10,
        ('transition_samples'): 3,
        ('point_duration_s'): 1.0,
        ('transition_s'): 0.5,
    },
    # short enough to play over DDS or refit inside a node: 5 samples a point, 0.1 s a point
    'dds': {'samples_per_point': 5, 'point_duration_s': 0.1, 'transition_s': 0.05},
}


class Campaigns:
    """Seeded simulated campaigns of the memo's schedule, each built once per session (per
    pytest-xdist worker) and shared by the tests that ask for the same one.

    A campaign is named by (balance, seed, recipe, noise, effects): noise 'table17' is the point
    noise of Table 17's cubic row (table17_noise), None none, a number that % FS; effects a
    parse_effects string. The same name is the same data as simulate_campaign gives for it. Its
    arrays are read-only, so that no test changes what another one reads.
    """

    def __init__(self, directory: Path):
        self._directory = directory
        self._built: dict[tuple, object] = {}

    def _once(self, key: tuple, build):
        if key not in self._built:
            self._built[key] = build()
        return self._built[key]

    def campaign(
        self,
        balance: str = 'lmc6522',
        seed: int = 0,
        recipe: str = 'memo',
        noise: str | float | None = 'table17',
        effects: str = '',
    ):
        """The simulation's Campaign (read-only arrays)."""
        from balance_calib.simulation.balance_sim import (
            simulate_campaign,
            SimulationSettings,
            table17_noise,
        )
        from balance_calib.simulation.effects import parse_effects

        def build():
            config = load_balance_config(balance)
            sigma = table17_noise(config) if noise == 'table17' else noise
            settings = SimulationSettings(noise_sigma_pct_fs=sigma, seed=seed, **RECIPES[recipe])
            campaign = simulate_campaign(
                config, settings=settings, effects=parse_effects(effects) if effects else ()
            )
            for value in vars(campaign).values():
                if isinstance(value, np.ndarray):
                    value.flags.writeable = False
            return campaign

        return self._once(('campaign', balance, seed, recipe, noise, effects), build)

    def points(
        self,
        balance: str = 'lmc6522',
        seed: int = 0,
        recipe: str = 'memo',
        noise: str | float | None = 'table17',
        effects: str = '',
    ):
        """The campaign reduced to load points (refit.pipeline.campaign_points)."""
        from balance_calib.refit.pipeline import campaign_points

        campaign = self.campaign(balance, seed, recipe, noise, effects)
        return self._once(
            ('points', balance, seed, recipe, noise, effects), lambda: campaign_points(campaign)
        )

    def bag(
        self,
        balance: str = 'lmc6522',
        seed: int = 0,
        recipe: str = 'memo',
        noise: str | float | None = 'table17',
        effects: str = '',
        points: slice | None = None,
    ) -> Path:
        """The campaign (or a slice of its points) written as a rosbag2 MCAP bag directory, once;
        tests read it and never write into it.
        """
        from balance_calib.simulation.campaign_bag import write_campaign_bag

        key = (
            balance,
            seed,
            recipe,
            noise,
            effects,
            None if points is None else (points.start, points.stop, points.step),
        )
        name = '_'.join(str(part) for part in key).replace(' ', '')
        return self._once(
            ('bag',) + key,
            lambda: write_campaign_bag(
                self.campaign(balance, seed, recipe, noise, effects),
                self._directory / name,
                points=points,
            ),
        )


def pytest_collection_modifyitems(config, items):
    """The DDS tests (marker ros) form one pytest-xdist group: with --dist loadgroup (as
    launchless_scripts/test runs them) one worker runs them one after another while the others
    take the remaining tests, so that no two tests' nodes compete for discovery at once.
    """
    for item in items:
        if item.get_closest_marker('ros') is not None:
            item.add_marker(pytest.mark.xdist_group('dds'))


@pytest.fixture(scope='session')
def campaigns(tmp_path_factory) -> Campaigns:
    return Campaigns(tmp_path_factory.mktemp('campaigns'))


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
    """A ROS_DOMAIN_ID for this test alone (ros_harness.new_domain_id, the one allocator)."""
    from ros_harness import new_domain_id  # rclpy only for the tests that ask for a domain

    return new_domain_id()
