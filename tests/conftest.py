"""Shared fixtures: shipped profiles, the fixture G-code, workspace samplers."""

from __future__ import annotations

import importlib.util
import logging
import os
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from hypothesis import settings

from cdprhost.kinematics import MachineModel
from cdprhost.profile import load_profile

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("CDPRHOST_SHARED", REPO.parent / "shared"))


def load_script(path: Path, name: str) -> ModuleType:
    """A script outside the packages (``bench/``, ``firmware/tools/``) imported as the module
    ``name``, registered in ``sys.modules`` (a dataclass of its looks its module up there)."""
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


FIXTURE_GCODE = SHARED / "fixtures" / "part-prusaslicer.gcode"

settings.register_profile("ci", max_examples=200, deadline=None)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

PAPER_TRUTH_OUTLETS = np.array(
    [(-260.0, -150.111, 78.0), (260.0, -150.111, 78.0), (0.0, 300.222, 78.0)]
)


@pytest.fixture(autouse=True, scope="session")
def _isolated_state(tmp_path_factory):
    """Job logs, resume points and boards' records of every test (and the CLIs they start)
    go to temporary folders, never to the user's ~/.local/state or ~/.config."""
    os.environ["CDPRHOST_STATE"] = str(tmp_path_factory.mktemp("state"))
    # the session's own profiles too: a session-scoped fixture loads its profile before
    # any test's _isolated_profiles runs, and must not read a board's record left in the
    # user's folder by a print outside the tests
    os.environ["CDPRHOST_PROFILES"] = str(tmp_path_factory.mktemp("session-profiles"))


@pytest.fixture(autouse=True)
def _threads_and_log_handlers_end_with_their_test():
    """What a test leaves running ends with it: the stderr log handler a CLI it ran set up
    (on the test's captured stderr, closed with the test), then the printer services it ran
    in threads of this process (tests/service/inprocess.py), their prints cancelled and
    their threads joined. Before, such a thread logged an e-stop after the test, into a
    closed capture ("Logging error ... EstopFlag")."""
    cdprhost_log = logging.getLogger("cdprhost")
    before = set(cdprhost_log.handlers)
    yield
    for handler in set(cdprhost_log.handlers) - before:
        if getattr(handler, "_cdprhost_stderr", False):
            cdprhost_log.removeHandler(handler)
    inprocess = sys.modules.get("tests.service.inprocess")
    if inprocess is not None:
        inprocess.end_services()


@pytest.fixture(autouse=True)
def _isolated_profiles(tmp_path_factory, monkeypatch):
    """What a board announced is kept beside the profile: never in the user's folder, and
    never seen by another test (a print on a pty device records the board's limits, and a
    later estimate in the same worker would plan on them)."""
    monkeypatch.setenv("CDPRHOST_PROFILES", str(tmp_path_factory.mktemp("profiles")))


@pytest.fixture(scope="session")
def sim_profile():
    return load_profile("paper-simulation")


@pytest.fixture(scope="session")
def proto_profile():
    return load_profile("paper-prototype")


@pytest.fixture(scope="session")
def sim_model(sim_profile):
    return MachineModel.from_profile(sim_profile)


@pytest.fixture(scope="session")
def fixture_gcode() -> Path:
    if not FIXTURE_GCODE.is_file():
        pytest.skip(f"fixture not found: {FIXTURE_GCODE}")
    return FIXTURE_GCODE
