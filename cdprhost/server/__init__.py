"""The print server: the slicer upload API (the OctoPrint REST subset slicers use).

A shell package (it imports job, link, machine and preflight; nothing below imports it).
``cdprhost serve`` runs it headless with :class:`~cdprhost.server.headless.HeadlessPrinter`;
``cdprhost tui --listen`` runs it inside the terminal UI with the TUI's own printer.

- :mod:`.apikey`: the key (made at first use, mode 0600, rotatable, constant-time check);
- :mod:`.guard`: the key and size gate in front of every route (401/403/413);
- :mod:`.uploads`: the upload folder, name checks, staging;
- :mod:`.printer`: the interface the routes use (:class:`~.printer.Printer`, ``Refused``);
- :mod:`.headless`: the printer of ``serve``; :mod:`.jobcontrol`: the one safe-stop adapter;
- :mod:`.shapes`: OctoPrint's reply shapes; :mod:`.app`: the routes (why FastAPI: there);
- :mod:`.listen`: ``[HOST:]PORT``, binding, the server thread.
"""
