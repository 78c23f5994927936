"""What leaves or enters a run: the topic contract and message contents (``messages``), rosbag2/MCAP recording and
reading (``recording``, which re-exports ``bag_writer``, ``bag_reader`` and ``signals``; ``bag_repair``), a
RunResult from a bag (``results``), the re-run check, the live view and the plots. May import ``gyro_sim.engine``
and every layer below it; never rclpy (that is ``gyro_sim.ros``).
"""
