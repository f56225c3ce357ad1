"""ament_python build of balance_calib (colcon build, or pip install -e .)."""

from glob import glob

from setuptools import Extension, find_packages, setup

package_name = 'balance_calib'

setup(
    name=package_name,
    version='0.1.0',
    # balance_calib and its sub-packages only: tools/ (ros_cli, the development stand-in for the
    # ros2 CLI, and the scripts that regenerate data) is not installed
    packages=find_packages(include=['balance_calib', 'balance_calib.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.csv')),
        ('share/' + package_name + '/config/models', glob('config/models/*.yaml')),
        ('share/' + package_name + '/config/plotjuggler', glob('config/plotjuggler/*.xml')),
        ('share/' + package_name + '/config/foxglove', glob('config/foxglove/*.json')),
        ('share/' + package_name + '/config/daq', glob('config/daq/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.yaml')),
    ],
    # the live calibrator's lone sample in C (live/sample_kernel.py), the pure core's only
    # accelerator, warning-free (-Wall -Werror); optional: without a C compiler the package
    # installs and every sample takes the pure core's path (the node says so at start-up)
    ext_modules=[
        Extension(
            'balance_calib.live._sample_kernel',
            ['balance_calib/live/_sample_kernel.c'],
            extra_compile_args=['-O2', '-std=c99', '-Wall', '-Werror'],
            optional=True,
        )
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='balance_calib maintainers',
    maintainer_email='maintainers@balance-calib.invalid',
    description='Six-component wind-tunnel balance calibration after NAL TM-663, for ROS 2.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'balance-calib = balance_calib.cli:main',
            'bridge_publisher = balance_calib.nodes.bridge_publisher:main',
            'balance_calibrator = balance_calib.nodes.balance_calibrator:main',
            'balance_recorder = balance_calib.nodes.balance_recorder:main',
            'thrust_analyzer = balance_calib.nodes.thrust_analyzer:main',
            'aero_coefficients = balance_calib.nodes.aero_coefficients:main',
            'balance_daq = balance_calib.nodes.balance_daq:main',
        ],
    },
)
