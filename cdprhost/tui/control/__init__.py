"""Adapters between the UI and the lower layers (no drawing here)."""
