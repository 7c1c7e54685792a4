"""Fixtures of the sweep tests: a tiny, fast sweep spec (synthetic crowds, no simulation)."""

import pytest

TINY_SPEC = """
[sweep]
name = "tiny"
command = ["crowd", "simulate", "--scale", "1", "10", "--tasks", "4"]
seed = 3

[parameters.practitioners]
set = "--practitioners"
values = [0, 3, 6]

[parameters.public]
set = "--public"
values = [0, 10]

[collect]
raters = "raters"
malicious = "malicious"
first_task = "tasks.0"

[derived]
malicious_share = "malicious / raters"
"""


@pytest.fixture
def tiny_spec(tmp_path):
    """Six runs of 'crowd simulate'; practitioners = public = 0 fails (no raters: bad input)."""
    p = tmp_path / "tiny.toml"
    p.write_text(TINY_SPEC)
    return p
