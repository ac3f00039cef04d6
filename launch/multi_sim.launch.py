"""Launch several vjm_ros simulators in one graph, one namespace each, one ``/clock``.

    ros2 launch vjm_ros multi_sim.launch.py                                # /robot1 and /robot2
    ros2 launch vjm_ros multi_sim.launch.py namespaces:=a,b,c scene:=five_bar

Every topic of a simulator but ``/clock`` and ``/diagnostics`` goes under its namespace.
``/clock`` is absolute, so only the first simulator publishes it (``publish_clock`` true); the
others run with ``publish_clock:=false``. Two publishers of ``/clock`` would interleave two
simulated times (subscribers see time step back; each simulator warns, naming the other). Nodes
with ``use_sim_time`` follow the first simulator's time; the stamps of the others count their
own simulated time, from their own start.

Each simulator reads config/sim_node.yaml; ``scene`` and ``rate_hz`` override it. Uses only launch
features of Humble, Jazzy and Kilted; export ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy
and later) or ``ROS_LOCALHOST_ONLY=1`` (Humble) first.
"""

import os

DEFAULT_SCENE = "four_bar"
"""The node's own default scene (parameter ``scene``)."""


def simulators(namespaces: str) -> list:
    """``(namespace, publish_clock)`` of each simulator: ``/clock`` from the first one only.

    Parameters
    ----------
    namespaces : str
        Comma-separated namespaces (a leading ``/`` is optional).

    Raises
    ------
    ValueError
        No namespace, or one given twice.
    """
    names = [n.strip().strip("/") for n in namespaces.split(",")]
    names = [n for n in names if n]
    if not names:
        raise ValueError(f"namespaces: expected comma-separated namespaces, found {namespaces!r}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"namespaces: expected each namespace once, found {', '.join(twice)} "
                         "more than once")
    return [(name, i == 0) for i, name in enumerate(names)]


def generate_launch_description():
    from ament_index_python.packages import get_package_share_directory
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue

    from launch import LaunchDescription

    config = os.path.join(get_package_share_directory("vjm_ros"), "config", "sim_node.yaml")

    def nodes(context):
        return [
            Node(
                package="vjm_ros",
                executable="vjm_sim_node",
                name="vjm_sim_node",
                namespace=namespace,
                output="screen",
                parameters=[
                    config,
                    {
                        "scene": LaunchConfiguration("scene"),
                        "rate_hz": ParameterValue(LaunchConfiguration("rate_hz"), value_type=float),
                        "publish_clock": publish_clock,
                    },
                ],
            )
            for namespace, publish_clock in simulators(
                LaunchConfiguration("namespaces").perform(context))
        ]

    return LaunchDescription([
        DeclareLaunchArgument("namespaces", default_value="robot1,robot2",
                              description="Comma-separated namespaces, one simulator each; the "
                                          "first publishes /clock."),
        DeclareLaunchArgument("scene", default_value=DEFAULT_SCENE,
                              description="Scene of every simulator."),
        DeclareLaunchArgument("rate_hz", default_value="1000.0", description="Tick rate, Hz."),
        OpaqueFunction(function=nodes),
    ])
