"""Pure algorithms of asmonc_vision: numpy, OpenCV and filterpy only (no rclpy, no messages)."""
