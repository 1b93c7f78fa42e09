"""The bench's plots (matplotlib: the ``plot`` extra)."""
from __future__ import annotations

import math
import os
import textwrap

from clfx.core.errors import ClfxError
from clfx.plugins import get_plugin

MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def family(effect: str) -> str:
    """The effect family a bench row belongs to: its plugin's descriptor group ("Lens",
    "Glare", ...; a case variant "distortion:moustache" is its effect's), "Other" for a
    name no plugin has."""
    try:
        return get_plugin(effect.split(":", 1)[0]).descriptor.group or "Other"
    except Exception:  # noqa: BLE001 - an unknown name still gets a panel
        return "Other"


def pareto_points(effect: dict) -> dict:
    """An effect's points on the time/error plane: ``levels`` (ms, rel_rmse, quality) in
    quality order, the ``naive`` method's (ms, rel_rmse) and the unchanged ``input``'s
    relative RMSE (it costs nothing: a horizontal line).  Error 0 (a level identical to
    the reference, or the reference itself) has no place on a log axis: left out."""
    levels = [(r["ms"], r["rel_rmse"], r["quality"]) for r in effect["rows"]
              if not r.get("identity") and r.get("rel_rmse", 0) > 0 and "ms" in r]
    naive = inp = None
    for b in effect.get("baselines") or ():
        err = b.get("rel_rmse")
        if b.get("baseline") == "naive" and "ms" in b and err and err > 0:
            naive = (b["ms"], err)
        elif b.get("baseline") == "input" and err and err > 0:
            inp = err
    return {"levels": levels, "naive": naive, "input": inp}


def check_plot_path(path: str) -> None:
    """Refuse, before a bench runs, a --plot file matplotlib cannot write (its extension names
    no format it has, or matplotlib is missing)."""
    try:
        from matplotlib.backend_bases import FigureCanvasBase  # lazy: optional, ~1.9 s
    except ImportError as exc:
        raise ClfxError("--plot needs matplotlib: pip install 'clfx[plot]'") from exc
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    kinds = FigureCanvasBase.get_supported_filetypes()
    if ext not in kinds:
        raise ClfxError(f"--plot {path}: {('.' + ext) if ext else 'no extension'} is not a "
                        f"format matplotlib writes; expected one of "
                        f"{', '.join('.' + k for k in sorted(kinds))}")


def pareto_plot(results: dict, path: str) -> None:
    """`pareto_figure` of ``results`` as a PNG at ``path``."""
    import matplotlib.pyplot as plt  # lazy: optional ([plot] extra); ~1.9 s to import

    fig = pareto_figure(results)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pareto_figure(results: dict):
    """Time vs relative error as small multiples, one panel per effect family (descriptor
    group): each effect's quality levels as a line, its naive method as a hollow marker of
    the same colour and the unchanged input's error as a dotted line (the error to beat at
    no cost).  Needs matplotlib: the [plot] extra."""
    try:
        import matplotlib  # lazy: optional ([plot] extra); ~1.9 s to import

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # lazy: after choosing the Agg backend
    except ImportError as exc:
        raise ClfxError("--plot needs matplotlib: pip install 'clfx[plot]'") from exc
    groups: dict[str, list[dict]] = {}
    for e in results["effects"]:
        groups.setdefault(family(e["effect"]), []).append(e)
    names = sorted(groups)
    cols = min(3, max(1, len(names)))
    rows = max(1, math.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.8 * rows), squeeze=False)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    w, h = results["size"]
    for ax, name in zip(axes.ravel(), names):
        plotted = False
        for i, e in enumerate(groups[name]):
            pts = pareto_points(e)
            colour = f"C{i % 10}"
            if pts["levels"]:
                xs, ys, qs = zip(*pts["levels"])
                ax.plot(xs, ys, "-", marker=MARKERS[i % len(MARKERS)], color=colour,
                        label=e["effect"])
                ax.annotate(qs[0], (xs[0], ys[0]), fontsize=6, color=colour,
                            textcoords="offset points", xytext=(3, 3))
                plotted = True
            if pts["naive"] is not None:
                ax.plot(*pts["naive"], marker=MARKERS[i % len(MARKERS)], markersize=9,
                        markerfacecolor="none", color=colour, linestyle="none")
                plotted = True
            if pts["input"] is not None:
                ax.axhline(pts["input"], color=colour, linestyle=":", linewidth=1)
        if plotted:
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.legend(fontsize=6, loc="best")
        ax.set_title(name, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("ms per frame", fontsize=8)
        ax.set_ylabel("relative RMSE", fontsize=8)
        ax.tick_params(labelsize=7)
    title = textwrap.wrap(f"clfx: what accuracy costs ({w}x{h}). Line: an effect's quality "
                          f"levels (the cheapest labelled); hollow marker: its naive method; "
                          f"dotted: the unchanged input's error (levels with error 0 not "
                          f"shown)", width=int(15 * 4.6 * cols))
    fig.suptitle("\n".join(title), fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.035 * len(title) / rows))
    return fig
