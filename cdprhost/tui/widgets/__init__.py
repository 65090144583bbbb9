"""Widgets of the terminal UI: panels and text charts."""
