"""reach: formal reachability comparison suite for spacecraft guidance and control.

One hybrid-automaton model format (``reach.model``), one property format (``reach.spec``),
interchangeable verification back-ends (``reach.backends``) returning one ``Result`` type
(``reach.result``), and a benchmark runner (``reach.bench``).
"""

__version__ = "0.1.0"
