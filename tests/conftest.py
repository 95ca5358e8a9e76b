"""Root of the test tree: the shared builders of tests/fixtures, registered as plugins.

Their pytest fixtures (``locust``, ``stick_insect``) are visible in every directory; test
modules import the plain builders from ``tests.fixtures.*`` themselves, never from a conftest
or another test module (tests/test_repo.py checks). Under ``--import-mode=importlib`` pytest
binds ``tests`` to this folder when it imports this file, before the plugins below, so they
are found here even where an installed package brings a ``tests`` of its own.
"""

import pytest

# before the plugins import them: their asserts get pytest's messages as well
pytest.register_assert_rewrite("tests.fixtures")

pytest_plugins = [
    "tests.fixtures.paths",
    "tests.fixtures.bodies",
    "tests.fixtures.cameras",
    "tests.fixtures.planted",
    "tests.fixtures.settings",
    "tests.fixtures.assertions",
    "tests.fixtures.projects",
    "tests.fixtures.keypoint_files",
]
