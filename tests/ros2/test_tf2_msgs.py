"""tf2_msgs built from its interface definition (``omnical ros2 build-tf2-msgs``): the same
type as Jazzy's, and a missing tool said in one line."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from ros2_env import needs_ros2

from omnical.errors import ConfigError
from omnical.ros2.interfaces import (
    BUILT_AGAINST,
    TF2_MSGS_SOURCE,
    build_tf2_msgs,
    tf2_msgs_installed,
    tf2_msgs_stale,
)

# Jazzy's tf2_msgs/msg/TFMessage, as a Jazzy `ros2 topic info /tf --verbose` and its bags'
# metadata.yaml (type_description_hash) give it: DDS matches a publisher and a subscriber on
# the type's name and this hash, so a TF listener of a real ROS 2 system takes ours.
JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


@needs_ros2
def test_the_built_tfmessage_is_jazzys_type() -> None:
    if not tf2_msgs_installed():
        if os.environ.get("CI"):
            pytest.fail("no tf2_msgs on CI: make runs `omnical ros2 build-tf2-msgs`")
        pytest.skip("no tf2_msgs: omnical ros2 build-tf2-msgs")
    prefixes = [sys.prefix, *os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)]
    found = [Path(p) / "share" / "tf2_msgs" / "msg" / "TFMessage.json" for p in prefixes if p]
    description = next(p for p in found if p.is_file())  # built here, or a system ROS 2's
    types = json.loads(description.read_text(encoding="utf-8"))["type_hashes"]
    hashes = {t["type_name"]: t["hash_string"] for t in types}
    assert hashes["tf2_msgs/msg/TFMessage"] == JAZZY_TFMESSAGE_HASH


def test_the_interface_definition_ships_with_the_package() -> None:
    assert (TF2_MSGS_SOURCE / "msg" / "TFMessage.msg").read_text(encoding="utf-8") == (
        "geometry_msgs/TransformStamped[] transforms\n"
    )
    assert (TF2_MSGS_SOURCE / "package.xml").is_file()
    assert (TF2_MSGS_SOURCE / "CMakeLists.txt").is_file()


def test_a_prefix_without_the_build_tools_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError, match=r"^no geometry_msgs in .*: pip install 'omnical\[ros2\]'"
    ):
        build_tf2_msgs(tmp_path)


# A stand-in for cmake (the real build is make's, ≈ 10 s): configure does nothing, the build
# exits $FAKE_BUILD_STATUS, the install writes one file under $DESTDIR + the prefix.
FAKE_CMAKE = """#!/bin/sh
case "$1" in
  --build) exit "${FAKE_BUILD_STATUS:-0}" ;;
  --install) /bin/mkdir -p "$DESTDIR$FAKE_PREFIX/share/tf2_msgs" "$DESTDIR$FAKE_PREFIX/lib" \
    && echo built > "$DESTDIR$FAKE_PREFIX/share/tf2_msgs/marker" \
    && echo library > "$DESTDIR$FAKE_PREFIX/lib/libtf2.so.1" \
    && /bin/ln -s libtf2.so.1 "$DESTDIR$FAKE_PREFIX/lib/libtf2.so" ;;
esac
"""


def _fake_venv(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tools: tuple[str, ...]) -> Path:
    """A prefix with the build tools' folders, its ``bin`` holding ``tools`` (cmake the
    stand-in, the others no-ops), the only folder on PATH."""
    prefix = tmp_path / "venv"
    for needed in ("geometry_msgs", "rosidl_default_generators", "ament_cmake"):
        (prefix / "share" / needed / "cmake").mkdir(parents=True)
    bin_dir = prefix / "bin"
    bin_dir.mkdir()
    for tool in tools:
        (bin_dir / tool).write_text(FAKE_CMAKE if tool == "cmake" else "#!/bin/sh\n")
        (bin_dir / tool).chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(bin_dir / "python"))
    monkeypatch.setenv("PATH", str(bin_dir))
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setenv("FAKE_PREFIX", str(prefix))
    return prefix


def test_without_cmake_it_says_how_to_get_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prefix = _fake_venv(tmp_path, monkeypatch, ("cc", "c++"))
    with pytest.raises(ConfigError, match=r"^cmake not found: pip install 'omnical\[ros2\]'"):
        build_tf2_msgs(prefix)


def test_without_a_cxx_compiler_it_says_which_packages(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prefix = _fake_venv(tmp_path, monkeypatch, ("cmake", "cc"))  # rosidl builds C++ too
    with pytest.raises(
        ConfigError, match=r"C and C\+\+ compilers .*\(Debian: g\+\+ python3-dev\)$"
    ):
        build_tf2_msgs(prefix)


def test_a_failed_step_is_one_line_naming_its_kept_log_and_installs_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prefix = _fake_venv(tmp_path, monkeypatch, ("cmake", "cc", "c++"))
    monkeypatch.setenv("FAKE_BUILD_STATUS", "1")
    with pytest.raises(ConfigError) as caught:
        build_tf2_msgs(prefix)
    line = str(caught.value)
    assert line.startswith("building tf2_msgs failed while compiling (exit 1): see ")
    assert "\n" not in line
    log = Path(line.rsplit("see ", 1)[1])
    assert "--build" in log.read_text(encoding="utf-8")
    shutil.rmtree(log.parent)  # kept for the user; not for the test's next run
    assert not (prefix / "share" / "tf2_msgs").exists()


def test_the_install_is_staged_and_copied_into_the_prefix(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prefix = _fake_venv(tmp_path, monkeypatch, ("cmake", "cc", "c++"))
    said: list[str] = []
    assert build_tf2_msgs(prefix, say=said.append) == prefix
    assert (prefix / "share" / "tf2_msgs" / "marker").read_text() == "built\n"
    assert (prefix / "lib" / "libtf2.so").readlink() == Path("libtf2.so.1")
    assert said == [
        "tf2_msgs: configuring",
        "tf2_msgs: compiling",
        "tf2_msgs: installing",
        "tf2_msgs: copying into the environment",
    ]


def test_a_build_again_leaves_the_files_a_running_process_mapped_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each file is replaced by a new one (a rename), not rewritten: a running `ros2 twin`
    that mapped the old library keeps it (a rewrite in place crashed one, SIGSEGV)."""
    prefix = _fake_venv(tmp_path, monkeypatch, ("cmake", "cc", "c++"))
    build_tf2_msgs(prefix)
    library = prefix / "lib" / "libtf2.so.1"
    with library.open("rb") as mapped:
        build_tf2_msgs(prefix)
        assert os.fstat(mapped.fileno()).st_ino != library.stat().st_ino
        assert mapped.read() == b"library\n"
    assert (prefix / "lib" / "libtf2.so").resolve() == library
    assert not list(prefix.rglob("*.omnical-new"))


def test_a_build_records_the_wheels_it_was_built_against(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """After an upgrade of the ROS 2 wheels the command builds again: the stamp says what
    changed; one built here without a stamp is stale, none here (a system ROS 2's) is not."""
    prefix = _fake_venv(tmp_path, monkeypatch, ("cmake", "cc", "c++"))
    assert tf2_msgs_stale(prefix) is None  # nothing built here
    build_tf2_msgs(prefix)
    assert tf2_msgs_stale(prefix) is None
    stamp = prefix / "share" / "tf2_msgs" / "omnical-built-against"
    lines = stamp.read_text(encoding="utf-8").splitlines()
    stamp.unlink()  # built by an omnical before the stamp
    assert tf2_msgs_stale(prefix) == "built before omnical recorded the wheels' versions"
    stamp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    lines = stamp.read_text(encoding="utf-8").splitlines()
    assert [line.split("==")[0] for line in lines] == list(BUILT_AGAINST)
    now = lines[0].split("==")[1]
    stamp.write_text("\n".join(["ros-rclpy==0.0.1", *lines[1:]]) + "\n", encoding="utf-8")
    assert tf2_msgs_stale(prefix) == f"ros-rclpy 0.0.1 → {now}"


@needs_ros2
def test_the_command_builds_nothing_when_tf2_msgs_is_there() -> None:
    if not tf2_msgs_installed():
        pytest.skip("no tf2_msgs: omnical ros2 build-tf2-msgs")  # the test above fails on CI
    run = "from omnical.cli.entry import main; main()"
    done = subprocess.run(
        [sys.executable, "-c", run, "ros2", "build-tf2-msgs"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "tf2_msgs is installed: nothing to build (--force to build it again)\n"
