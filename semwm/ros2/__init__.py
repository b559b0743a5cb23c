"""ROS 2 bags in and out (``pip install "semwm[ros2]"``; pure Python, no ROS needed).

* :mod:`semwm.ros2.messages`: the ``vision_msgs`` message definitions and a
  typestore (``rosbags``) that (de)serialises them as CDR;
* :mod:`semwm.ros2.classmap`: the class-mapping file (a detector's class ids ->
  knowledge classes);
* :mod:`semwm.ros2.convert`: a ``Detection3DArray``/``Detection2DArray`` message ->
  semwm detections, counting what could not be used (:class:`BagReport`);
* :mod:`semwm.ros2.read`: a bag's detection (and sensor pose) topics -> replay records;
* :mod:`semwm.ros2.write`: published worlds -> a ROS 2 bag of ``Detection3DArray``.

``semwm replay BAG --ros2-detections /topic`` and ``--ros2-out BAG`` use them
(docs/ros2.md). Nothing here is imported by the core.
"""
