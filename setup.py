from glob import glob

from setuptools import find_packages, setup

package_name = 'mbtrack_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
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
    zip_safe=True,
    maintainer='mbtrack_ros developers',
    maintainer_email='mbtrack@example.org',
    description='Multi-camera multi-person HJS tracking for ROS 2 Jazzy.',
    license='BSD-3-Clause',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'mbtrack = mbtrack_ros.cli:main',
            'tracker_node = mbtrack_ros.nodes.tracker_node:main',
            'bag_player = mbtrack_ros.nodes.bag_player:main',
        ],
    },
)
