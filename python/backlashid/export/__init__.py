"""Export an identified model for use outside backlashid: a python-control system and
dependency-free C99 for embedded controllers.

Both run the model's one-step function on a flat state vector (:func:`state_vector`; the
layout is documented there and in rust/core/src/model/state_space.rs) and reproduce
``model.simulate``: python-control through the core's step, the C through the same
operations in the same order. The state vector of Example 1:

>>> model = bid.example1()
>>> bid.export.state_names(model)
['u(t-1)', 'u(t-2)', 'x(t-1)', 'x(t-2)', 'y(t-1)']
"""

from __future__ import annotations

# the implementation lives with the models, whose to_c / to_python_control methods call it
from ..models import state_from_vector, state_names, state_vector, to_c, to_python_control

__all__ = ["state_from_vector", "state_names", "state_vector", "to_c", "to_python_control"]
