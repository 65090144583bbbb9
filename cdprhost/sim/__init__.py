"""The simulated world: the embedded device (:mod:`.embedded`), virtual motion capture
(:mod:`.virtual_mocap`), synthetic session folders (:mod:`.synthetic_session`), simulated
measurements (:mod:`.measurement`), diagnosis scenarios (:mod:`.scenarios`) and the AVR
firmware run in simavr (:mod:`.avr_device`).

Nothing in the product's core imports this package; tests, benchmarks, the CLI's
``sim-device`` and the demo paths do."""
