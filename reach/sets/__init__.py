"""Set representations, one module per type."""

from reach.sets.box import Box
from reach.sets.hpolytope import HPolytope
from reach.sets.star import Star, chord_hull

__all__ = ["Box", "HPolytope", "Star", "chord_hull"]
