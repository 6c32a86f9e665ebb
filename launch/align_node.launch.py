"""Start ``align_node`` (CEMNet odometry), optionally with RViz2 and a bag replay.

    ros2 launch cemnet_ros align_node.launch.py input_topic:=/velodyne_points
    ros2 launch cemnet_ros align_node.launch.py bag:=my_run.mcap use_sim_time:=true rviz:=false
    ros2 launch cemnet_ros align_node.launch.py lifecycle:=true                  # managed, configured and activated
    ros2 launch cemnet_ros align_node.launch.py lifecycle:=true autostart:=false  # left unconfigured for a manager

``ros2 launch cemnet_ros align_node.launch.py --show-args`` lists the arguments. See docs/install_ros.md.

Every process started here (the node, RViz2, the bag player, and a driver included in this launch) uses the
package's Fast DDS profile for large clouds (``dds_profile``; docs/node.md: Large clouds) unless the shell
already names one in FASTRTPS_DEFAULT_PROFILES_FILE; ``dds_profile:=none`` (or an empty value from an including
launch file) unsets the variable: Fast DDS's defaults.

RViz2 starts where it is installed (``rviz:=auto``); ``rviz:=true`` without it fails before any process starts.
It gets a copy of the package's view whose topics and fixed frame are this launch's: the namespace it runs under,
``input_topic`` and ``odom_frame`` (cemnet_ros/rviz_config.py).

``lifecycle:=true`` starts ``align_lifecycle_node`` (a managed node, same name, parameters and topics) instead; with
``autostart:=true`` (the default) this launch file configures it once its process has started and activates it once
``configure`` has reached ``inactive`` (launch_ros lifecycle events), so one command gives a working node.
"""
import os

from ament_index_python.packages import PackageNotFoundError, get_package_prefix, get_package_share_directory
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    ExecuteProcess,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
    UnsetEnvironmentVariable,
)
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessStart
from launch.events import matches_action
from launch.substitution import Substitution
from launch.substitutions import LaunchConfiguration, NotEqualsSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from lifecycle_msgs.msg import Transition

from cemnet_ros.launch_choices import dds_profile_file, lifecycle_wanted, rviz_wanted
from cemnet_ros.rviz_config import write_resolved_config
from launch import LaunchDescription


def generate_launch_description():
    share = get_package_share_directory("cemnet_ros")  # the installed copy, not the source tree
    use_sim_time = LaunchConfiguration("use_sim_time")
    bag = LaunchConfiguration("bag")

    arguments = [
        DeclareLaunchArgument("input_topic", default_value="points",
                              description="sensor_msgs/PointCloud2 scans to align (sequential mode)"),
        DeclareLaunchArgument("params_file",
                              default_value=os.path.join(share, "config", "align_node.yaml"),
                              description="align_node parameters (ROS 2 params file); the arguments below "
                                          "override the file's input_topic, odom_frame, base_frame, use_sim_time"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="use the /clock topic (set true when replaying a bag)"),
        DeclareLaunchArgument("odom_frame", default_value="odom",
                              description="parent frame of the odometry and the TF (REP-105 odom)"),
        DeclareLaunchArgument("base_frame", default_value="base_link",
                              description="child frame of the odometry and the TF"),
        DeclareLaunchArgument("rviz", default_value="auto",
                              description="start RViz2 with the package's view: auto = where it is installed, "
                                          "true = required (fails before starting anything without it), false"),
        DeclareLaunchArgument("dds_profile",
                              default_value=os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or
                              os.path.join(share, "config", "fastdds_large_data.xml"),
                              description="Fast DDS profile (shared memory large enough for full-size scans); "
                                          "none = Fast DDS's defaults"),
        DeclareLaunchArgument("bag", default_value="",
                              description="rosbag2 to replay with 'ros2 bag play <bag> --clock' ('' = none); "
                                          "also set use_sim_time:=true, and input_topic to the bag's cloud topic"),
        DeclareLaunchArgument("lifecycle", default_value="false",
                              description="true = start align_lifecycle_node, the managed node (same name, "
                                          "parameters and topics), instead of align_node"),
        DeclareLaunchArgument("autostart", default_value="true",
                              description="with lifecycle:=true: configure and activate it from here (false = a "
                                          "lifecycle manager or 'ros2 lifecycle set' does it)"),
    ]

    # The params file, then the launch arguments: later entries win, so the arguments override the file.
    # Launch parses values as YAML; value_type=str keeps a topic or frame such as "1" or "on" a string.
    parameters = [
        LaunchConfiguration("params_file"),
        {
            "input_topic": ParameterValue(LaunchConfiguration("input_topic"), value_type=str),
            "odom_frame": ParameterValue(LaunchConfiguration("odom_frame"), value_type=str),
            "base_frame": ParameterValue(LaunchConfiguration("base_frame"), value_type=str),
            "use_sim_time": use_sim_time,
        },
    ]
    align_node = Node(package="cemnet_ros", executable="align_node", name="align_node", output="screen",
                      parameters=parameters)
    # namespace="" is the launch's own (a PushRosNamespace of an including file applies, as to align_node)
    lifecycle_node = LifecycleNode(package="cemnet_ros", executable="align_lifecycle_node", name="align_node",
                                   namespace="", output="screen", parameters=parameters)

    rviz = Node(
        package="rviz2",
        executable="rviz2",
        arguments=["-d", ResolvedRvizConfig(os.path.join(share, "rviz", "cemnet_ros.rviz"),
                                            LaunchConfiguration("input_topic"), LaunchConfiguration("odom_frame"))],
        parameters=[{"use_sim_time": use_sim_time}],  # the TF and the clouds carry the bag's stamps
        output="screen",
    )

    bag_play = ExecuteProcess(
        cmd=["ros2", "bag", "play", bag, "--clock"],  # --clock publishes /clock for use_sim_time
        output="screen",
        condition=IfCondition(NotEqualsSubstitution(bag, "")),
    )

    return LaunchDescription(arguments + [
        OpaqueFunction(function=_start, args=[rviz, bag_play, align_node, lifecycle_node])])


def _start(context, rviz, bag_play, align_node, lifecycle_node):
    """The DDS profile and the processes, once the arguments are checked (cemnet_ros/launch_choices.py): a bad
    argument raises here, before any process starts. The node comes last: an action that fails at start
    (launch then exits without stopping what already runs) cannot leave it behind."""
    profile = dds_profile_file(LaunchConfiguration("dds_profile").perform(context))
    environment = UnsetEnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE") if profile is None \
        else SetEnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE", profile)
    wanted = rviz_wanted(LaunchConfiguration("rviz").perform(context), _installed("rviz2"))
    lifecycle, autostart = lifecycle_wanted(LaunchConfiguration("lifecycle").perform(context),
                                            LaunchConfiguration("autostart").perform(context))
    node = [align_node]
    if lifecycle:  # the event handlers first: the node's start is one of their events
        node = (_autostart(lifecycle_node) if autostart else []) + [lifecycle_node]
    return [environment] + ([rviz] if wanted else []) + [bag_play] + node


def _autostart(node):
    """Drive a lifecycle node to active: configure once its process has started, activate once that configure
    has reached 'inactive' (not on a later deactivate, which also ends in 'inactive')."""
    def transition(transition_id):
        return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node), transition_id=transition_id))

    return [RegisterEventHandler(OnProcessStart(target_action=node,
                                                on_start=[transition(Transition.TRANSITION_CONFIGURE)])),
            RegisterEventHandler(OnStateTransition(target_lifecycle_node=node, start_state="configuring",
                                                   goal_state="inactive",
                                                   entities=[transition(Transition.TRANSITION_ACTIVATE)]))]


def _installed(package):
    try:
        get_package_prefix(package)
    except PackageNotFoundError:
        return False
    return True


class ResolvedRvizConfig(Substitution):
    """The package's RViz view with the topics of the node this launch starts, as a temporary file: performed when
    RViz2 starts, in the launch's namespace scope (cemnet_ros/rviz_config.py)."""

    def __init__(self, template, input_topic, odom_frame):
        super().__init__()
        self._template, self._input_topic, self._odom_frame = template, input_topic, odom_frame

    def perform(self, context):
        return write_resolved_config(self._template, context.launch_configurations.get("ros_namespace"),
                                     self._input_topic.perform(context), self._odom_frame.perform(context))
