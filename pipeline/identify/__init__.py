"""Dynamic identification: excitation design, regressor, fit, validation (``pipeline identify``).

Data flows one way: robot spec -> regressor and base parameters (:mod:`.regressor`) ->
samples from recordings and a weighted least-squares fit made physically consistent
(:mod:`.fit`) -> an identified model file (:mod:`.model_file`) -> validation on other
recordings (:mod:`.validate`). :mod:`.excitation` designs and records the motions.
"""

from __future__ import annotations
