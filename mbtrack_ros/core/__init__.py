"""The algorithm core: cameras, shape and appearance models, filters, detection.

Pure numpy/OpenCV/numba; nothing here imports ROS (a test checks it).
"""
