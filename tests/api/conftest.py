"""Helpers of the public-API tests: run the CLI in-process and read its ``--json`` object."""

import json

import pytest

from simfab.cli import main


@pytest.fixture
def cli_json(capsys):
    """``cli_json(argv)`` -> the JSON object ``simfab ARGV --json`` prints (exit code 0 asserted)."""

    def run(argv):
        capsys.readouterr()
        assert main([*argv, "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    return run
