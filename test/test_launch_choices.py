"""The launch file's decisions (cemnet_ros/launch_choices.py): RViz2 only where it is installed unless asked for,
an empty or 'none' DDS profile unsets the variable, a missing profile file is refused, the lifecycle node is brought
up by the launch file unless autostart is false."""
import pytest

from cemnet_ros.launch_choices import LaunchChoiceError, dds_profile_file, lifecycle_wanted, rviz_wanted


@pytest.mark.parametrize("value, installed, wanted", [
    ("auto", True, True), ("auto", False, False), ("AUTO", False, False),
    ("true", True, True), ("True", True, True), ("1", True, True),
    ("false", True, False), ("false", False, False), ("0", False, False),
])
def test_rviz_starts_only_where_installed_or_when_asked(value, installed, wanted):
    assert rviz_wanted(value, installed) is wanted


def test_rviz_true_without_rviz2_fails_clearly():
    with pytest.raises(LaunchChoiceError, match="rviz2 package is not installed.*nothing was started"):
        rviz_wanted("true", installed=False)


def test_an_unknown_rviz_value_is_refused():
    with pytest.raises(LaunchChoiceError, match="expected auto, true or false"):
        rviz_wanted("maybe", installed=True)


@pytest.mark.parametrize("value", ["", "''", '""', "none", " None "])
def test_an_empty_or_none_dds_profile_unsets_the_variable(value):
    assert dds_profile_file(value) is None


def test_a_dds_profile_file_is_kept_and_a_missing_one_refused(tmp_path):
    profile = tmp_path / "profile.xml"
    profile.write_text("<dds/>")
    assert dds_profile_file(str(profile)) == str(profile)
    with pytest.raises(LaunchChoiceError, match="no such file"):
        dds_profile_file(str(tmp_path / "missing.xml"))


@pytest.mark.parametrize("lifecycle, autostart, wanted", [
    ("false", "true", (False, False)), ("false", "false", (False, False)),
    ("true", "true", (True, True)), ("True", "1", (True, True)), ("true", "false", (True, False)),
])
def test_autostart_brings_up_only_the_lifecycle_node(lifecycle, autostart, wanted):
    assert lifecycle_wanted(lifecycle, autostart) == wanted


@pytest.mark.parametrize("lifecycle, autostart, name", [("yes please", "true", "lifecycle"), ("true", "", "autostart")])
def test_a_lifecycle_or_autostart_value_that_is_not_a_boolean_is_refused(lifecycle, autostart, name):
    with pytest.raises(LaunchChoiceError, match=f"{name}:=.*expected true or false"):
        lifecycle_wanted(lifecycle, autostart)
