"""Measurements of the simulator: the speed/accuracy bench and the MuJoCo comparison."""
