"""The node publishes a joint's stop like a closure: an entry ``<joint>_stop`` of
``~/constraint_forces`` and a ``~/closures/<joint>_stop/wrench``, read by real rclpy
subscribers. The node runs in this process on its own ``ROS_DOMAIN_ID`` (``conftest.py``), with
the harness of ``test_ros_node.py``. Oracle: statics (``test_stop_forces.py``).
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from test_ros_node import NODE, Harness  # noqa: E402
from test_stop_forces import MGP, ROD, STOP  # noqa: E402
from waiting import wait_for  # noqa: E402

pytestmark = pytest.mark.ros

WRENCH = f"{NODE}/closures/pivot_stop/wrench"


def test_the_node_publishes_the_stop_force_of_a_rod_resting_on_its_stop(tmp_path):
    path = tmp_path / "rod.yaml"
    path.write_text(ROD)
    h = Harness(scene=str(path), realtime=False, duration=1.0, publish_clock=False,
                command_timeout=0.0)
    try:
        assert WRENCH in h.got  # the harness listens to every closure and stop
        h.start()
        assert h.join() == 0
        ticks = 1001  # t = 0, then 1000 ticks
        wait_for(lambda: len(h.messages(WRENCH)) >= ticks, 10.0, "stop wrenches")
        wait_for(lambda: len(h.messages(f"{NODE}/constraint_forces")) >= ticks, 10.0, "forces")
        wrenches = h.messages(WRENCH)[:ticks]
        forces = h.messages(f"{NODE}/constraint_forces")[:ticks]
        assert [(d.label, d.size) for d in forces[0].layout.dim] == [("pivot_stop", 3)]
        moment = np.array([w.wrench.torque.z for w in wrenches])
        np.testing.assert_array_equal(moment, [f.data[2] for f in forces])
        assert moment[0] == 0.0 and np.all([w.wrench.force.x == 0.0 for w in wrenches])
        # at rest on the stop from 0.5 s (test_stop_forces.py): s = m g p cos(stop)
        np.testing.assert_allclose(moment[600:], MGP * np.cos(STOP), rtol=1e-9)
    finally:
        h.close()
