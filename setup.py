"""asmonc_vision: ament_python package (colcon) that also installs with plain pip."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'asmonc_vision'

#: one console script per node; the same names for `ros2 run asmonc_vision <name>`
NODES = {
    'stereo_capture_node': 'asmonc_vision.nodes.capture_node:main',
    'detector_node': 'asmonc_vision.nodes.detector_node:main',
    'alarm_node': 'asmonc_vision.nodes.alarm_node:main',
    'bag_player_node': 'asmonc_vision.nodes.player_node:main',
    'bag_recorder_node': 'asmonc_vision.nodes.recorder_node:main',
    'egomotion_node': 'asmonc_vision.nodes.egomotion_node:main',
    'compass_node': 'asmonc_vision.nodes.compass_node:main',
    'gait_filter_node': 'asmonc_vision.nodes.gait_node:main',
    'audio_node': 'asmonc_vision.nodes.audio_node:main',
}
TOOLS = {
    'asmonc': 'asmonc_vision.cli.main:main',
    'asmonc-sim': 'asmonc_vision.sim.cli:main',
}

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='asmonc_vision developers',
    maintainer_email='asmonc@example.org',
    description='Wearable stereo-vision obstacle detection (GPOD/DGPR) on ROS 2 Jazzy',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={'console_scripts': [f'{k} = {v}' for k, v in {**NODES, **TOOLS}.items()]},
)
