"""Sessions: record, replay, re-simulate and report rosbag2 bags (MCAP or sqlite3, with metadata.yaml).

`bag` reads, writes and checks bags through the `rosbags` library (no rclpy); `record` and `replay`
are the rclpy shells; `resimulate` and `report` work on a bag's messages without a ROS graph.
"""
