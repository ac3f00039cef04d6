"""Launch the vjm_ros simulator, optionally with the example controller.

    ros2 launch vjm_ros sim.launch.py                                    # four_bar (the node's default)
    ros2 launch vjm_ros sim.launch.py scene:=five_bar controller:=true   # five_bar, circle tracking
    ros2 launch vjm_ros sim.launch.py scene:=five_bar controller:=true lockstep:=true
    ros2 launch vjm_ros sim.launch.py namespace:=robot1                  # topics under /robot1
    ros2 launch vjm_ros sim.launch.py namespace:=robot2 publish_clock:=false   # a second simulator

/clock is absolute: in a graph of several simulators only one may publish it (the others get
``publish_clock:=false``; ``multi_sim.launch.py`` starts several that way), else subscribers see
simulated time step back and each simulator warns, naming the other.

The simulator reads config/sim_node.yaml; ``scene``, ``rate_hz``, ``lockstep`` and
``publish_clock`` override it. The controller runs on simulated time (``use_sim_time``, default
true: it follows ``/clock``, which must then come from its simulator). Uses only launch features of Humble, Jazzy and Kilted. Keep DDS discovery on the host
by exporting ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy and later) or
``ROS_LOCALHOST_ONLY=1`` (Humble) before launching. The ``launch`` packages are imported only here
(they are not needed to run the nodes).
"""

import os

DEFAULT_SCENE = "four_bar"
"""The node's own default scene (parameter ``scene``), so that a launch without arguments runs
what ``ros2 run vjm_ros vjm_sim_node`` runs."""


def generate_launch_description():
    from ament_index_python.packages import get_package_share_directory
    from launch.actions import DeclareLaunchArgument
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue

    from launch import LaunchDescription

    config = os.path.join(get_package_share_directory("vjm_ros"), "config", "sim_node.yaml")
    scene = LaunchConfiguration("scene")
    namespace = LaunchConfiguration("namespace")
    return LaunchDescription([
        DeclareLaunchArgument("scene", default_value=DEFAULT_SCENE,
                              description="Scene of the simulator (the controller needs five_bar)."),
        DeclareLaunchArgument("namespace", default_value="",
                              description="Namespace of both nodes (joint_states goes under it)."),
        DeclareLaunchArgument("rate_hz", default_value="1000.0", description="Tick rate, Hz."),
        DeclareLaunchArgument("lockstep", default_value="false",
                              description="Each tick waits for the controller's command."),
        DeclareLaunchArgument("publish_clock", default_value="true",
                              description="Publish /clock (false for every simulator of a graph "
                                          "but one)."),
        DeclareLaunchArgument("controller", default_value="false",
                              description="Start the example PD controller (scene five_bar)."),
        DeclareLaunchArgument("use_sim_time", default_value="true",
                              description="The controller follows the simulator's /clock."),
        Node(
            package="vjm_ros",
            executable="vjm_sim_node",
            name="vjm_sim_node",
            namespace=namespace,
            output="screen",
            parameters=[
                config,
                {
                    "scene": scene,
                    "rate_hz": ParameterValue(LaunchConfiguration("rate_hz"), value_type=float),
                    "lockstep": ParameterValue(LaunchConfiguration("lockstep"), value_type=bool),
                    "publish_clock": ParameterValue(LaunchConfiguration("publish_clock"),
                                                    value_type=bool),
                    # With the controller, hold the start pose until its first command arrives.
                    "wait_for_command": ParameterValue(LaunchConfiguration("controller"),
                                                       value_type=bool),
                },
            ],
        ),
        Node(
            package="vjm_ros",
            executable="vjm_pd_controller",
            name="vjm_pd_controller",
            namespace=namespace,
            output="screen",
            parameters=[{
                "scene": scene,
                "simulator": "vjm_sim_node",
                "use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"),
                                               value_type=bool),
            }],
            condition=IfCondition(LaunchConfiguration("controller")),
        ),
    ])
