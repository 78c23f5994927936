"""ROS 2 controller node (imports rclpy)."""
