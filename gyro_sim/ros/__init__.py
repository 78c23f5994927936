"""ROS 2 adapters of the simulator core: the simulator node, the launcher, replay, the ament index (the only place
rclpy is imported, and only inside the nodes). May import ``gyro_sim.io`` and every layer below it; the layers
below never import this package (``gyro_sim.apps`` does: the ``gyro-sim`` command starts the nodes).
"""
