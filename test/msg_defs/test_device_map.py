"""msg_defs.device_map: the device → liver map as a labelled Float64MultiArray and back, refusals naming the
field."""
import math

import numpy as np
import pytest

from msg_defs.device_map import device_map_from_message, device_map_message


def test_device_map_round_trips_and_refuses_a_bad_message():
    from liver_sim.base.geometry.device_map import DeviceMap

    original = DeviceMap([0.0, math.sin(0.4), 0.0, math.cos(0.4)], [0.1, -0.2, 0.3], 0.5)
    message = device_map_message(original)
    back = device_map_from_message(message)
    np.testing.assert_allclose(back.rotation, original.rotation, atol=1e-12)
    np.testing.assert_array_equal(back.translation, original.translation)
    assert back.scale == 0.5
    message.data[7] = -1.0
    with pytest.raises(ValueError, match="scale"):
        device_map_from_message(message)
    message.data[7], message.data[4] = 0.5, float("nan")
    with pytest.raises(ValueError, match="finite"):
        device_map_from_message(message)
    message.layout.dim = message.layout.dim[:2]
    with pytest.raises(ValueError, match="layout"):
        device_map_from_message(message)


def test_a_device_map_message_is_labelled_and_a_zero_rotation_is_refused_by_name():
    from liver_sim.base.geometry.device_map import DeviceMap

    message = device_map_message(DeviceMap([0.0, 0.0, 0.0, 1.0], [0.1, -0.2, 0.3], 2.0))
    assert [(d.label, d.size) for d in message.layout.dim] == [("rotation_xyzw", 4), ("translation_m", 3),
                                                                ("scale", 1)]
    assert list(message.data) == [0.0, 0.0, 0.0, 1.0, 0.1, -0.2, 0.3, 2.0]
    message.data[3] = 0.0
    with pytest.raises(ValueError, match="^device map rotation_xyzw must be a non-zero quaternion"):
        device_map_from_message(message)
    message.data = [0.0, 0.0, 0.0, 1.0, 0.1, -0.2, 0.3]
    with pytest.raises(ValueError, match=r"^device map data must have shape \(8\), got \(7,\)"):
        device_map_from_message(message)
