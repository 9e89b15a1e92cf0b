"""The transport port and its implementations (in-process ``local``; ``ros`` over rclpy)."""
