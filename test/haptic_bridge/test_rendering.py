"""haptic_bridge.rendering: passive model updates, the glide between local models, the penalty force, the passivity
bounds and the energy a contact stores."""
import numpy as np
import pytest

from liver_sim.base.local_model import LocalModel, penetration


def test_a_passive_model_update_stores_no_more_than_the_hand_put_in():
    from haptic_bridge.rendering import PassiveModelUpdate, contact_potential

    tip = np.array([0.0, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])

    def plane(height):
        return LocalModel("plane", True, up * height, up, up * height, 0.0, 0.0, True, 100.0)

    def depth(model):
        return penetration(model, tip)[0]

    def admit(update, height, budget_j):
        return depth(update.admit(plane(height), depth, lambda m: 100.0, budget_j))

    update = PassiveModelUpdate(max_force_n=2.0)
    assert admit(update, 0.004, 0.0) == pytest.approx(0.0) and update.held_back  # first contact: up to touching
    assert admit(update, -0.001, 0.0) == 0.0 and not update.held_back            # away from the tool: at once
    update.shown = plane(0.002)                                                   # 2 mm deep, storing 0.2 mJ
    paid = contact_potential(0.003, 100.0, 2.0)                                   # the hand put in 0.45 mJ
    assert admit(update, 0.005, paid) == pytest.approx(0.003) and update.held_back  # 5 mm asked: 3 mm paid
    assert admit(update, 0.001, 0.0) == pytest.approx(0.001)                         # backing off: at once
    assert admit(update, 0.005, 1.0) == pytest.approx(0.005) and not update.held_back
