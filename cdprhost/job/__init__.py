"""The print job: a state machine (``state``), its log (``log``), and the runner.

Public API used by the CLI and the TUI:

- :class:`cdprhost.job.runner.PrintJob` ``(gcode, profile, link_factory, options, on_event)``:
  ``run() -> PrintResult`` (blocking; run it in a worker thread), and the one safe-stop
  path, thread-safe: ``request_pause()``, ``request_resume()``,
  ``request_cancel(reason="")`` (stop within the motion sent, :mod:`cdprhost.job.stopping`),
  ``emergency_stop()``, ``shutdown(reason, timeout_s)`` (quit and signals: cancel and wait;
  close the link only after it returns), ``wait()``, ``finished``, ``last_stop``.
  :func:`cdprhost.job.before_start.before_start` tells a screen what to ask before a start
  (a device fault, a saved resume point). Every change is reported as an event
  (:mod:`cdprhost.job.state`) through ``on_event``; fold events with
  ``state.reduce`` into a :class:`~cdprhost.job.state.JobSnapshot` to display.
- :class:`cdprhost.job.runner.PrintOptions`: resume-from-layer, log path,
  resume-point folder, ``clear_fault`` (False: a faulted device is refused, not cleared).
- :class:`cdprhost.job.runner.PrintResult`: the contract's ``print --json``
  fields (status, segments, retransmits, final_steps, last_line, last_layer,
  print_time_s, violations).
"""
