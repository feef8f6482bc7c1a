"""The live view: the scene (no ROS), its Foxglove server and its picture."""
