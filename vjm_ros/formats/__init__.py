"""Models of other formats: SDFormat, URDF and MJCF in (``vjm import``), URDF and MJCF out.

In: a reader per format (:mod:`~vjm_ros.formats.sdformat`, :mod:`~vjm_ros.formats.urdf_in`,
:mod:`~vjm_ros.formats.mjcf_in`) gives one :class:`~vjm_ros.formats.graph.JointGraph`;
:mod:`~vjm_ros.formats.carriages` turns massless carriages into the closures they stand for,
:mod:`~vjm_ros.formats.joint_graph` reduces the graph to planar chains and closures and
:mod:`~vjm_ros.formats.scene_document` writes the scene document;
:mod:`~vjm_ros.formats.importing` picks the reader by extension (what
:func:`vjm_ros.scene.load_scene` calls for a ``.sdf``, ``.urdf`` or ``.xml`` path).
Out: :mod:`~vjm_ros.formats.urdf_out`, :mod:`~vjm_ros.formats.mjcf_out`.
The layer sits above ``scene`` (it builds scenes) and below ``sim``.
"""
