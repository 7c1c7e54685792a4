"""``simfab demo``: run every built pipeline on the bundled default scenes.

Results go under ``--out`` (default ``./simfab-out/``), one folder per pipeline. The
JSON summary maps each pipeline to its own summary.
"""

from __future__ import annotations

import dataclasses
import os
import time

HELP = "run every built pipeline on the bundled default scenes (writes ./simfab-out/)"
DESCRIPTION = """Run every pipeline on small bundled cases, one folder per pipeline under --out
(default ./simfab-out/):
  grow      every bundled growth scene (scenes/growth/*.xml), then the sample sketch edit of
            the phone stand (scenes/growth/phone_stand_stroke.json)
  couple    2 of the bundled coupling scenes: cclamp2d (2D, tight grip) and clip3d (3D clip
            on a cylinder); then the rest-shape optimization of block2d_tight (the gradient
            method: a few insertions); 'simfab couple scenes' lists the others
  deploy    the bundled unit cell with its larger and smaller insert (dome vs saddle) and the
            dome surface scene (flattening, laser-cut pattern, deployment)
  crowd     the bundled 3D-printing survey (truth from the mesh, practitioners vs public,
            micro-crowd study) and the bracket-strength truth (FEM)
  validate  the buckling validation on a small table (n = 20, 40, 80; g/L = 0.9, 0.6)

--json keys: out (folder), pipelines {name: that pipeline's demo summary (its own output paths
and key figures, see 'simfab NAME --help'), with seconds}."""

def _units() -> dict:
    from simfab.cli import crowd, grow

    return {**grow.UNITS, **crowd.UNITS, "seconds": "s"}


#: units of summary keys for the plain-text table (the pipelines' own)
UNITS = _units()

#: Default --out: the demo's pipelines write side by side under ./simfab-out/<pipeline>.
DEFAULT_OUT = "simfab-out"

#: Pipelines in the order the demo runs them; each subcommand module may define demo(ctx).
PIPELINES = ("grow", "couple", "deploy", "crowd", "validate")


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
