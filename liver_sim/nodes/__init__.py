"""ROS 2 node shells: they translate between topics and the numerical core, nothing more."""
