"""`haptic_bridge`: the 1 kHz haptic loop between the physics (150 Hz) and the device driver.

Each tick of a RateLoop (own thread) takes the newest stylus sample of the device (`measured_cp_topic`, device frame),
places the tool tip in the liver frame with the device map `liver_tool` publishes (liver_sim.nodes.device_map_source:
taken from `device_map_node` only; zero force before one arrives), turns it and the
newest local model into a contact force (paper §2.5, P11 of docs/paper.md) — or, with `local_model: none`, holds the
newest physics contact wrench (the "without local model" baseline of Fig. 8, R4) — turns that force into the device
frame with the same map and sends it through SafeForceOutput (clamp, rate limit, watchdog, soft start) to the driver's
force topic. The loop reads its inputs itself, each only from its source node (`device_node`, `model_node`,
`device_map_node`), judged by each sample's writer (haptic_bridge.sources); each input's age counts from the reception
of its newest usable sample by DDS, and an implausible one is refused and counted (a device sample so refused is no
sample: the watchdog zeroes the force). The command is stamped with the
stamp of the input it was computed from (the device sample; the wrench in `none` mode), or the node's clock before
any: a rig measures the device → force latency by it. One hop: the device's own samples are the loop's input.

A Supervisor thread (haptic_bridge.supervisor) publishes zero whenever the loop stalls beyond stall_bound_s, raises, or
ends, and holds it until the loop is back; commands and zeros share one writer; on an ending signal (run_node) or close
the last message on it is a zero force, acknowledged before the context goes. Run-time parameter changes are checked
like start-up values and within the envelope fixed when the process started (haptic_bridge.tick.ENVELOPE), and applied
from the next tick, or refused with the reason. `haptic_bridge --managed` runs the same bridge as a lifecycle node:
activate starts the loop, deactivate and shutdown zero the force and stop it; its envelope is still the process's.
The tick itself is haptic_bridge.tick.BridgeTick; the parameters are haptic_bridge.parameters.PARAMETERS.
"""
from __future__ import annotations

import sys

from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node

from haptic_bridge.parameters import PARAMETERS, BridgeParameters
from haptic_bridge.tick import checked_change
from liver_sim.nodes.bridge_shell import BridgeShell
from liver_sim.nodes.parameters import declare_parameters, on_parameter_changes
from liver_sim.nodes.run import run_node


class HapticBridge(Node):
    """Device sample + newest local model (or physics wrench) → safe force command, at rate_hz, from start to close."""

    def __init__(self):
        super().__init__("haptic_bridge")
        self.p = BridgeParameters.from_values(declare_parameters(self, PARAMETERS))
        self.shell = BridgeShell(self, self.p)
        on_parameter_changes(self, PARAMETERS, self.shell.apply)
        self.get_logger().info(self.shell.describe())
        self.shell.start()

    def close(self) -> None:
        """Zero force on the wire, then stop the loop."""
        self.shell.stop("node closed (an ending signal or exit)")
        self.shell.destroy()


class ManagedHapticBridge(LifecycleNode):
    """The bridge as a lifecycle node: configure builds it (the force command's writer a lifecycle publisher, which
    sends only while active), activate runs the loop, deactivate and shutdown leave zero force on the wire and stop
    it, cleanup removes it. The envelope is the one of the process's start, in
    every state: a change while unconfigured is checked against it as a running bridge's would be. K·scale is checked
    at every parameter change (with every device map the loop may render with once configured) and at activation,
    which is refused while it is not passive."""

    def __init__(self):
        super().__init__("haptic_bridge")
        self.p = self.start_p = BridgeParameters.from_values(declare_parameters(self, PARAMETERS))
        self.shell = None
        on_parameter_changes(self, PARAMETERS, self._apply)

    def _apply(self, changes: dict) -> str | None:
        if self.shell is not None:
            return self.shell.apply(changes)
        self.p = checked_change(self.p, changes, 1.0, self.start_p)
        return None

    def on_configure(self, state) -> TransitionCallbackReturn:
        try:
            self.shell = BridgeShell(self, self.p, self.start_p)
        except ValueError as exc:
            self.get_logger().error(f"configure refused: {exc}")
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info(self.shell.describe())
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        activated = super().on_activate(state)  # the force publisher first: the loop's first tick is sent
        if activated != TransitionCallbackReturn.SUCCESS:
            return activated
        try:
            self.shell.start()  # checks K·scale with every map the loop may render with
        except ValueError as exc:
            super().on_deactivate(state)
            self.get_logger().error(f"activate refused: {exc}")
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.shell.stop("deactivated")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self.p = self.shell.p
        self.shell.destroy()
        self.shell = None
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        if self.shell is not None:
            self.shell.stop("shut down")
            self.shell.destroy()
            self.shell = None


def main(args=None) -> int:
    argv = list(sys.argv if args is None else args)
    managed = "--managed" in argv
    return run_node(ManagedHapticBridge if managed else HapticBridge, [a for a in argv if a != "--managed"])


if __name__ == "__main__":
    raise SystemExit(main())
