"""The haptic bridge's numerical core: local-model rendering at 1 kHz and the safety stage (no ROS)."""
from haptic_bridge.local_model import (
    FrameMap,
    PlaneModel,
    SphereModel,
    contact_force,
    max_passive_stiffness,
    passivity_damping_min,
    penetration,
    quaternion_to_matrix,
)
from haptic_bridge.safety import (
    DEFAULT_MAX_FORCE_N,
    PHANTOM_MAX_FORCE_N,
    RateLimiter,
    SafeForceOutput,
    Watchdog,
    clamp_norm,
)

__all__ = [
    "DEFAULT_MAX_FORCE_N",
    "FrameMap",
    "PHANTOM_MAX_FORCE_N",
    "PlaneModel",
    "RateLimiter",
    "SafeForceOutput",
    "SphereModel",
    "Watchdog",
    "clamp_norm",
    "contact_force",
    "max_passive_stiffness",
    "passivity_damping_min",
    "penetration",
    "quaternion_to_matrix",
]
