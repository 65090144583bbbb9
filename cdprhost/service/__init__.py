"""The printer service: the job, the link and the device state in their own process, with
front ends (``cdprhost print``, the TUI, the upload server, a web page) as its clients.

- :mod:`~cdprhost.service.wire`: the versioned messages (pydantic), one JSON line each;
- :mod:`~cdprhost.service.paths`: where a device's service listens, its key;
- :mod:`~cdprhost.service.journal`: the job's events, compacted for a late front end;
- :mod:`~cdprhost.service.device_session`: the device's link between prints, its machine
  operations and its status for every client;
- :mod:`~cdprhost.service.printer_service`: the service (``python -m cdprhost.service``);
- :mod:`~cdprhost.service.client`: ``attach(port, who, replay=...)`` finds or starts the
  service of a device and returns a :class:`~cdprhost.service.client.ServiceClient`.
"""
