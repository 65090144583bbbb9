"""docs/cli.md documents every command and sub-command the parser has."""

from __future__ import annotations

import argparse
from pathlib import Path

from cdprhost.cli.main import COMMANDS, build_parser

DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def test_every_command_and_step_is_in_cli_md():
    text = DOC.read_text()
    missing = []
    for name in COMMANDS:
        parser = _subcommands(build_parser(name))[name]
        steps = _subcommands(parser)
        words = [f"cdprhost {name} {step}" for step in steps] or [f"cdprhost {name}"]
        missing += [w for w in words if f"`{w}" not in text]
    assert not missing, f"docs/cli.md leaves out: {missing}"
