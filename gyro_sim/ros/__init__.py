"""ROS 2 adapters of the simulator core (imports rclpy; the core never imports this package)."""
