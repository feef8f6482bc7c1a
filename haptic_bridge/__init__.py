"""The haptic bridge's core without ROS: one tick of the 1 kHz loop (tick), local-model rendering (rendering),
the safety stage before the device (safety) and the bridge's parameters (parameters).

The `haptic_bridge` node that runs it is liver_sim.nodes.bridge_node.
"""
