"""ROS 2 message definitions (``ros2msg`` schema text) of every type the logs carry.

An MCAP file of the ROS 2 profile stores, for each channel, the ``.msg`` text of its type followed
by the text of every type it depends on, each introduced by a line of 80 ``=`` and a
``MSG: <package>/<Type>`` line (the layout rosbag2 writes, which rerun's reader also expects). The texts below are the interface
definitions of ROS 2 Kilted with comments removed, so the logs can be written without a ROS
installation.
"""

from __future__ import annotations

SEPARATOR = "=" * 80

_TEXT: dict[str, str] = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/msg/String": "string data\n",
    "std_msgs/msg/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    "std_msgs/msg/MultiArrayDimension": "string label\nuint32 size\nuint32 stride\n",
    "std_msgs/msg/MultiArrayLayout": "MultiArrayDimension[] dim\nuint32 data_offset\n",
    "std_msgs/msg/Float64MultiArray": "MultiArrayLayout layout\nfloat64[] data\n",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/Wrench": "Vector3 force\nVector3 torque\n",
    "geometry_msgs/msg/WrenchStamped": "std_msgs/Header header\nWrench wrench\n",
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n"
    ),
    "sensor_msgs/msg/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data\n",
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock\n",
    "visualization_msgs/msg/UVCoordinate": "float32 u\nfloat32 v\n",
    "visualization_msgs/msg/MeshFile": "string filename\nuint8[] data\n",
    "visualization_msgs/msg/Marker": (
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n"
        "int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n"
        "int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n"
        "int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n"
        "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n"
        "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n"
        "builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n"
        "std_msgs/ColorRGBA[] colors\nstring texture_resource\n"
        "sensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\n"
        "string mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n"
    ),
    "visualization_msgs/msg/MarkerArray": "Marker[] markers\n",
}

_DEPENDS: dict[str, tuple[str, ...]] = {
    "std_msgs/msg/Header": ("builtin_interfaces/msg/Time",),
    "std_msgs/msg/MultiArrayLayout": ("std_msgs/msg/MultiArrayDimension",),
    "std_msgs/msg/Float64MultiArray": ("std_msgs/msg/MultiArrayLayout",),
    "geometry_msgs/msg/Pose": ("geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"),
    "geometry_msgs/msg/Wrench": ("geometry_msgs/msg/Vector3",),
    "geometry_msgs/msg/WrenchStamped": ("std_msgs/msg/Header", "geometry_msgs/msg/Wrench"),
    "sensor_msgs/msg/JointState": ("std_msgs/msg/Header",),
    "sensor_msgs/msg/CompressedImage": ("std_msgs/msg/Header",),
    "rosgraph_msgs/msg/Clock": ("builtin_interfaces/msg/Time",),
    "visualization_msgs/msg/Marker": (
        "std_msgs/msg/Header",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Vector3",
        "std_msgs/msg/ColorRGBA",
        "builtin_interfaces/msg/Duration",
        "geometry_msgs/msg/Point",
        "sensor_msgs/msg/CompressedImage",
        "visualization_msgs/msg/UVCoordinate",
        "visualization_msgs/msg/MeshFile",
    ),
    "visualization_msgs/msg/MarkerArray": ("visualization_msgs/msg/Marker",),
}


def dependencies(type_name: str) -> list[str]:
    """Every type ``type_name`` depends on, depth first, each once.

    Parameters
    ----------
    type_name : str
        Full ROS 2 type name, e.g. ``"sensor_msgs/msg/JointState"``.

    Returns
    -------
    list of str
    """
    seen: list[str] = []

    def visit(name: str) -> None:
        for dep in _DEPENDS.get(name, ()):
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(type_name)
    return seen


def definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type, dependencies included.

    Parameters
    ----------
    type_name : str
        Full ROS 2 type name, e.g. ``"geometry_msgs/msg/WrenchStamped"``.

    Returns
    -------
    str

    Raises
    ------
    KeyError
        For a type this module does not define.
    """
    parts = [_TEXT[type_name]]
    for dep in dependencies(type_name):
        package, _, name = dep.split("/")
        parts.append(f"{SEPARATOR}\nMSG: {package}/{name}\n{_TEXT[dep]}")
    return "".join(parts)


def known_types() -> list[str]:
    """Names of the types defined here."""
    return sorted(_TEXT)
