"""liver_sim: an ament_python package that also installs with plain pip.

Two ways in, one file:
  * ROS workspace:  colcon build  (setuptools; setup.cfg puts the executables
    into lib/liver_sim so that ``ros2 run liver_sim <executable>`` finds them);
  * virtualenv:     pip install -e .  (console scripts land in <venv>/bin).

Exact versions of every dependency live in requirements.txt; the ranges below
are deliberately loose so a ROS workspace can use its system packages.
"""
import os
from glob import glob

from setuptools import find_packages, setup

package_name = 'liver_sim'

# Executables (docs/contract.md, "Executables"): the command line and the four nodes.
CONSOLE_SCRIPTS = [
    'liver-sim = liver_sim.cli.main:main',
    'liver_physics = liver_sim.nodes.physics_node:main',
    'haptic_bridge = liver_sim.nodes.bridge_node:main',
    'liver_tool = liver_sim.nodes.tool_node:main',
    'phantom_sim = liver_sim.nodes.phantom_node:main',
]

here = os.path.dirname(os.path.abspath(__file__))


def _rel_glob(pattern):
    """Sorted files matching ``pattern`` under this directory, as relative paths."""
    return sorted(
        os.path.relpath(p, here) for p in glob(os.path.join(here, pattern))
    )


setup(
    name=package_name,
    version='0.1.0',
    description='Interactive mass-spring model of the human liver with haptic '
                'feedback, as ROS 2 nodes',
    license='Apache-2.0',
    maintainer='liver_sim maintainers',
    maintainer_email='liver-sim@example.org',
    python_requires='>=3.11',
    # The simulator (liver_sim and its subpackages) plus the haptic bridge and
    # message helpers, whichever of them exist as packages; never the tests.
    packages=find_packages(
        where=here,
        include=[
            'liver_sim', 'liver_sim.*',
            'haptic_bridge', 'haptic_bridge.*',
            'msg_defs', 'msg_defs.*',
        ],
        exclude=['test', 'test.*', 'tests', 'tests.*'],
    ),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', _rel_glob(os.path.join('config', '*.yaml'))
         + _rel_glob(os.path.join('config', '*.xml')) + _rel_glob(os.path.join('config', '*.json'))
         + _rel_glob(os.path.join('config', '*.rviz'))),
    ],
    install_requires=[
        'numpy>=1.24,<2.5',  # numba 0.68 supports numpy < 2.5
        'numba>=0.59',
        'scipy>=1.10',
        'meshio>=5.3',
        'trimesh>=4.0',
        'matplotlib>=3.6',
        'rosbags>=0.11',  # sessions: rosbag2 bags (record, replay, resimulate, report)
        'PyYAML>=6.0',
        'foxglove-sdk>=0.30',  # liver-sim view: the live view's WebSocket server for the Foxglove app
        'nibabel>=5.0',  # mesh build SEGMENTATION: NIfTI label volumes
        'pynrrd>=1.0',  # ... NRRD and 3D Slicer .seg.nrrd
        'scikit-image>=0.22',  # ... marching cubes
    ],
    extras_require={
        'test': ['pytest', 'websockets'],  # websockets: the tests' Foxglove client
        'peers': ['mujoco==4.0.0'],  # liver-sim bench physics --peers: MuJoCo's flex beside our model
    },
    zip_safe=True,
    entry_points={
        'console_scripts': CONSOLE_SCRIPTS,
    },
)
