"""Figures of the crowd module (matplotlib, Agg backend, written atomically as PNG)."""

from __future__ import annotations

import numpy as np

from simfab.io.atomic import save_figure


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (imported on first use)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_study(result, path, *, title: str = "Micro-crowd study") -> str:
    """Percentile rank and population bias (mean +- 1 sd over sub-crowds) against crowd size."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    k = result.sizes
    for ax, m, s, label, color, top in (
        (axes[0], result.percentile_mean, result.percentile_sd, "percentile rank of crowd estimate (%)", "tab:blue",
         100.0),
        (axes[1], result.bias_mean, result.bias_sd, "population bias (RMS error, unit scale)", "tab:red", np.inf),
    ):
        ax.fill_between(k, np.maximum(m - s, 0.0), np.minimum(m + s, top), color="gold", alpha=0.5,
                        label="+- 1 sd (clipped to the range)")
        ax.plot(k, m, "o-", color=color, label="mean")
        ax.set_xlabel("crowd size")
        ax.set_ylabel(label)
        ax.set_xticks(k)
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    axes[0].set_ylim(0, 105)
    axes[1].set_ylim(bottom=0)
    n = int(result.n_subcrowds.max())
    fig.suptitle(f"{title} (up to {n} sub-crowds per size, Bayesian aggregate)")
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return str(path)


def plot_expert_network(crowd_error: float, individual, names, path, *, title: str = "Expert network") -> str:
    """Crowd error at the centre, each individual's error around it, coloured by error;
    individuals who beat the crowd get a dashed ring. Errors: unit-scale RMS."""
    plt = pyplot()
    from matplotlib import cm, colors
    from matplotlib.patches import Circle

    e = np.asarray(individual, float)
    n = e.size
    if n > NETWORK_MAX_NODES:  # a ring of 100 labelled nodes is unreadable: rank them instead
        return _plot_expert_ranking(crowd_error, e, names, path, title=title)
    norm = colors.Normalize(vmin=0.0, vmax=max(float(e.max()), crowd_error) * 1.05)
    cmap = plt.get_cmap("viridis_r")
    fig, ax = plt.subplots(figsize=(6.4, 6.4), constrained_layout=True)
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    pos = np.column_stack([np.cos(ang), np.sin(ang)])
    r_node = min(0.16, 1.6 / max(n, 1))
    for p in pos:
        ax.plot([0, p[0]], [0, p[1]], color="0.8", lw=0.8, zorder=0)
    for i, (p, err) in enumerate(zip(pos, e)):
        ax.add_patch(Circle(p, r_node, facecolor=cmap(norm(err)), edgecolor="k", lw=0.6, zorder=2))
        if err < crowd_error:
            ax.add_patch(Circle(p, r_node * 1.35, fill=False, edgecolor="crimson", lw=1.4, ls="--", zorder=3))
        fs = 7 if n > 20 else 8
        ax.text(p[0], p[1], f"{err:.2f}", ha="center", va="center", fontsize=fs, zorder=4,
                color="w" if norm(err) > 0.5 else "k")
        ax.text(1.3 * p[0], 1.3 * p[1], str(names[i]), ha="center", va="center", fontsize=fs - 1, color="0.3")
    ax.add_patch(Circle((0, 0), 0.22, facecolor=cmap(norm(crowd_error)), edgecolor="k", lw=1.2, zorder=2))
    ax.text(0, 0, f"crowd\n{crowd_error:.3f}", ha="center", va="center", fontsize=10, zorder=4,
            color="w" if norm(crowd_error) > 0.5 else "k")
    beaten = int(np.sum(e > crowd_error))
    ax.set_title(f"{title}\ncrowd beats {beaten} of {n} individuals\n"
                 "(dashed ring: individual better than the crowd)", fontsize=9, wrap=True)
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.7, label="RMS error (unit scale)")
    ax.set_xlim(-1.45, 1.45)
    ax.set_ylim(-1.45, 1.45)
    ax.set_aspect("equal")
    ax.axis("off")
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return str(path)


#: Above this many raters the expert network is drawn as a ranking (labels would overlap).
NETWORK_MAX_NODES = 30


def _plot_expert_ranking(crowd_error: float, e: np.ndarray, names, path, *, title: str) -> str:
    """Every individual's error, sorted, against the crowd's (a horizontal line); individuals
    better than the crowd are named."""
    plt = pyplot()
    order = np.argsort(e)
    n = e.size
    better = e[order] < crowd_error
    fig, ax = plt.subplots(figsize=(8.0, 4.6), constrained_layout=True)
    x = np.arange(1, n + 1)
    ax.bar(x[~better], e[order][~better], width=0.85, color="0.65", label="individual (worse than the crowd)")
    ax.bar(x[better], e[order][better], width=0.85, color="crimson", label="individual better than the crowd")
    ax.axhline(crowd_error, color="tab:blue", lw=2, label=f"Bayesian crowd estimate: {crowd_error:.3f}")
    for i in np.nonzero(better)[0][:12]:
        ax.annotate(str(names[order[i]]), (x[i], e[order][i]), textcoords="offset points", xytext=(0, 4),
                    ha="center", fontsize=7, rotation=90)
    beaten = int(np.sum(e > crowd_error))
    ax.set_xlabel(f"individual raters, ranked by error (1 = best of {n})")
    ax.set_ylabel("RMS error (unit scale, 0..1)")
    ax.set_xlim(0, n + 1)
    ax.set_ylim(0, max(float(e.max()), crowd_error) * 1.12)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{title}\ncrowd beats {beaten} of {n} individuals", fontsize=10)
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return str(path)


def plot_method_errors(per_question: dict, tasks, path, *, title: str = "Crowd error per question") -> str:
    """Bars of |estimate - truth| (unit scale) per question, one bar per aggregation method."""
    plt = pyplot()
    names = list(per_question)
    Q = len(tasks)
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * Q + 2), 3.8), constrained_layout=True)
    w = 0.8 / max(len(names), 1)
    for m, name in enumerate(names):
        ax.bar(np.arange(Q) + (m - (len(names) - 1) / 2) * w, per_question[name], width=w, label=name.replace("_", " "))
    ax.set_xticks(np.arange(Q))
    ax.set_xticklabels(tasks)
    ax.set_ylabel("|estimate - truth| (unit scale)")
    ax.set_title(title)
    ax.legend(fontsize=8, ncol=min(5, len(names)))
    ax.grid(axis="y", alpha=0.3)
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return str(path)
