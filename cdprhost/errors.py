"""Error types shared by every layer; each maps to a CLI exit status.

Exit status contract (spec/cli-contract.md): 0 success, 1 the check or job itself
failed, 2 bad input (usage, unreadable or invalid file, invalid profile).
"""

from __future__ import annotations


class CdprError(Exception):
    """Base class. ``exit_code`` is what the CLI returns when this escapes."""

    exit_code = 1


class InputError(CdprError):
    """Bad input: a file, a profile, an argument. Message names the place and reason."""

    exit_code = 2

    def __init__(
        self, message: str, *, source: str | None = None, problems: list[str] | None = None
    ):
        self.source = source
        self.problems = list(problems or [])
        text = message if source is None else f"{source}: {message}"
        if self.problems:
            text += "\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(text)


class JobFailed(CdprError):
    """The job itself failed (violations found, print failed, no convergence)."""

    exit_code = 1
