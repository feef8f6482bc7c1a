"""Shared geometry at the bottom of the layers (it imports only liver_sim.base.checks, liver_sim.base.parameters and
liver_sim.base.kernel_cache): rotations, the device map between the haptic device and the liver, numba closest-point
primitives; importing it first brings numba's cache of the kernels in line with their sources."""
from liver_sim.base import kernel_cache

kernel_cache.refresh()
