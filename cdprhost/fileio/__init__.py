"""Small file helpers used by the shells (CLI, wizard, job)."""
