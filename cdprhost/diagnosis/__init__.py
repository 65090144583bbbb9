"""Model discrepancy workflow (`cdprhost diagnose`): find, name, add, show.

- :mod:`workflow`: ``diagnose(obs, model, noise, settings) -> Diagnosis`` (the loop);
- :mod:`stat_tests`, :mod:`crossval`, :mod:`noise`: chi-square / F / BIC / Holm,
  grouped K-fold held-out error by pose and its noise floor, the sigma used;
- :mod:`signatures`: absorbed and confusable effects; :mod:`localise`: ``where``;
- :mod:`augment`, :mod:`report`, :mod:`plot`: profile, JSON/text, figure;
- :mod:`session_input`: a session folder -> observations; :mod:`scenarios`:
  hidden-effect simulations for tests and benchmarks.
"""
