"""Reading URDF text: what is accepted unchanged and what is refused, with which error."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from conftest import ur10_path

from kincal.errors import InputFileError, KincalError, UrdfError
from kincal.urdf_source import MAX_URDF_BYTES, check_urdf_text, read_urdf_text

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"
TIAGO = Path(__file__).resolve().parents[2] / "shared/data/tiago_mocap/tiago_48_schunk.urdf"

MINIMAL = '<?xml version="1.0"?>\n<robot name="r">\n  <link name="a"/>\n</robot>\n'


def write(tmp_path: Path, text: str, name: str = "robot.urdf") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8"))
    return path


# ---------------------------------------------------------------- accepted files


def test_real_urdfs_are_returned_unchanged():
    paths = [EC66, ur10_path()] + ([TIAGO] if TIAGO.exists() else [])
    for path in paths:
        assert read_urdf_text(path) == path.read_bytes().decode("utf-8")


def test_crlf_and_non_ascii_survive(tmp_path):
    text = MINIMAL.replace("\n", "\r\n").replace('name="a"', 'name="Gelenk_ä_✓"')
    path = write(tmp_path, "\ufeff" + text)  # with a UTF-8 byte-order mark too
    read = read_urdf_text(path)
    assert read == "\ufeff" + text
    assert read.count("\r\n") == 4


@pytest.mark.parametrize(
    "robot",
    [
        # generated URDFs keep the namespace declaration: that alone is fine
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="a"/></robot>',
        # a DOCTYPE without internal subset declares nothing
        '<!DOCTYPE robot>\n<robot name="r"><link name="a"/></robot>',
        # a plain "$" that is no substitution
        '<robot name="r"><link name="cost_$5"/></robot>',
    ],
)
def test_harmless_constructs_are_accepted(robot):
    check_urdf_text(robot)


# ---------------------------------------------------------------- file problems


def test_missing_file(tmp_path):
    path = tmp_path / "nope.urdf"
    with pytest.raises(InputFileError, match="no such file") as info:
        read_urdf_text(path)
    assert str(path) in str(info.value)


def test_directory(tmp_path):
    with pytest.raises(InputFileError, match="is a directory") as info:
        read_urdf_text(tmp_path)
    assert str(tmp_path) in str(info.value)


def test_unreadable_path(tmp_path):
    # a regular file used as a directory fails for every user, root included
    blocker = write(tmp_path, MINIMAL, "file.urdf")
    with pytest.raises(InputFileError, match="cannot read") as info:
        read_urdf_text(blocker / "robot.urdf")
    assert str(blocker) in str(info.value)


def test_too_large(tmp_path):
    path = tmp_path / "huge.urdf"
    with open(path, "wb") as f:
        f.truncate(MAX_URDF_BYTES + 1)  # sparse: no real disk use
    with pytest.raises(UrdfError, match="larger than 20 MB"):
        read_urdf_text(path)


def test_other_encoding_is_refused(tmp_path):
    path = tmp_path / "latin.urdf"
    path.write_bytes('<?xml version="1.0" encoding="ISO-8859-1"?><robot name="\xe4"/>'.encode("latin-1"))
    with pytest.raises(UrdfError, match="ISO-8859-1"):
        read_urdf_text(path)


def test_invalid_utf8_is_refused(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_bytes(b'<robot name="\xff"/>')
    with pytest.raises(UrdfError, match="not UTF-8 .*offset 13"):
        read_urdf_text(path)


# ---------------------------------------------------------------- content problems


def test_malformed_xml_names_file_line_and_column(tmp_path):
    path = write(tmp_path, '<robot name="r">\n  <link name="a">\n</robot>\n')
    with pytest.raises(UrdfError) as info:
        read_urdf_text(path)
    message = str(info.value)
    assert message.startswith(f"{path}:3:3: malformed XML")
    assert "mismatched tag" in message


def test_billion_laughs_is_rejected_before_expansion():
    levels = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{i} "{("&lol%d;" % (i - 1)) * 10}">' for i in range(1, 12)
    ]
    bomb = "<?xml version='1.0'?>\n<!DOCTYPE robot [\n" + "\n".join(levels) + "\n]>\n<robot name='&lol11;'/>"
    start = time.perf_counter()
    with pytest.raises(UrdfError, match="DOCTYPE with an internal subset") as info:
        check_urdf_text(bomb, source="bomb.urdf")
    # 10**11 expanded bytes would take minutes and all memory; refusing takes microseconds.
    # The bound is generous on purpose: it only catches an actual expansion.
    assert time.perf_counter() - start < 2.0
    assert str(info.value).startswith("bomb.urdf:2:")


@pytest.mark.parametrize(
    "doctype",
    [
        '<!DOCTYPE robot [<!ENTITY x "1">]>',
        '<!DOCTYPE robot [<!ENTITY x SYSTEM "file:///etc/passwd">]>',
        '<!DOCTYPE robot [<!ELEMENT robot ANY>]>',  # any internal subset, even without entities
    ],
)
def test_doctype_internal_subsets_are_rejected(doctype):
    with pytest.raises(UrdfError, match="DOCTYPE"):
        check_urdf_text(doctype + '<robot name="r"/>')


def test_external_dtd_is_rejected():
    # expat does not fetch it, and would silently drop the &x; it declares from the attribute
    text = '<!DOCTYPE robot SYSTEM "robot.dtd"><robot name="r"><link name="&x;"/></robot>'
    with pytest.raises(UrdfError, match="external DTD"):
        check_urdf_text(text)


def test_undefined_entity_is_malformed():
    with pytest.raises(UrdfError, match="^<string>:1:17: malformed XML: undefined entity"):
        check_urdf_text('<robot name="r"><link name="&x;"/></robot>')


XACRO_NS = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'


@pytest.mark.parametrize(
    "body, what",
    [
        ('<xacro:macro name="m" params="p"><link name="${p}"/></xacro:macro>', "<xacro:macro>"),
        ('<xacro:include filename="$(find pkg)/arm.xacro"/>', "<xacro:include>"),
        ('<xacro:property name="d" value="0.1"/>', "<xacro:property>"),
        ('<link name="a"><visual><origin xyz="0 0 ${d}"/></visual></link>', "${d}"),
        ('<link name="a"><visual><geometry><mesh filename="$(find pkg)/m.stl"/></geometry></visual></link>',
         "$(find pkg)"),
    ],
)
def test_xacro_left_in_is_rejected_with_a_hint(body, what):
    text = f'<robot name="r" {XACRO_NS}>\n  {body}\n</robot>'
    with pytest.raises(UrdfError) as info:
        check_urdf_text(text, source="arm.urdf")
    message = str(info.value)
    assert "xacro" in message and "xacro file.urdf.xacro > file.urdf" in message
    assert what.strip("<>") in message
    assert message.startswith("arm.urdf:2:")


def test_xacro_elements_under_another_prefix_are_rejected():
    text = '<robot name="r" xmlns:x="http://ros.org/wiki/xacro"><x:macro name="m"/></robot>'
    with pytest.raises(UrdfError, match="<x:macro>"):
        check_urdf_text(text)


def test_root_must_be_robot():
    with pytest.raises(UrdfError, match="root element is <sdf>, expected <robot>"):
        check_urdf_text('<sdf version="1.6"><model name="m"/></sdf>')


def test_every_refusal_is_a_kincal_error(tmp_path):
    for bad in ("", "<robot>", "<robot/><robot/>"):
        with pytest.raises(KincalError):
            read_urdf_text(write(tmp_path, bad))
