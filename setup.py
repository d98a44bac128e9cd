from glob import glob

from setuptools import find_namespace_packages, setup

package_name = 'mbtrack_ros'

# Everything from the package index, ROS 2 Jazzy wheels included. A colcon build inside a
# ROS 2 workspace takes these from package.xml (rosdep) instead; `pip install .[test]`
# (what `python3 -m mbtrack_ros.bootstrap` runs) takes them from here.
PYPI_RUNTIME = [
    'ros-jazzy-rclpy[fastrtps]',
    'ros-jazzy-sensor-msgs',
    'ros-jazzy-geometry-msgs',
    'ros-jazzy-std-msgs',
    'ros-jazzy-visualization-msgs',
    'ros-jazzy-diagnostic-msgs',
    'numpy>=1.26',
    'opencv-python-headless>=4.8',
    'scipy>=1.11',
    'numba>=0.59',
    'PyYAML>=6',
    'rosbags>=0.10',
    'mcap>=1.2',
    'motmetrics==1.4.0',
    'pandas>=2',
    'matplotlib>=3.8',
    'tqdm>=4.66',
]

setup(
    name=package_name,
    version='0.1.0',
    # the data folders too (namespace packages), so that setuptools installs their files
    # without warning that they look like packages it was not told about
    packages=find_namespace_packages(include=[package_name, package_name + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    package_data={package_name: ['data/**/*']},
    include_package_data=True,
    python_requires='>=3.11',
    install_requires=['setuptools'],
    extras_require={'pypi': PYPI_RUNTIME,
                    'test': PYPI_RUNTIME + ['pytest>=7', 'hypothesis>=6']},
    zip_safe=True,
    maintainer='mbtrack_ros developers',
    maintainer_email='mbtrack@example.org',
    description='Multi-camera multi-person HJS tracking for ROS 2 Jazzy.',
    license='BSD-3-Clause',
    entry_points={
        'console_scripts': [
            'mbtrack = mbtrack_ros.cli:main',
            'tracker_node = mbtrack_ros.nodes.tracker_node:main',
            'bag_player = mbtrack_ros.nodes.bag_player:main',
            'camera_node = mbtrack_ros.nodes.camera_node:main',
        ],
    },
)
