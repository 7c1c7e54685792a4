"""``simfab demo``: run every built pipeline on the bundled default scenes.

Results go under ``--out`` (default ``./simfab-out/``), one folder per pipeline. The
JSON summary maps each pipeline to its own summary.
"""

from __future__ import annotations

import dataclasses
import os
import time

HELP = "run every built pipeline on the bundled default scenes (writes ./simfab-out/)"
DESCRIPTION = """Run every built pipeline (grow, couple, deploy, crowd) on its bundled default scenes.
Results go to --out (default ./simfab-out/), one folder per pipeline.

--json keys: out (folder), pipelines {name: that pipeline's demo summary (its own output paths
and key figures, see 'simfab NAME --help'), with seconds}."""

#: Default --out: the demo's pipelines write side by side under ./simfab-out/<pipeline>.
DEFAULT_OUT = "simfab-out"

#: Pipelines in the order the demo runs them; each subcommand module may define demo(ctx).
PIPELINES = ("grow", "couple", "deploy", "crowd")


@dataclasses.dataclass(frozen=True, kw_only=True)
class DemoContext:
    """What a pipeline's ``demo`` gets: where to write and how to behave."""

    out: str
    seed: int = 0
    device: str = "cpu"
    quiet: bool = False


def add_args(p):
    p.add_argument("--only", nargs="+", choices=PIPELINES, help="run only these pipelines")


def run(args):
    from simfab.cli import subcommand_module
    from simfab.progress import log

    out = args.out
    summary = {"out": out, "pipelines": {}}
    for name in args.only or PIPELINES:
        mod = subcommand_module(name)
        demo = getattr(mod, "demo", None)
        if demo is None:
            summary["pipelines"][name] = {"status": "not built yet"}
            continue
        log(f"simfab demo: {name} ...", quiet=args.quiet)
        t0 = time.perf_counter()
        ctx = DemoContext(out=os.path.join(out, name), seed=args.seed, device=args.device, quiet=args.quiet)
        res = demo(ctx)
        res = dict(res or {})
        res.setdefault("seconds", time.perf_counter() - t0)
        summary["pipelines"][name] = res
    return summary
