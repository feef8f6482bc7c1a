"""`liver-sim replay`: republish a bag's messages (serialized, as recorded) with their original timing.

Message k goes out at start + (t_k − t_0)/rate on an absolute schedule, so a slow publish delays
the next messages without shifting the rest.  Product topics keep their QoS of docs/contract.md;
other topics are published reliable, volatile, keep-last 10.

Device commands (DEVICE_COMMAND_TOPICS, in any namespace: /left/phantom/servo_cf of a two-hand session too) are
never republished on their own topics: a replay next to a rig would drive its device past the bridge's clamp, rate
limit and watchdog.  They are left out, or, with `remap_device_commands`, published on that topic instead (the
baseline's on that topic + "_without_local_model"; a namespace's under the namespace: /left + TOPIC).
"""
from __future__ import annotations

import itertools
import time
from pathlib import Path

import rclpy
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.stop_request import stop_on_signals
from liver_sim.base.topic_names import BASELINE_FORCE_TOPIC
from liver_sim.nodes.occupants import refuse_occupied
from liver_sim.sessions.bag import bag_info, read_messages
from liver_sim.sessions.record import _rclpy_qos, known_topic, message_class
from msg_defs.topics import TOPICS

REPLAY_NODE = "liver_sim_replay"
#: Recorded force commands: a replay never publishes them where a device driver listens, in any namespace.
DEVICE_COMMAND_TOPICS = (TOPICS["servo_cf"].name, BASELINE_FORCE_TOPIC)


def device_command_namespace(topic: str) -> str | None:
    """The namespace prefix ('' for the root, '/left') of a device command topic (DEVICE_COMMAND_TOPICS under any
    namespace), or None for another topic."""
    for command in DEVICE_COMMAND_TOPICS:
        if topic == command or topic.endswith(command):
            return topic.removesuffix(command)
    return None


def output_topics(wanted: list[str], remap_device_commands: str | None, progress=print) -> dict[str, str]:
    """{recorded topic: topic to publish it on} for the `wanted` topics: device commands left out, or moved
    to `remap_device_commands`; ValueError when the commands are asked for by name without a remap, or the
    remap is itself a device command topic."""
    commands = [t for t in wanted if device_command_namespace(t) is not None]
    if remap_device_commands is None:
        out = {t: t for t in wanted if t not in commands}
        if commands:
            progress(f"left out the device commands {', '.join(commands)} (--remap-device-commands TOPIC "
                     "replays them on another topic)")
        if not out:
            raise ValueError(f"{', '.join(commands)}: device commands are never replayed on their own topic; "
                             "give --remap-device-commands TOPIC to replay them on another topic")
        return out
    servo = TOPICS["servo_cf"].name
    out = {t: device_command_namespace(t) + remap_device_commands + t.removeprefix(device_command_namespace(t) + servo)
           if t in commands else t for t in wanted}
    remapped = [out[t] for t in commands]
    if any(device_command_namespace(t) is not None or t in wanted for t in [remap_device_commands, *remapped]):
        raise ValueError(f"--remap-device-commands {remap_device_commands}: must be a topic no device and no "
                         "other replayed topic uses")
    return out


def run_replay(bag: Path, rate: float = 1.0, topics: list[str] | None = None, delay_s: float = 1.0,
               progress=print, remap_device_commands: str | None = None) -> dict[str, int]:
    """Publish the bag's messages (only `topics` if given) at `rate` × their recorded pace after `delay_s`
    (time for subscribers to match), device commands only on `remap_device_commands` (see
    :func:`output_topics`); stop early on SIGINT/SIGTERM.  Returns {recorded topic: messages published}."""

    if not rate > 0.0:
        raise ValueError(f"--rate must be > 0, got {rate!r}")
    info = bag_info(bag)
    out_topics = output_topics(sorted(info.topics) if topics is None else topics, remap_device_commands, progress)
    wanted = list(out_topics)
    messages = read_messages(bag, wanted)  # streamed: a long session need not fit in memory
    first = next(messages, None)
    if first is None:
        raise ValueError(f"{bag}: holds no messages on {', '.join(out_topics.values())}")
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    sent = dict.fromkeys(wanted, 0)
    with stop_on_signals() as stop:
        try:
            node = rclpy.create_node(REPLAY_NODE, context=context, start_parameter_services=False)
            refuse_occupied(node, "a replay")  # before any publisher shows itself to the running nodes
            publishers = {}
            for topic in wanted:
                msgtype = info.topics[topic][0]
                spec = known[1] if (known := known_topic(topic)) is not None else None
                qos = _rclpy_qos(spec, spec.depth) if spec else 10
                publishers[topic] = node.create_publisher(message_class(msgtype), out_topics[topic], qos)
            t0 = first.timestamp_ns
            span = (info.start_ns + info.duration_ns - t0) * 1e-9 / rate
            progress(f"replaying {sum(info.topics[t][1] for t in wanted)} messages of {bag} ({span:.1f} s at rate "
                     f"{rate:g}) on {', '.join(out_topics.values())}")
            stop.wait(delay_s)
            start = time.monotonic()
            next_progress = start + 5.0
            for message in itertools.chain([first], messages):
                due = start + (message.timestamp_ns - t0) * 1e-9 / rate
                if stop.wait(max(0.0, due - time.monotonic())):
                    break
                publishers[message.topic].publish(message.data)
                sent[message.topic] += 1
                if time.monotonic() >= next_progress:
                    next_progress += 5.0
                    progress(f"  {time.monotonic() - start:6.1f} / {span:.1f} s")
            stop.wait(0.5)  # let reliable messages reach their subscribers before the publishers go
            node.destroy_node()
        finally:
            messages.close()
            context.try_shutdown()
    progress("published " + ", ".join(f"{t} {n}" for t, n in sent.items()))
    return sent
