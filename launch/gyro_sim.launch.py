"""The simulator and controller nodes with their parameter files (config/*.params.yaml).

    ros2 launch gyro_sim gyro_sim.launch.py [scene:=NAME|PATH] [mode:=lockstep|realtime|freerun]
        [namespace:=NS] [use_controller:=true|false] [record:=BAG_DIR]

DDS stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless the environment sets
ROS_AUTOMATIC_DISCOVERY_RANGE, as with ``gyro-sim run --ros``. The launch arguments override the
parameter files' values.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import EnvironmentVariable, LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

DISCOVERY_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
ARGUMENTS = (  # name, default, description
    ("scene", "nutation_oblate", "built-in scene name or scene YAML path (both nodes)"),
    ("mode", "lockstep", "simulator timing mode: lockstep, realtime or freerun"),
    ("namespace", "", "namespace of both nodes ('' = none)"),
    ("use_controller", "true", "start the controller node (true/false)"),
    ("record", "", "bag directory the simulator records to ('' = no recording)"),
)


def _params_file(name):
    """config/NAME of the installed gyro_sim package."""
    return PathJoinSubstitution([FindPackageShare("gyro_sim"), "config", name])


def _text(name):
    """The launch argument ``name`` as a string parameter (a scene named '1' stays a string)."""
    return ParameterValue(LaunchConfiguration(name), value_type=str)


def generate_launch_description():
    ns = LaunchConfiguration("namespace")
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=desc) for name, default, desc in ARGUMENTS),
        # the value already set, else LOCALHOST
        SetEnvironmentVariable(DISCOVERY_RANGE, EnvironmentVariable(DISCOVERY_RANGE, default_value="LOCALHOST")),
        Node(package="gyro_sim", executable="simulator", name="gyro_simulator", namespace=ns, output="screen",
             parameters=[_params_file("simulator.params.yaml"),
                         {"scene": _text("scene"), "mode": _text("mode"), "record": _text("record")}]),
        Node(package="gyro_ctl", executable="controller", name="gyro_controller", namespace=ns, output="screen",
             parameters=[_params_file("controller.params.yaml"), {"scene": _text("scene")}],
             condition=IfCondition(LaunchConfiguration("use_controller"))),
    ])
