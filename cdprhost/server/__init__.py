"""The print server: the slicer upload API (the OctoPrint REST subset slicers use).

A shell package (it imports job, link, machine and preflight; nothing below imports it).
``cdprhost serve`` runs it as a client of the printer service
(:class:`~cdprhost.server.service_printer.ServicePrinter`: every job runs in the service);
``cdprhost tui --listen`` runs it inside the terminal UI with the TUI's own printer.

- :mod:`.apikey`: the key (made at first use, mode 0600, rotatable, constant-time check);
- :mod:`.guard`: the key and size gate in front of every route (401/403/413);
- :mod:`.uploads`: the upload folder, name checks, staging;
- :mod:`.printer`: the interface the routes use (:class:`~.printer.Printer`, ``Refused``);
- :mod:`.service_printer`: the printer of ``serve``, a client of the printer service;
- :mod:`.headless`: a printer that runs jobs in this process (the in-process tests and
  benches); :mod:`.jobcontrol`: its one safe-stop adapter;
- :mod:`.shapes`: OctoPrint's reply shapes; :mod:`.app`: the routes (why FastAPI: there);
- :mod:`.listen`: ``[HOST:]PORT``, binding, the server thread.
"""
