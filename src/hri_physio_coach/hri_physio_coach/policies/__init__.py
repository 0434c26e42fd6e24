"""Adaptation policies: what a rule update does with the heart rate it sees.

- :mod:`~hri_physio_coach.policies.types`: rule inputs, controls, proposals, decisions and the
  :class:`~hri_physio_coach.policies.types.Policy` protocol;
- :mod:`~hri_physio_coach.policies.simple`: the thesis's ``threshold`` (Algorithm 1), ``fuzzy``
  (Algorithm 2) and ``static`` (control condition);
- :mod:`~hri_physio_coach.policies.predictive` (with its
  :mod:`~hri_physio_coach.policies.response_model`): acts on the predicted steady-state heart rate;
- :mod:`~hri_physio_coach.policies.adapter`: any policy plus the thesis's proposed fixes, on the ladder;
- :mod:`~hri_physio_coach.policies.registry`: policies by name.

Nothing is re-exported here, so no module of the subpackage imports another through this one.
"""
