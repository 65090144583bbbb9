"""The simulated world: the embedded device (:mod:`.embedded`), virtual motion capture
(:mod:`.virtual_mocap`), synthetic session folders (:mod:`.synthetic_session`), simulated
measurements (:mod:`.measurement`) and diagnosis scenarios (:mod:`.scenarios`).

Nothing in the product's core imports this package; tests, benchmarks, the CLI's
``sim-device`` and the demo paths do."""
