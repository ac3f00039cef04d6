"""The physics: the model, the compiled kernels (kinematics, dynamics, closures, fixed-step methods)
and the mechanism around them, closure settings and the integrators.

Imports nothing else of the package (docs/design.md section 7): no scene files, logs or ROS.
"""
