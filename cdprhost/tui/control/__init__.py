"""Control of the terminal UI: the backend seam, its implementation on the real layers, and
the controller (:class:`Controller`) that runs blocking calls in workers."""
