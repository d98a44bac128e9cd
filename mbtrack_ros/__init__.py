"""mbtrack_ros: multi-camera multi-person tracking with the Hybrid Joint-Separable filter.

Layers, imported in one direction only:

* :mod:`mbtrack_ros.core` - the algorithms (numpy/OpenCV/numba, no ROS import);
* :mod:`mbtrack_ros.recording`, :mod:`mbtrack_ros.synth`, :mod:`mbtrack_ros.evaluation` -
  bag and file I/O, synthetic recordings, CLEAR-MOT scoring;
* :mod:`mbtrack_ros.nodes` and :mod:`mbtrack_ros.cli` - ROS 2 nodes and the ``mbtrack`` command.
"""

__version__ = '0.1.0'
