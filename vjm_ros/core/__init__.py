"""The physics: model, kinematics, dynamics, closures, the compiled kernels and the integrators.

Imports nothing else of the package (docs/design.md section 7): no scene files, logs or ROS.
"""
