"""Upload names: whatever a client sends, an accepted name lands inside the upload folder."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cdprhost.server.uploads import BadName, NotGcode, UploadFolder, check_filename, check_folder

names = st.text(min_size=0, max_size=40).map(lambda t: t + ".gcode") | st.text(max_size=40)
folders = st.text(max_size=40) | st.lists(st.sampled_from(["a", "..", ".", "", "/", "b c"])).map(
    "/".join
)


@given(name=names, folder=folders)
def test_an_accepted_name_stays_inside_the_folder(tmp_path_factory, name, folder):
    root = tmp_path_factory.mktemp("up")
    uploads = UploadFolder(root)
    try:
        parts = check_folder(folder)
        checked = check_filename(name)
    except (BadName, NotGcode):
        return
    target = uploads.target(parts, checked)
    assert target.name == name
    assert root.resolve() in target.resolve().parents
    assert all(p not in ("..", ".") and "/" not in p and "\x00" not in p for p in parts)


@pytest.mark.parametrize("folder", ["", "/", "//", "sub", "/sub/", "a/b"])
def test_folder_forms_octoprint_accepts(folder):
    assert check_folder(folder) == tuple(p for p in folder.split("/") if p)


def test_a_symlink_out_of_the_folder_is_refused(tmp_path):
    root = tmp_path / "up"
    root.mkdir()
    (root / "link").symlink_to(tmp_path)
    with pytest.raises(BadName, match="outside the upload folder"):
        UploadFolder(root).target(("link",), "x.gcode")
