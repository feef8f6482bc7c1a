"""Shared geometry at the bottom of the layers (it imports only liver_sim.base.checks and liver_sim.base.parameters):
rotations, the device map between the haptic device and the liver, numba closest-point primitives."""
