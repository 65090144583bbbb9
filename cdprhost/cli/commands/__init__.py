"""One module per top-level command. Each defines ``register(subparsers)``.

``register`` adds its parser and sets ``func=run`` where ``run(args) -> int``.
Modules here are discovered automatically by ``cdprhost.cli.main``.
"""
