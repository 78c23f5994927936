"""The simulator and controller nodes.

    ros2 launch gyro_sim gyro_sim.launch.py [scene:=NAME|PATH] [mode:=lockstep|realtime|freerun]
        [namespace:=NS] [use_controller:=true|false] [record:=BAG_DIR]
        [params_file:=SIMULATOR_PARAMS_YAML] [controller_params:=CONTROLLER_PARAMS_YAML]

The simulator takes ``params_file`` (default: the installed config/simulator.params.yaml); ``scene``, ``mode`` and
``record`` override it. The controller runs **the scene's own law and parameters** (its ``controller`` section)
unless ``controller_params`` names a parameter file (e.g. the installed config/controller.params.yaml: ψ-switching
with nutation_oblate's gains); ``scene`` overrides the file's.

DDS stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless the environment sets
ROS_AUTOMATIC_DISCOVERY_RANGE, as with ``gyro-sim run --ros``.

Ending: the launch ends when the simulator node ends (its run is over, or it failed): the controller is then
stopped (the project's controller also ends by itself after the simulator's final ``done:`` line). On Ctrl-C both
nodes get SIGINT from the terminal and end cleanly: the simulator closes its bag (marked
``interrupted: signal SIGINT``) and exits 130, the controller too (ros2 launch reports a node's non-zero status as
"process has died [..., exit code 130]": the run was interrupted, nothing was lost). ros2 launch escalates to
SIGTERM after ``sigterm_timeout`` s (harmless: a node already stopping ignores it) and to SIGKILL
``sigkill_timeout`` s later, which would leave the bag unfinished: the simulator gets :data:`SIM_SIGTERM_TIMEOUT`
+ :data:`SIM_SIGKILL_TIMEOUT` s (as ``gyro-sim run --ros``), the controller launch's defaults (5 + 5 s). A SIGKILL
of ros2 launch itself leaves the nodes running (``gyro-sim run --ros`` does not: gyro_sim/ros/launch.py).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, SetEnvironmentVariable, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import (EnvironmentVariable, EqualsSubstitution, LaunchConfiguration, NotEqualsSubstitution,
                                  PathJoinSubstitution)
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

DISCOVERY_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
#: s from the shutdown's SIGINT to SIGTERM, and from SIGTERM to SIGKILL, for the simulator: time to close a long
#: run's bag on a loaded machine (in all 30 s, gyro_sim.ros.launch.STOP_GRACE)
SIM_SIGTERM_TIMEOUT, SIM_SIGKILL_TIMEOUT = "10", "20"
ARGUMENTS = (  # name, default, description
    ("scene", "nutation_oblate", "built-in scene name or scene YAML path (both nodes)"),
    ("mode", "lockstep", "simulator timing mode: lockstep, realtime or freerun"),
    ("namespace", "", "namespace of both nodes ('' = none)"),
    ("use_controller", "true", "start the controller node (true/false)"),
    ("record", "", "bag directory the simulator records to ('' = no recording)"),
    ("controller_params", "", "parameter file of the controller ('' = the scene's own law and parameters)"),
)


def _params_file(name):
    """config/NAME of the installed gyro_sim package."""
    return PathJoinSubstitution([FindPackageShare("gyro_sim"), "config", name])


def _text(name):
    """The launch argument ``name`` as a string parameter (a scene named '1' stays a string)."""
    return ParameterValue(LaunchConfiguration(name), value_type=str)


def generate_launch_description():
    ns = LaunchConfiguration("namespace")

    ctl_params = LaunchConfiguration("controller_params")

    def controller(parameters, condition):
        return Node(package="gyro_ctl", executable="controller", name="gyro_controller", namespace=ns, output="screen",
                    parameters=parameters, condition=condition)

    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=desc) for name, default, desc in ARGUMENTS),
        DeclareLaunchArgument("params_file", default_value=_params_file("simulator.params.yaml"),
                              description="parameter file of the simulator (scene, mode, record override it)"),
        # the value already set, else LOCALHOST
        SetEnvironmentVariable(DISCOVERY_RANGE, EnvironmentVariable(DISCOVERY_RANGE, default_value="LOCALHOST")),
        Node(package="gyro_sim", executable="simulator", name="gyro_simulator", namespace=ns, output="screen",
             parameters=[LaunchConfiguration("params_file"),
                         {"scene": _text("scene"), "mode": _text("mode"), "record": _text("record")}],
             sigterm_timeout=SIM_SIGTERM_TIMEOUT, sigkill_timeout=SIM_SIGKILL_TIMEOUT,
             on_exit=Shutdown(reason="the simulator node ended")),
        GroupAction(condition=IfCondition(LaunchConfiguration("use_controller")), actions=[
            # the scene's own law and parameters
            controller([{"scene": _text("scene")}], IfCondition(EqualsSubstitution(ctl_params, ""))),
            # the user's parameter file, the scene from the launch argument
            controller([ctl_params, {"scene": _text("scene")}], IfCondition(NotEqualsSubstitution(ctl_params, ""))),
        ]),
    ])
