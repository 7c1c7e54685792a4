"""Plots of a sweep table: each figure against the 1-2 swept parameters (PNG beside the table).

- one axis: the figure against x (lines; one line per value of a second swept parameter);
  a categorical figure (text, e.g. ``category``) as points on category rows;
- two axes on a full grid: a heat map (a categorical figure with one colour per category
  and a legend); not a grid (random samples): points coloured by the figure.

Failed runs are marked (red x on the axis, or hatched cells) with their count in the title.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simfab.io.atomic import save_figure


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _label(name: str, unit: str) -> str:
    return f"{name} [{unit}]" if unit else name


def _is_text(series) -> bool:
    return not np.issubdtype(np.asarray(series.dropna()).dtype, np.number) if series.notna().any() else False


def plot_axes(spec, df) -> tuple[str | None, str | None, str | None]:
    """(x, y, series): the plot axes for ``spec`` -- the [plot] table's choices, else the swept
    parameters (x, and y for a heat map when two are swept); ``series`` is a second swept
    parameter drawn as separate lines when only x is an axis. (None, None, None): no plot
    (nothing swept, or more than two swept parameters and no [plot] x)."""
    swept = [p.name for p in spec.swept]
    x, y = spec.plot.x, spec.plot.y
    if x is None:
        if not 1 <= len(swept) <= 2:
            return None, None, None
        x = swept[0]
        y = y if y is not None else (swept[1] if len(swept) == 2 else None)
    others = [s for s in swept if s not in (x, y)]
    if y is None and len(others) == 1:
        # x is derived from the other (e.g. a ratio of one swept size): no separate lines
        per = df.groupby(others[0])[x].nunique() if x in df and others[0] in df else None
        series = others[0] if per is not None and (per > 1).any() else None
        return x, None, series
    return x, y, None


def plot_sweep(spec, df, out: Path) -> dict[str, str]:
    """Write one PNG per figure of ``spec`` (all collected and derived columns, or the [plot]
    list) from the table ``df``; returns {figure: path}."""
    x, y, series = plot_axes(spec, df)
    if x is None or len(df) == 0:
        return {}
    figs = spec.plot.figures or tuple([g.name for g in spec.figures] + [n for n, _ in spec.derived])
    figs = [f for f in figs if f not in (x, y) and f in df]
    units = {p.name: p.unit for p in spec.parameters} | {g.name: g.unit for g in spec.figures}
    logs = {p.name for p in spec.parameters if p.log}
    ok = df["status"] == "ok"
    paths = {}
    plt = _plt()
    for f in figs:
        if not df.loc[ok, f].notna().any():
            continue
        fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
        n_fail = int((~ok).sum())
        if x in logs:  # scales first: the heat map's ticks are set for them
            ax.set_xscale("log")
        if y in logs:
            ax.set_yscale("log")
        if y is None:
            _lines(ax, df, x, f, series, ok, units)
        else:
            _map(fig, ax, df, x, y, f, ok, units, logs)
        ax.set_xlabel(_label(x, units.get(x, "")))
        fail = f", {n_fail} failed run{'s' if n_fail != 1 else ''} marked" if n_fail else ""
        ax.set_title(f"{spec.name}: {_label(f, units.get(f, ''))}\n{len(df)} runs{fail}", fontsize=11)
        p = out / f"{spec.name}_{f}.png"
        save_figure(fig, p, dpi=110)
        plt.close(fig)
        paths[f] = str(p)
    return paths


def _lines(ax, df, x, f, series, ok, units):
    text = _is_text(df.loc[ok, f])
    groups = [(None, df)] if series is None else list(df.groupby(series, sort=True))
    cats = sorted(df.loc[ok, f].dropna().unique()) if text else None
    for key, g in groups:
        g = g[g["status"] == "ok"].sort_values(x)
        if series is None:
            label = None
        elif isinstance(key, float):
            unit = " " + units[series] if units.get(series) else ""
            label = f"{series} = {key:.4g}{unit}"
        else:
            label = f"{series} = {key}"
        if text:
            ax.plot(g[x], [cats.index(v) for v in g[f]], "o", ms=8, label=label)
        else:
            ax.plot(g[x], g[f], "o-", label=label)
    if text:
        ax.set_yticks(range(len(cats)), cats)
        ax.set_ylim(-0.5, len(cats) - 0.5)
        ax.set_ylabel(f)
    else:
        ax.set_ylabel(_label(f, units.get(f, "")))
        if (df.loc[ok, f].dropna() < 0).any() and (df.loc[ok, f].dropna() > 0).any():
            ax.axhline(0.0, color="0.5", lw=0.8)
    bad = df.loc[~ok, x].dropna()
    if len(bad):
        ax.plot(bad, np.zeros(len(bad)), "x", color="red", ms=10, mew=2, transform=ax.get_xaxis_transform(),
                clip_on=False, label="failed run")
    ax.grid(alpha=0.3)
    if series is not None or len(bad):
        ax.legend(loc="best", fontsize=9)


def _map(fig, ax, df, x, y, f, ok, units, logs):
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch
    from matplotlib.ticker import NullLocator

    xs, ys = np.sort(df[x].dropna().unique()), np.sort(df[y].dropna().unique())
    text = _is_text(df.loc[ok, f])
    cats = sorted(df.loc[ok, f].dropna().unique()) if text else None
    val = df[f].map(lambda v: cats.index(v) if v in cats else np.nan) if text else df[f].astype(float)
    val = val.where(ok)
    grid = len(xs) * len(ys) == len(df[[x, y]].drop_duplicates()) and len(xs) > 1 and len(ys) > 1
    if text:
        cmap = ListedColormap(_palette(len(cats)))
        norm = BoundaryNorm(np.arange(len(cats) + 1) - 0.5, len(cats))
    else:
        cmap, norm = "viridis", None
    if grid:
        Z = np.full((len(ys), len(xs)), np.nan)
        for xv, yv, v in zip(df[x], df[y], val):
            Z[np.searchsorted(ys, yv), np.searchsorted(xs, xv)] = v
        ax.set_facecolor("0.85")  # failed / missing cells
        m = ax.pcolormesh(_edges(xs, x in logs), _edges(ys, y in logs), np.ma.masked_invalid(Z), cmap=cmap, norm=norm,
                          shading="flat")
        for (i, j) in zip(*np.nonzero(np.isnan(Z))):
            ax.text(xs[j], ys[i], "x", color="red", ha="center", va="center", fontsize=12, fontweight="bold")
        if len(xs) <= 12:
            ax.set_xticks(xs, [f"{v:.3g}" for v in xs])
            ax.xaxis.set_minor_locator(NullLocator())
        if len(ys) <= 12:
            ax.set_yticks(ys, [f"{v:.3g}" for v in ys])
            ax.yaxis.set_minor_locator(NullLocator())
        if not text and Z.size <= 64:  # small charts: print the values in the cells
            for (i, j), v in np.ndenumerate(Z):
                if np.isfinite(v):
                    ax.text(xs[j], ys[i], f"{v:.3g}", ha="center", va="center", fontsize=8,
                            color="w" if v < np.nanmean(Z) else "k")
    else:
        m = ax.scatter(df[x], df[y], c=val, cmap=cmap, norm=norm, s=60, edgecolors="k")
        bad = ~ok
        ax.scatter(df.loc[bad, x], df.loc[bad, y], marker="x", color="red", s=60)
    ax.set_ylabel(_label(y, units.get(y, "")))
    if text:
        ax.legend(handles=[Patch(color=c, label=k) for c, k in zip(_palette(len(cats)), cats)]
                  + [Patch(facecolor="0.85", label="failed run")],
                  loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    else:
        fig.colorbar(m, ax=ax, label=_label(f, units.get(f, "")))


def _edges(v: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around sorted centres ``v``: midpoints, the ends mirrored (in log space
    for a log axis)."""
    v = np.log(v) if log else np.asarray(v, float)
    mid = 0.5 * (v[1:] + v[:-1])
    e = np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])
    return np.exp(e) if log else e


def _palette(n: int) -> list:
    import matplotlib

    return [matplotlib.colormaps["tab10"](i % 10) for i in range(n)]
