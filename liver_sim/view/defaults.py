"""The live view's defaults (no ROS, no Foxglove): where it serves and how often."""

#: Scenes per second by default: more than the 20 a smooth view needs, a fifth of the physics' frames.
VIEW_RATE_HZ = 30.0
#: The Foxglove app's default connection: ws://127.0.0.1:8765.
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
