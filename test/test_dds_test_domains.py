"""The DDS tests' ROS domains: FACE_REID_TEST_DOMAINS moves them (a range FIRST-LAST, default 1-100; a bad value
stops the run with one line), the environment's own ROS_DOMAIN_ID is never taken, and two test runs at once never
hold the same domain."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import _USERS_DOMAIN, DEFAULT_DOMAINS, DOMAINS_VARIABLE, REPO_ROOT, parse_test_domains, take_domain


def test_a_range_of_domains_is_read_and_bad_values_are_named() -> None:
    assert parse_test_domains(None) == parse_test_domains(" ") == DEFAULT_DOMAINS == range(1, 101)
    assert parse_test_domains("120-180") == range(120, 181)
    assert parse_test_domains(" 7 - 7 ") == range(7, 8)
    for bad in ("120", "120-", "-5", "a-b", "1.5-3", "180-120", "0-233", "120:180"):
        with pytest.raises(ValueError, match=rf"^{DOMAINS_VARIABLE}='{bad}': ") as caught:
            parse_test_domains(bad)
        assert "FIRST-LAST" in str(caught.value) or "0..232" in str(caught.value), caught.value
    with pytest.raises(ValueError, match="only this environment's ROS_DOMAIN_ID"):
        parse_test_domains("7-7", users_domain="7")


def test_a_domain_is_held_by_one_test_run_at_a_time(tmp_path: Path) -> None:
    domains = range(5, 8)
    first, first_lock = take_domain(domains, 0, lock_dir=tmp_path)
    second, second_lock = take_domain(domains, 0, users_domain="6", lock_dir=tmp_path)  # 6: the user's own
    assert (first, second) == (5, 7)
    with pytest.raises(TimeoutError, match=f"give {DOMAINS_VARIABLE} a range of its own"):
        take_domain(domains, 0, users_domain="6", lock_dir=tmp_path, wait_s=0.0)
    first_lock.close()  # the end of that test: free again
    assert take_domain(domains, 1, users_domain="6", lock_dir=tmp_path, wait_s=0.0)[0] == 5
    second_lock.close()


def _pytest(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args], cwd=REPO_ROOT,
                          env=env, capture_output=True, text=True, timeout=300)


def test_a_bad_range_stops_the_run_with_one_line() -> None:
    run = _pytest({**os.environ, DOMAINS_VARIABLE: "120"}, "--collect-only", "test/test_layout.py")
    assert run.returncode == pytest.ExitCode.USAGE_ERROR, run.stdout + run.stderr
    assert f"{DOMAINS_VARIABLE}='120': expected a range of ROS domain ids FIRST-LAST" in run.stderr, run.stderr
    assert "Traceback" not in run.stderr


@pytest.mark.ros
def test_the_fixture_takes_its_domain_from_the_range(ros_domain_id: int) -> None:
    """Run on its own by the test below (and in the suite, where it checks the same with the default range)."""
    assert ros_domain_id in parse_test_domains(os.environ.get(DOMAINS_VARIABLE), _USERS_DOMAIN)
    assert os.environ["ROS_DOMAIN_ID"] == str(ros_domain_id) != _USERS_DOMAIN
    if out := os.environ.get("FACE_REID_TEST_DOMAIN_OUT"):
        Path(out).write_text(str(ros_domain_id))


@pytest.mark.ros
def test_the_variable_moves_the_tests_domains(tmp_path: Path) -> None:
    out = tmp_path / "domain"
    env = {**os.environ, DOMAINS_VARIABLE: "150-151", "ROS_DOMAIN_ID": "150", "FACE_REID_TEST_DOMAIN_OUT": str(out)}
    run = _pytest(env, f"{Path(__file__).relative_to(REPO_ROOT)}::test_the_fixture_takes_its_domain_from_the_range")
    assert run.returncode == 0, run.stdout + run.stderr
    assert out.read_text() == "151"  # in the range, and not the environment's own 150
