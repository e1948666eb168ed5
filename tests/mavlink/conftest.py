"""Shared fixtures: the trained Zshape model of the guidance tests (for the service-level security tests)."""

from tests.guidance.conftest import zshape_model  # noqa: F401 (a fixture, used by name)
