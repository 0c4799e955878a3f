"""Property files: what must hold (safety, reach, reach-avoid, event bounds), model-independent."""

from reach.spec.properties import (BoundEvent, BoundReach, BoundReachAvoid, BoundSafety, Property,
                                   bind, load_properties)

__all__ = ["Property", "BoundSafety", "BoundReach", "BoundReachAvoid", "BoundEvent", "bind",
           "load_properties"]
