"""``simfab.validate``: simulators checked against closed-form mechanics, as functions.

:func:`buckling` pushes a discrete elastic rod of length L into gaps g < L (pinned or clamped
ends), directly and through the rigid insert of scenes/deploy/elastica.xml, and compares the
midspan rise delta and the axial force P with the exact elastica (g/L = 2E(k)/K(k) - 1,
delta/L = k/K(k); :mod:`simfab.deploy.elastica`), the observed convergence order in the segment
count n, and the critical load from the straight beam's Hessian (:mod:`simfab.deploy.buckling`).
Tolerances at n = VALIDATION_N: :mod:`simfab.deploy.tolerances`. ``simfab validate buckling`` is
this function and a table.
"""

from __future__ import annotations

import dataclasses
import os

from simfab.results import Result, field, to_json

__all__ = ["BucklingResult", "buckling"]

#: Columns of buckling.csv (one row per case), in order.
CSV_HEADER = ["support", "path", "g_over_L", "n", "delta_over_L", "delta_over_L_exact", "rel_err", "order", "force",
              "force_exact", "force_rel_err", "seconds", "newton_iterations", "tolerance", "passed"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class BucklingResult(Result):
    """The buckling validation's table and verdict.

    Args:
        passed: every case at n = VALIDATION_N within its tolerance.
        failures: one line per missed case.
        convergence_order: support -> median observed order of the rise error in n [-].
        insert_vs_direct_max_rel_diff: largest relative rise difference between the insert and the
            direct path [-] (None unless both ran).
        critical_load: per support: support, n, load figures [N], rel_err, tolerance.
        tolerances: n, pinned_rise, clamped_rise, force, critical_load [-].
        beam: the beam's setup (lengths [m], young [Pa], poisson, ...).
        scene: the elastica MJCF scene's path.
        rows: one per case (the CSV's columns: delta_over_L [-], force [N], rel_err [-], order, seconds [s], ...).
        shapes: (support, path, n, g/L) -> the deformed centreline (k, 2) [m] (for the plot).
        ratios, supports, paths, ns: the gap ratios g/L [-], supports, paths and segment counts that ran
            (for the plot; not in the JSON).
        outputs: csv, json, png when written.
    """

    passed: bool
    failures: list
    convergence_order: dict = field(unit="-")
    insert_vs_direct_max_rel_diff: float | None = field(unit="-")
    critical_load: list
    tolerances: dict = field(unit="-")
    beam: dict
    scene: str
    rows: list
    shapes: dict = field(json=False, default_factory=dict)
    ratios: tuple = field(json=False, default=())
    supports: tuple = field(json=False, default=())
    paths: tuple = field(json=False, default=())
    ns: tuple = field(json=False, default=())

    def to_json(self) -> dict:
        """The ``--json`` object: the summary, ``outputs``, then ``rows``.

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        outputs, rows = d.pop("outputs"), d.pop("rows")
        return {**d, "outputs": outputs, "rows": rows}


def buckling(*, g_over_L=None, n=None, support: str = "both", path: str = "both", scene=None, out=None,
             seed: int = 0, device: str = "cpu", progress: bool | None = None) -> BucklingResult:
    """Validate the discrete elastic rods against the exact elastica.

    Args:
        g_over_L: gap ratios g/L in (0, 1) (default :data:`simfab.deploy.buckling.DEFAULT_RATIOS`).
        n: segment counts (even, >= 4; default :data:`simfab.deploy.buckling.DEFAULT_N`).
        support: "pinned", "clamped" or "both".
        path: the end displacement applied "direct", through the rigid "insert", or "both".
        scene: the elastica MJCF scene (default scenes/deploy/elastica.xml).
        out: folder for buckling.csv, buckling.json and buckling_shapes.png; None writes nothing.
        seed: no effect, kept for the common signature: nothing is drawn at random (the continuation starts
            from a deterministic first-mode imperfection, :mod:`simfab.deploy.buckling`).
        device: Warp device.
        progress: True logs each case on stderr.

    Returns:
        The :class:`BucklingResult` (``passed`` False with ``failures`` when a case misses its tolerance).

    Raises:
        InputError: a bad ratio, segment count, support, path or scene (before any work).
    """
    import numpy as np

    from simfab._warp import device as check_device
    from simfab.deploy import buckling as bk
    from simfab.deploy import elastica
    from simfab.deploy import tolerances as tol
    from simfab.errors import InputError
    from simfab.progress import log

    del seed  # no effect (see Args)
    quiet = not progress
    ratios = list(g_over_L or bk.DEFAULT_RATIOS)
    ns = sorted(set(n or bk.DEFAULT_N))
    for r in ratios:  # checked before any work
        elastica.check_ratio(r)
    for k in ns:
        bk.check_segments(k)
    if support not in (*elastica.SUPPORTS, "both"):
        raise InputError(f"must be pinned, clamped or both, got {support!r}", where="--support")
    if path not in (*bk.PATHS, "both"):
        raise InputError(f"must be {', '.join(bk.PATHS)} or both, got {path!r}", where="--path")
    supports = elastica.SUPPORTS if support == "both" else (support,)
    paths = bk.PATHS if path == "both" else (path,)
    scene = bk.load_insert_scene(scene or bk.elastica_scene_path())
    setup = scene.setup
    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)

    dev = check_device(device)

    rows, shapes = [], {}
    for support in supports:
        for path in paths:
            for n in ns:
                log(f"buckling: {support} {path} n={n}", quiet=quiet)
                for row in bk.run_continuation(setup, support, n, ratios, path=path, device=dev, keep_states=True):
                    shapes[(support, path, n, row["g_over_L"])] = row.pop("shape")
                    row["tolerance"] = tol.RISE_RTOL[support] if n == tol.VALIDATION_N else None
                    rows.append(row)
    rows.sort(key=lambda r: (r["support"], r["path"], -r["g_over_L"], r["n"]))

    # observed convergence order between consecutive n (per support, path, g/L)
    orders = []
    for r in rows:
        prev = [q for q in rows if (q["support"], q["path"], q["g_over_L"]) == (r["support"], r["path"], r["g_over_L"])
                and q["n"] < r["n"]]
        r["order"] = None
        if prev:
            q = max(prev, key=lambda q: q["n"])
            if q["rel_err"] > 0 and r["rel_err"] > 0:
                r["order"] = float(np.log(q["rel_err"] / r["rel_err"]) / np.log(r["n"] / q["n"]))
                orders.append((r["support"], r["order"]))
    order_summary = {s: float(np.median([o for ss, o in orders if ss == s])) for s in supports
                     if any(ss == s for ss, _ in orders)}

    # insert path vs direct path
    insert_vs_direct = None
    if len(paths) == 2:
        diffs = []
        for r in rows:
            if r["path"] == "insert":
                d = next(q for q in rows if q["path"] == "direct" and (q["support"], q["n"], q["g_over_L"]) ==
                         (r["support"], r["n"], r["g_over_L"]))
                diffs.append(abs(r["delta_over_L"] - d["delta_over_L"]) / d["delta_over_L"])
        insert_vs_direct = float(max(diffs))

    crit = []
    n_crit = tol.VALIDATION_N if tol.VALIDATION_N in ns else max(ns)
    for support in supports:
        c = bk.critical_load(setup, n_crit, support, device=dev)
        c["tolerance"] = tol.CRITICAL_LOAD_RTOL if support == "pinned" else None
        crit.append(c)

    failures = []
    for r in rows:
        if r["n"] == tol.VALIDATION_N:
            r["passed"] = bool(r["rel_err"] <= tol.RISE_RTOL[r["support"]] and r["force_rel_err"] <= tol.FORCE_RTOL)
            if not r["passed"]:
                failures.append(f"{r['support']} {r['path']} g/L={r['g_over_L']} (rise {r['rel_err']:.2e}, "
                                f"force {r['force_rel_err']:.2e})")
        else:
            r["passed"] = None
    for c in crit:
        if c["tolerance"] is not None and c["n"] == tol.VALIDATION_N and c["rel_err"] > c["tolerance"]:
            failures.append(f"critical load {c['support']} ({c['rel_err']:.2e})")
    if insert_vs_direct is not None and insert_vs_direct > tol.INSERT_VS_DIRECT_RTOL:
        failures.append(f"insert path differs from direct path by {insert_vs_direct:.2e}")

    result = BucklingResult(
        passed=not failures, failures=failures, convergence_order=order_summary,
        insert_vs_direct_max_rel_diff=insert_vs_direct, critical_load=crit,
        tolerances=dict(n=tol.VALIDATION_N, pinned_rise=tol.PINNED_RISE_RTOL, clamped_rise=tol.CLAMPED_RISE_RTOL,
                        force=tol.FORCE_RTOL, critical_load=tol.CRITICAL_LOAD_RTOL),
        beam=dict(vars(setup)), scene=scene.path, rows=rows, shapes=shapes, ratios=tuple(ratios),
        supports=tuple(supports), paths=tuple(paths), ns=tuple(ns))
    return result if out is None else write_all(result, out)


def write_all(result: BucklingResult, out) -> BucklingResult:
    """Write buckling.csv, buckling.json (the summary and rows) and buckling_shapes.png together.

    Args:
        result: the validation's result.
        out: the output folder.

    Returns:
        ``result`` with ``outputs`` (csv, json, png).
    """
    from simfab.io.atomic import atomic_paths, write_csv, write_json

    out = os.path.abspath(out)
    outputs = dict(csv=os.path.join(out, "buckling.csv"), json=os.path.join(out, "buckling.json"),
                   png=os.path.join(out, "buckling_shapes.png"))
    result = dataclasses.replace(result, outputs=outputs)
    summary = result.to_json()
    summary.pop("outputs")
    with atomic_paths(outputs) as tmp:  # the three files appear together
        write_csv(tmp["csv"], CSV_HEADER, [[r[h] for h in CSV_HEADER] for r in result.rows])
        _plot(tmp["png"], result.shapes, result.rows, result.ratios, result.supports, result.paths, result.ns,
              result.beam["length"])
        write_json(tmp["json"], summary)
    return result


def _plot(path, shapes, rows, ratios, supports, paths, ns, L):
    import matplotlib

    from simfab.deploy import elastica
    from simfab.deploy import tolerances as tol
    from simfab.io.atomic import save_figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    n_show = tol.VALIDATION_N if tol.VALIDATION_N in ns else max(ns)
    fig, axes = plt.subplots(len(supports), 1, figsize=(8, 3.2 * len(supports)), squeeze=False)
    for ax, support in zip(axes[:, 0], supports):
        for i, r in enumerate(sorted(set(ratios), reverse=True)):
            ex = elastica.solve_elastica(r, support).shape(1.0, 301)
            ax.plot(ex[:, 0], ex[:, 1], color=f"C{i}", lw=1.5, label=f"exact g/L={r:.2f}")
            sim = shapes.get((support, paths[0], n_show, r))
            if sim is not None:
                ax.plot(sim[:, 0] / L, sim[:, 1] / L, "o", color=f"C{i}", ms=2.5, mfc="none")
        ax.set_title(f"{support} ends: exact elastica (lines) vs DER n={n_show} (markers, {paths[0]} path)")
        ax.set_xlabel("x / L")
        ax.set_ylabel("z / L")
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, path)
