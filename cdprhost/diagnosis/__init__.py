"""Model discrepancy workflow (`cdprhost diagnose`): find, name, add, show.

- :mod:`workflow`: ``diagnose(obs, model, noise, settings) -> Diagnosis`` (the loop);
- :mod:`stat_tests`, :mod:`crossval`: chi-square / F / BIC / Holm, grouped K-fold
  held-out error by pose and its noise floor (the pose noise is calibration's
  :mod:`~cdprhost.calibration.pose_noise`, shared with identification);
- :mod:`signatures`: absorbed and confusable effects; :mod:`localise`: ``where``;
- :mod:`augment`, :mod:`report`, :mod:`plot`: profile, JSON/text, figure;
- :mod:`session_input`: a session folder -> observations (through the one session
  reader); hidden-effect simulations live in :mod:`cdprhost.sim.scenarios`.
"""
