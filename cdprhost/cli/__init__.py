"""Command-line shell: parses arguments, calls the core, maps errors to exit codes."""
