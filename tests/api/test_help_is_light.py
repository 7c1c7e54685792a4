"""``simfab --help`` and every ``simfab CMD --help`` answer without importing Warp, MuJoCo or OpenUSD
(each in a fresh interpreter: the modules a command's help imports)."""

import subprocess
import sys

import pytest

from simfab.cli import SUBCOMMANDS

CODE = """
import contextlib, io, sys
from simfab.cli import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    main({argv!r})
print(sorted({{m.split('.')[0] for m in sys.modules}} & {{'warp', 'mujoco', 'pxr'}}))
"""


@pytest.mark.parametrize("argv", [["--help"]] + [[c, "--help"] for c in SUBCOMMANDS], ids=lambda a: " ".join(a))
def test_help_loads_no_simulator(argv):
    out = subprocess.run([sys.executable, "-c", CODE.format(argv=argv)], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", f"simfab {' '.join(argv)} imports {out.stdout.strip()}"
