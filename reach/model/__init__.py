"""The common hybrid-automaton model format: dataclasses, YAML loader, safe expressions."""

from reach.model.automaton import HybridAutomaton, Mode, Transition
from reach.model.loader import load_model

__all__ = ["HybridAutomaton", "Mode", "Transition", "load_model"]
