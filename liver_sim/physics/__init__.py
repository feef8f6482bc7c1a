"""The heterogeneous mass-spring liver and its tools (paper §2), without ROS. Importing it first brings numba's cache
of the kernels in line with their sources (liver_sim.base.kernel_cache)."""
from liver_sim.base import kernel_cache

kernel_cache.refresh()
