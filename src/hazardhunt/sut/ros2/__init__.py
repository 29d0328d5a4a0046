"""The ROS 2 bridge: the user's ROS 2 node(s) as the robot's controller, in lock-step simulated
time (docs/ros2.md).

:class:`~hazardhunt.sut.ros2.bridge.Ros2Controller` is the built-in controller ``ros2``. Nothing
here imports ROS 2's Python packages until a bridge is built; without them (the ``ros2``
extra), building one is a one-line error saying what to install.
"""
