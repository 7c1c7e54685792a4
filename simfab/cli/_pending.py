"""Shared behaviour of a subcommand whose pipeline is not built yet."""

from simfab.errors import InputError


def not_built(name: str) -> InputError:
    return InputError(f"the '{name}' pipeline is not built yet in this version of simfab")
