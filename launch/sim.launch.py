"""Launch the vjm_ros simulator with the example controller.

    ros2 launch vjm_ros sim.launch.py                       # five_bar, realtime, circle tracking
    ros2 launch vjm_ros sim.launch.py lockstep:=true        # every tick waits for the controller
    ros2 launch vjm_ros sim.launch.py scene:=four_bar controller:=false

The simulator reads config/sim_node.yaml; ``scene``, ``rate_hz`` and ``lockstep`` override it.
Discovery stays on this host unless ``discovery_range`` says otherwise. The ``launch`` packages
are imported only here (they are not needed to run the nodes).
"""

import os


def generate_launch_description():
    from ament_index_python.packages import get_package_share_directory
    from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue

    from launch import LaunchDescription

    config = os.path.join(get_package_share_directory("vjm_ros"), "config", "sim_node.yaml")
    scene = LaunchConfiguration("scene")
    return LaunchDescription([
        DeclareLaunchArgument("scene", default_value="five_bar",
                              description="Scene of the simulator (the controller needs five_bar)."),
        DeclareLaunchArgument("rate_hz", default_value="1000.0", description="Tick rate, Hz."),
        DeclareLaunchArgument("lockstep", default_value="false",
                              description="Each tick waits for the controller's command."),
        DeclareLaunchArgument("controller", default_value="true",
                              description="Start the example PD controller."),
        DeclareLaunchArgument("discovery_range", default_value="LOCALHOST",
                              description="ROS_AUTOMATIC_DISCOVERY_RANGE of both nodes."),
        SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", LaunchConfiguration("discovery_range")),
        Node(
            package="vjm_ros",
            executable="vjm_sim_node",
            name="vjm_sim_node",
            output="screen",
            parameters=[
                config,
                {
                    "scene": scene,
                    "rate_hz": ParameterValue(LaunchConfiguration("rate_hz"), value_type=float),
                    "lockstep": ParameterValue(LaunchConfiguration("lockstep"), value_type=bool),
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
            output="screen",
            parameters=[{"scene": scene, "simulator": "vjm_sim_node"}],
            condition=IfCondition(LaunchConfiguration("controller")),
        ),
    ])
